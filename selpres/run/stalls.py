"""Stalls as their own outcome (issue 40): which replicas ended stalled, and the state of their hidden units.

A replica **stalled** when its final held-out RMS (overall, Nm) is at least ``STALL_SHARE`` of the floor's, the
RMS of predicting the training mean (:mod:`selpres.run.floor`). On the modern study's validation draw the nets
of Adam + ReLU that converged end at 7-15 % of the floor, the stalled ones on plateaus at 21-23 % (PUMA 560), 29,
38 and 45-48 % (two-link arm) and up to the floor itself; 20 % lies below every plateau (docs/studies/modern.md).

The cause's evidence is counted at the end on the held-out inputs, per replica, for every hidden layer:

* **dead**: the unit's derivative is at most ``TOL`` on every input, so no gradient reaches its incoming
  weights again (ReLU: never active; sigmoid, tanh: saturated on every input);
* **linear**: not dead, and its derivative is the same within ``TOL`` on every input: over the set the unit is an
  affine function of its inputs and bends nothing (ReLU: active on every input, "always on"; leaky ReLU: on
  one side of 0 everywhere).

A net whose units are mostly dead or linear is close to an affine map, whatever it is trained for. Both are written into
results.json's ``stalls`` (a list beside ``replica_results``, one entry per replica, so that list is unchanged).
"""

from __future__ import annotations

import math

import torch

from selpres.engines.activations import activation as units

STALL_SHARE = 0.2  # stalled: final held-out RMS >= this share of the mean predictor's
TOL = 1e-3  # a derivative this close to 0 (dead) or to constant (linear) over the set; built-in units peak at 0.25-1
CHUNK = 2048  # held-out inputs per block: [R, CHUNK, width] at a time, not [R, n, width]


def is_stalled(rms: float | None, floor: float | None, share: float = STALL_SHARE) -> bool | None:
    """Whether a final RMS is at least ``share`` of the floor's (None where either is unknown)."""
    if rms is None or floor is None or not math.isfinite(rms) or not floor > 0:
        return None
    return rms >= share * floor


@torch.no_grad()
def unit_states(params: list[torch.Tensor], X: torch.Tensor, activation: str) -> list[tuple[torch.Tensor, ...]]:
    """Per hidden layer, ([R, H] dead, [R, H] linear) of replicas ``params`` ([W1, b1, W2, b2, ...], leading
    replica dim) on the inputs ``X`` [n, in] (as the net sees them: scaled), by the derivative of each unit's
    activation (its class's ``prime``) on every input."""
    act = units(activation)
    hidden = len(params) // 2 - 1
    lo = [None] * hidden  # per layer, the smallest and largest derivative of each unit over the inputs
    hi = [None] * hidden
    R = params[0].shape[0]
    for start in range(0, X.shape[0], CHUNK):
        h = X[start : start + CHUNK].to(params[0].dtype).expand(R, -1, -1)
        for k in range(hidden):
            w, b = params[2 * k], params[2 * k + 1]
            z = torch.baddbmm(b.unsqueeze(1), h, w.transpose(1, 2))
            h = act.forward(z)
            d = act.prime(z, h)
            small, large = d.amin(1), d.amax(1)
            lo[k] = small if lo[k] is None else torch.minimum(lo[k], small)
            hi[k] = large if hi[k] is None else torch.maximum(hi[k], large)
    out = []
    for small, large in zip(lo, hi):
        dead = (small.abs() <= TOL) & (large.abs() <= TOL)
        out.append((dead, ~dead & (large - small <= TOL)))
    return out


def evidence(reps: list[dict], engine, prob, activation: str, floor: dict) -> dict:
    """results.json's ``stalls``: the rule, and per replica (in ``replica_results``' order) whether it stalled
    (:func:`is_stalled` against the held-out floor; None for a diverged replica), its final RMS as a share of the
    floor, and its hidden units' counts on the held-out inputs (:func:`unit_states`)."""
    base = floor.get("heldout", {}).get("nm", {}).get("overall")
    states = unit_states(engine.params(), prob.scored["heldout"][0], activation)
    out = []
    for r, rep in enumerate(reps):
        rms = rep["final"]["heldout"]["nm"]["overall"] if rep["status"] == "complete" else None
        entry = {"seed": rep["seed"], "stalled": is_stalled(rms, base), "share_of_floor": None, "dead": None}
        entry["linear"] = None
        if entry["stalled"] is not None:
            entry["share_of_floor"] = rms / base
            entry["dead"] = sum(int(d[r].sum()) for d, _ in states)
            entry["linear"] = sum(int(lin[r].sum()) for _, lin in states)
        out.append(entry)
    return {
        "rule": f"final held-out RMS >= {STALL_SHARE:g} x the mean predictor's (floor.heldout.nm.overall)",
        "threshold": STALL_SHARE,
        "units_on": "heldout",
        "tol": TOL,
        "hidden_units": sum(int(d.shape[1]) for d, _ in states),
        "replicas": out,
    }
