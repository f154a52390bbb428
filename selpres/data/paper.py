"""The paper's grid route (section 5.1): the exemplar set, the test sets and the commanded boxes of the two-link arm.

Network input (θ1, θ̇1, θ̈1, θ2, θ̇2, θ̈2) and target (τ1, τ2): patterns that the forward simulator (eq. 5) generated on
a grid, kept where both |θ̈| <= accel_limit. Other arms and sizes are drawn by ``selpres.data.sampled``, users' tables
read by ``selpres.data.file``; the sets' types, the scaler and the RMS criterion every route shares are
``selpres.patterns``'. All functions are pure in their arguments; randomness comes only from an explicit
``torch.Generator`` or seed.
"""

from __future__ import annotations

import math
from typing import Any

import torch

from selpres.arms.two_link import TwoLinkArm
from selpres.errors import ConfigError
from selpres.patterns import DTYPE, ExemplarSet, Patterns, TestSets

INPUT_NAMES = ("theta1", "dtheta1", "ddtheta1", "theta2", "dtheta2", "ddtheta2")
TARGET_NAMES = ("tau1", "tau2")
COLUMN_NAMES = INPUT_NAMES + TARGET_NAMES


def _range(data_cfg: Any, key: str) -> tuple[float, float]:
    node = data_cfg[key]
    return float(node["lo"]), float(node["hi"])


def heldout_count(value: Any, total: int, what: str) -> int:
    """``data.heldout`` as a count: a whole number as it is, a float in (0, 1) as that fraction of
    ``total`` (rounded half up, at least 1). ``what`` names ``total`` in the message."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError("data.heldout", value, "a whole number of patterns >= 1, or a fraction in (0, 1)")
    if isinstance(value, float):
        if not 0.0 < value < 1.0:
            raise ConfigError("data.heldout", value, f"a fraction in (0, 1) of {what}, or a whole number >= 1")
        return max(1, math.floor(value * total + 0.5))
    if value < 1:
        raise ConfigError("data.heldout", value, "a whole number of patterns >= 1, or a fraction in (0, 1)")
    return int(value)


def _rows(q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor, tau: torch.Tensor) -> Patterns:
    X = torch.stack((q[:, 0], qd[:, 0], qdd[:, 0], q[:, 1], qd[:, 1], qdd[:, 1]), -1)
    return Patterns(X.contiguous(), tau.contiguous())


# ------------------------------------------------------------------------------------ exemplar grid


def grid_points(lo: float, hi: float, step: float, name: str = "grid") -> int:
    """How many points ``grid_axis`` will have; checks the range without allocating it."""
    lo, hi, step = float(lo), float(hi), float(step)
    if not step > 0:
        raise ValueError(f"{name}: step must be > 0, got {step}")
    if hi < lo:
        raise ValueError(f"{name}: hi ({hi}) must be >= lo ({lo})")
    n = round((hi - lo) / step)
    if abs(lo + n * step - hi) > 1e-9 * max(1.0, abs(hi)):
        raise ValueError(f"{name}: hi - lo = {hi - lo} is not a whole number of steps of {step}")
    return n + 1


def grid_axis(lo: float, hi: float, step: float, name: str = "grid") -> torch.Tensor:
    """``lo + i*step`` for i = 0..n (not repeated addition, so endpoints such as 18.0 come out exact)."""
    n = grid_points(lo, hi, step, name)
    return float(lo) + torch.arange(n, dtype=DTYPE) * float(step)


def _axis(data_cfg: Any, key: str) -> torch.Tensor:
    node = data_cfg[key]
    return grid_axis(node["lo"], node["hi"], node["step"], name=key)


def accel_filter(qdd: torch.Tensor, limit: float) -> torch.Tensor:
    """The paper's selection rule: keep a pattern iff both |θ̈| <= limit (boundary included)."""
    return (qdd.abs() <= float(limit)).all(-1)


def grid_accelerations(arm: TwoLinkArm, data_cfg: Any) -> tuple[torch.Tensor, ...]:
    """The whole θ1×θ̇1×θ2×θ̇2×τ1×τ2 grid through one batched forward-dynamics call.

    Returns (states [S, 4] as θ1, θ̇1, θ2, θ̇2; τ1 axis; τ2 axis; θ̈ [S, T1, T2, 2]).
    """
    th, w = _axis(data_cfg, "theta"), _axis(data_cfg, "dtheta")
    t1, t2 = _axis(data_cfg, "tau1"), _axis(data_cfg, "tau2")
    states = torch.cartesian_prod(th, w, th, w)  # [S, 4]: θ1, θ̇1, θ2, θ̇2
    q = states[:, [0, 2]].view(-1, 1, 1, 2)
    qd = states[:, [1, 3]].view(-1, 1, 1, 2)
    tau = torch.stack(torch.broadcast_tensors(t1[:, None], t2[None, :]), -1)  # [T1, T2, 2]
    return states, t1, t2, arm.forward_dynamics(q, qd, tau)  # θ̈ broadcasts to [S, T1, T2, 2]


def build_exemplar_set(arm: TwoLinkArm, data_cfg: Any) -> ExemplarSet:
    """Simulate the grid and keep the |θ̈| <= limit rows (paper, section 5.1).

    Rows come out in lexicographic order (θ1, θ̇1, θ2, θ̇2, τ1, τ2), θ1 slowest, so the set is deterministic.
    """
    states, t1, t2, qdd = grid_accelerations(arm, data_cfg)
    s, i, j = accel_filter(qdd, data_cfg["accel_limit"]).nonzero(as_tuple=True)
    tau_kept = torch.stack((t1[i], t2[j]), -1)
    p = _rows(states[s][:, [0, 2]], states[s][:, [1, 3]], qdd[s, i, j], tau_kept)
    return ExemplarSet(p.X, p.Y, n_candidates=int(qdd.shape[:-1].numel()))


# -------------------------------------------------------------------------------- outside patterns


def _max_det_mass_matrix(arm: TwoLinkArm, theta_lo: float, theta_hi: float) -> float:
    """max of det H over θ2 ∈ [lo, hi]; det H = m2 l1² l2² (m1 + m2 sin² θ2) peaks at endpoints or π/2 + kπ."""
    cands = [theta_lo, theta_hi]
    k = math.ceil((theta_lo - math.pi / 2) / math.pi)
    while math.pi / 2 + k * math.pi <= theta_hi:
        cands.append(math.pi / 2 + k * math.pi)
        k += 1
    q = torch.tensor([[0.0, c] for c in cands], dtype=DTYPE)
    return float(arm.det_mass_matrix(q).max())


def _uniform(n: int, lo: float, hi: float, generator: torch.Generator, cols: int = 1) -> torch.Tensor:
    return lo + (hi - lo) * torch.rand(n, cols, dtype=DTYPE, generator=generator)


MAX_OUTSIDE_DRAWS = 20_000_000  # give up (rather than hang) when a filter accepts nothing in this many draws


def sample_outside(
    arm: TwoLinkArm, data_cfg: Any, count: int, generator: torch.Generator, *, _reweight: bool = True
) -> Patterns:
    """``count`` patterns from the CONTINUOUS version of the exemplar distribution.

    Target law: state and τ uniform in their boxes, conditioned on both |θ̈| <= a. Plain rejection keeps ~0.1 %,
    so we sample θ̈ instead: for a fixed state τ = H θ̈ + b is affine with Jacobian det H(q), hence the target
    law equals "state uniform, θ̈ uniform in [−a, a]², reweighted ∝ det H(q), restricted to τ in the box".
    The reweighting is done exactly by accepting with probability det H / max det H.
    (``_reweight=False`` drops it; only the tests use that, to show the distribution test has power.)
    """
    count = int(count)
    th_lo, th_hi = _range(data_cfg, "theta")
    w_lo, w_hi = _range(data_cfg, "dtheta")
    t1_lo, t1_hi = _range(data_cfg, "tau1")
    t2_lo, t2_hi = _range(data_cfg, "tau2")
    a = float(data_cfg["accel_limit"])
    det_max = _max_det_mass_matrix(arm, th_lo, th_hi)
    tau_lo = torch.tensor([t1_lo, t2_lo], dtype=DTYPE)
    tau_hi = torch.tensor([t1_hi, t2_hi], dtype=DTYPE)

    parts: list[Patterns] = [_rows(*(torch.empty(0, 2, dtype=DTYPE),) * 4)]
    have, drawn, accepted = 0, 0, 0
    while have < count:
        if drawn >= MAX_OUTSIDE_DRAWS and accepted == 0:
            raise ValueError(
                f"no outside pattern in {drawn:,} random draws: the continuous ranges (theta, dtheta, tau1, tau2) "
                f"and accel_limit={a} leave (almost) nothing to sample from"
            )
        # batch sized from the acceptance rate seen so far (deterministic: depends only on the generator)
        rate = max(accepted / drawn, 1e-3) if drawn else 0.05
        n = int(min(max((count - have) / rate * 1.2, 1024), 2_000_000))
        q = _uniform(n, th_lo, th_hi, generator, 2)
        qd = _uniform(n, w_lo, w_hi, generator, 2)
        qdd = _uniform(n, -a, a, generator, 2)
        u = torch.rand(n, dtype=DTYPE, generator=generator)
        tau = arm.inverse_dynamics(q, qd, qdd)
        keep = ((tau >= tau_lo) & (tau <= tau_hi)).all(-1)
        if _reweight:
            keep &= u * det_max <= arm.det_mass_matrix(q)
        drawn += n
        accepted += int(keep.sum())
        parts.append(_rows(q[keep], qd[keep], qdd[keep], tau[keep]))
        have += int(keep.sum())
    X = torch.cat([p.X for p in parts])[:count]
    Y = torch.cat([p.Y for p in parts])[:count]
    return Patterns(X, Y)


def make_test_sets(arm: TwoLinkArm, data_cfg: Any, exemplar: ExemplarSet, seed: int) -> TestSets:
    """The paper's 10 random test patterns ("some from the exemplar set and some outside") + a held-out set."""
    gen = torch.Generator().manual_seed(int(seed))
    n_test, n_ex = int(data_cfg["test_patterns"]), int(data_cfg["test_from_exemplar"])
    if not 0 <= n_ex <= min(n_test, len(exemplar)):
        raise ValueError(f"test_from_exemplar: {n_ex} not in [0, min(test_patterns={n_test}, {len(exemplar)})]")
    idx = torch.randperm(len(exemplar), generator=gen)[:n_ex]
    out = sample_outside(arm, data_cfg, n_test - n_ex, gen)
    test10 = Patterns(torch.cat((exemplar.X[idx], out.X)), torch.cat((exemplar.Y[idx], out.Y)))
    from_ex = torch.arange(n_test) < n_ex
    heldout = sample_outside(arm, data_cfg, int(data_cfg["heldout"]), gen)
    return TestSets(test10, from_ex, heldout)


# ------------------------------------------------------------------------------------------ scaling


def grid_bounds(data_cfg: Any) -> tuple[torch.Tensor, ...]:
    """(x lo, x hi, τ lo, τ hi) the grid route commands: its θ, θ̇ ranges, ±accel_limit and τ boxes."""
    th, w = _range(data_cfg, "theta"), _range(data_cfg, "dtheta")
    a = float(data_cfg["accel_limit"])
    x0 = torch.tensor([th[0], w[0], -a, th[0], w[0], -a], dtype=DTYPE)
    x1 = torch.tensor([th[1], w[1], a, th[1], w[1], a], dtype=DTYPE)
    t1, t2 = _range(data_cfg, "tau1"), _range(data_cfg, "tau2")
    return x0, x1, torch.tensor([t1[0], t2[0]], dtype=DTYPE), torch.tensor([t1[1], t2[1]], dtype=DTYPE)
