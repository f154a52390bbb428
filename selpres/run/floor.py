"""A task's floor: what predicting the training-set mean torque scores, and the normalised MSE against it.

A network's RMS error in Nm says little across arms and ranges: 13 Nm is good for a UR5's shoulder over ±2π
and bad for the paper's arm. Two numbers make it comparable (issue 21, item 7):

* the **floor**, ``results["floor"][set]["nm"][joint]``: the RMS error of the constant prediction
  ȳ = mean of the exemplar targets (per joint; overall = the RMS over every joint's errors, as our RMS is);
* the **nMSE**, ``replica_results[r]["final"][set]["nmse"][joint]``: MSE ÷ the variance of that set's
  targets (population variance), the metric the inverse-dynamics literature reports (Vijayakumar & Schaal's
  SARCOS results, GPR/LWPR comparisons); overall = the mean of the per-joint nMSE, as those papers average it.
  The mean predictor scores nMSE ≈ 1; a joint whose target does not vary (variance 0) has no nMSE (None).

A job whose network ends within ``MARGIN`` of the floor on the held-out set (RMS ≥ (1 − MARGIN) × floor, i.e.
nMSE ≳ 0.8 for a centred set) gets a warning naming the joint: it learnt next to nothing of it.
"""

from __future__ import annotations

import math

import torch

from selpres.patterns import metric_names

MARGIN = 0.1  # a network must beat the mean predictor's RMS by more than 10 % not to be warned about


def nmse(nm_sums: torch.Tensor, n: int, Y: torch.Tensor) -> dict[str, torch.Tensor]:
    """Per joint and overall nMSE of every replica, from its per-output sums of squared errors in Nm²
    ``[R, out]`` over the ``n`` patterns whose targets (Nm) are ``Y [n, out]``."""
    var = Y.var(0, unbiased=False).to(nm_sums.dtype)
    per = torch.where(var > 0, nm_sums.div(n) / var.clamp_min(torch.finfo(var.dtype).tiny), math.nan)
    names = metric_names(Y.shape[1])[1:]
    return {"overall": per.mean(1), **{joint: per[:, k] for k, joint in enumerate(names)}}


def task_floor(train_Y: torch.Tensor, tests: dict[str, tuple[torch.Tensor, torch.Tensor]]) -> dict:
    """set -> {"nm": joint -> RMS, "nmse": joint -> nMSE} of predicting ``train_Y``'s mean on each test set."""
    mean = train_Y.mean(0)
    out = {}
    for name, (_, Y) in tests.items():
        sq = (Y - mean).square().sum(0, keepdim=True)  # [1, out]
        per = sq.div(Y.shape[0]).sqrt()[0]
        names = metric_names(Y.shape[1])[1:]
        rms = {"overall": float(sq.sum().div(Y.numel()).sqrt()), **{j: float(v) for j, v in zip(names, per)}}
        ratio = {k: (None if math.isnan(float(v[0])) else float(v[0])) for k, v in nmse(sq, Y.shape[0], Y).items()}
        out[name] = {"nm": rms, "nmse": ratio}
    return out


def floor_warnings(summary: dict, floor: dict, data_info: dict | None, topology: str = "") -> list[str]:
    """One line per held-out joint whose mean final RMS is within MARGIN of the floor, with the likely cause."""
    held = floor.get("heldout", {}).get("nm", {})
    boxes = (data_info or {}).get("boxes") or {}
    spans = {k: max((hi - lo for lo, hi in boxes.get(k) or []), default=None) for k in ("q", "dq")}
    ranges = ", ".join(f"data.{k} up to {v:.3g} wide" for k, v in spans.items() if v is not None) or "data.*"
    cause = (
        f"the input ranges ({ranges}: narrow them) or the network's size and training "
        f"(topology {topology or 'as set'}: more hidden units or epochs)"
    )
    out = []
    for joint, base in held.items():
        if joint == "overall" or not base:
            continue
        got = (summary.get(f"heldout_rms_nm_{joint}") or {}).get("mean")
        if got is not None and got >= (1 - MARGIN) * base:
            out.append(
                f"{joint}: held-out RMS {got:.4g} Nm is no better than predicting the training mean "
                f"({base:.4g} Nm) by {MARGIN:.0%}: the network learnt next to nothing of it; likely cause: {cause}"
            )
    return out
