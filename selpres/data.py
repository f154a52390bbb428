"""Exemplar set, test sets, sigmoid-range scaling and export (paper section 5.1).

Network input is (θ1, θ̇1, θ̈1, θ2, θ̇2, θ̈2) and target (τ1, τ2): the network learns inverse dynamics from
patterns that the forward simulator (eq. 5) generated. All functions are pure in their arguments;
randomness comes only from an explicit ``torch.Generator`` or seed.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np
import torch

from selpres.robot import TwoLinkArm, cfg_get
from selpres.storage import atomic_write, stable_hash

INPUT_NAMES = ("theta1", "dtheta1", "ddtheta1", "theta2", "dtheta2", "ddtheta2")
TARGET_NAMES = ("tau1", "tau2")
COLUMN_NAMES = INPUT_NAMES + TARGET_NAMES
DTYPE = torch.float64


class DataMismatchError(ValueError):
    """An exported data file was made with a different robot/data config than the one in use."""


def _range(data_cfg: Any, key: str) -> tuple[float, float]:
    node = cfg_get(data_cfg, key)
    return float(cfg_get(node, "lo")), float(cfg_get(node, "hi"))


# ----------------------------------------------------------------------------------------- patterns


@dataclass(frozen=True)
class Patterns:
    """Input rows ``X [n, 6]`` (INPUT_NAMES order) and targets ``Y [n, 2]`` in Nm, float64."""

    X: torch.Tensor
    Y: torch.Tensor

    def __iter__(self):  # allows ``X, Y = patterns``
        return iter((self.X, self.Y))

    def __len__(self) -> int:
        return int(self.X.shape[0])


@dataclass(frozen=True)
class ExemplarSet(Patterns):
    """The paper's exemplar set U (1002 patterns with the default robot) and how many grid candidates it came from."""

    n_candidates: int = 0


@dataclass(frozen=True)
class TestSets:
    """``test10``: the paper's 10 random test patterns (``test10_from_exemplar`` marks the rows taken from
    the exemplar set); ``heldout``: many outside patterns, for a metric that is not dominated by noise."""

    test10: Patterns
    test10_from_exemplar: torch.Tensor
    heldout: Patterns


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
    node = cfg_get(data_cfg, key)
    return grid_axis(cfg_get(node, "lo"), cfg_get(node, "hi"), cfg_get(node, "step"), name=key)


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
    s, i, j = accel_filter(qdd, cfg_get(data_cfg, "accel_limit")).nonzero(as_tuple=True)
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
    a = float(cfg_get(data_cfg, "accel_limit"))
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
    n_test, n_ex = int(cfg_get(data_cfg, "test_patterns")), int(cfg_get(data_cfg, "test_from_exemplar"))
    if not 0 <= n_ex <= min(n_test, len(exemplar)):
        raise ValueError(f"test_from_exemplar: {n_ex} not in [0, min(test_patterns={n_test}, {len(exemplar)})]")
    idx = torch.randperm(len(exemplar), generator=gen)[:n_ex]
    out = sample_outside(arm, data_cfg, n_test - n_ex, gen)
    test10 = Patterns(torch.cat((exemplar.X[idx], out.X)), torch.cat((exemplar.Y[idx], out.Y)))
    from_ex = torch.arange(n_test) < n_ex
    heldout = sample_outside(arm, data_cfg, int(cfg_get(data_cfg, "heldout")), gen)
    return TestSets(test10, from_ex, heldout)


# ------------------------------------------------------------------------------------------ scaling


@dataclass(frozen=True)
class Scaler:
    """Per-column affine map of [min − margin·range, max + margin·range] onto [lo, hi] ⊂ (0, 1).

    The BPN's output units are sigmoids, so targets must lie inside (0, 1) and away from its flat ends.
    Default mode ``exemplar`` uses the exemplar set's own min/max. Measured with the default robot: the exemplar
    τ1 spans only 14.0–15.4 Nm of the commanded 14–18 Nm box and τ2 only 6.9–8.0 of 4–8, so with margin 0.1
    mode ``commanded`` maps τ1 into [0.167, 0.400] and τ2 into [0.650, 0.833], where ``exemplar`` uses
    [0.167, 0.833] for both: ``commanded`` wastes most of the sigmoid's range (τ2 sits near its upper end)
    and shrinks the targets' spread by 2–3.5×. scripts/export_data.py prints both.
    """

    x_min: torch.Tensor  # data-side bounds (margin already applied), [6]
    x_max: torch.Tensor
    y_min: torch.Tensor  # [2]
    y_max: torch.Tensor
    lo: float = 0.1
    hi: float = 0.9

    @classmethod
    def fit(cls, exemplar: Patterns, data_cfg: Any) -> "Scaler":
        sc = cfg_get(data_cfg, "scaling")
        mode, margin = str(cfg_get(sc, "mode")), float(cfg_get(sc, "margin"))
        if mode == "exemplar":
            x0, x1 = exemplar.X.min(0).values, exemplar.X.max(0).values
            y0, y1 = exemplar.Y.min(0).values, exemplar.Y.max(0).values
        elif mode == "commanded":
            th, w = _range(data_cfg, "theta"), _range(data_cfg, "dtheta")
            a = float(cfg_get(data_cfg, "accel_limit"))
            x0 = torch.tensor([th[0], w[0], -a, th[0], w[0], -a], dtype=DTYPE)
            x1 = torch.tensor([th[1], w[1], a, th[1], w[1], a], dtype=DTYPE)
            t1, t2 = _range(data_cfg, "tau1"), _range(data_cfg, "tau2")
            y0 = torch.tensor([t1[0], t2[0]], dtype=DTYPE)
            y1 = torch.tensor([t1[1], t2[1]], dtype=DTYPE)
        else:
            raise ValueError(f"scaling.mode: expected 'exemplar' or 'commanded', got {mode!r}")

        def widen(v0: torch.Tensor, v1: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            span = v1 - v0
            span = torch.where(span > 0, span, torch.ones_like(span))  # constant column: any invertible map
            return (v0 - margin * span).to(DTYPE), (v1 + margin * span).to(DTYPE)

        lo, hi = float(cfg_get(sc, "lo")), float(cfg_get(sc, "hi"))
        if not lo < hi:
            raise ValueError(f"scaling: lo ({lo}) must be < hi ({hi})")
        return cls(*widen(x0, x1), *widen(y0, y1), lo=lo, hi=hi)

    def _fwd(self, v: torch.Tensor, v0: torch.Tensor, v1: torch.Tensor) -> torch.Tensor:
        v0, v1 = v0.to(v), v1.to(v)
        return self.lo + (v - v0) * ((self.hi - self.lo) / (v1 - v0))

    def _inv(self, s: torch.Tensor, v0: torch.Tensor, v1: torch.Tensor) -> torch.Tensor:
        v0, v1 = v0.to(s), v1.to(s)
        return v0 + (s - self.lo) * ((v1 - v0) / (self.hi - self.lo))

    def transform_x(self, X: torch.Tensor) -> torch.Tensor:
        return self._fwd(X, self.x_min, self.x_max)

    def inverse_x(self, Xs: torch.Tensor) -> torch.Tensor:
        return self._inv(Xs, self.x_min, self.x_max)

    def transform_y(self, Y: torch.Tensor) -> torch.Tensor:
        return self._fwd(Y, self.y_min, self.y_max)

    def inverse_y(self, Ys: torch.Tensor) -> torch.Tensor:
        return self._inv(Ys, self.y_min, self.y_max)


def rms_overall_nm(pred_scaled: torch.Tensor, Y_true_Nm: torch.Tensor, scaler: Scaler) -> torch.Tensor:
    """The overall Nm entry of ``rms_errors`` alone (what a learning-curve point needs), shape ``[...]``."""
    return (scaler.inverse_y(pred_scaled) - Y_true_Nm.to(pred_scaled)).square().mean((-2, -1)).sqrt()


def rms_errors(pred_scaled: torch.Tensor, Y_true_Nm: torch.Tensor, scaler: Scaler) -> dict[str, torch.Tensor]:
    """The paper's criterion, RMS of (network output − actual output), in Nm and in scaled units.

    ``pred_scaled`` is ``[..., N, 2]`` (e.g. a leading replica dim R); every value has the leading shape ``[...]``.
    Keys: tau1_Nm, tau2_Nm, overall_Nm, tau1_scaled, tau2_scaled, overall_scaled; overall = sqrt of the mean
    squared error over both joints and all patterns.
    """
    Y_true_Nm = Y_true_Nm.to(pred_scaled)
    out: dict[str, torch.Tensor] = {}
    for unit, err in (
        ("Nm", scaler.inverse_y(pred_scaled) - Y_true_Nm),
        ("scaled", pred_scaled - scaler.transform_y(Y_true_Nm)),
    ):
        sq = err.square()
        per_joint = sq.mean(-2).sqrt()  # [..., 2]
        for k, name in enumerate(TARGET_NAMES):
            out[f"{name}_{unit}"] = per_joint[..., k]
        out[f"overall_{unit}"] = sq.mean((-2, -1)).sqrt()
    return out


# ------------------------------------------------------------------------------------------- export


def _plain(cfg: Any) -> Any:
    """Resolved plain container with ints folded into floats, so ``m2: 3`` and ``m2: 3.0`` hash alike."""
    try:
        from omegaconf import DictConfig, ListConfig, OmegaConf

        if isinstance(cfg, (DictConfig, ListConfig)):
            cfg = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
    except ImportError:  # pragma: no cover
        pass
    if isinstance(cfg, Mapping):
        return {str(k): _plain(v) for k, v in cfg.items()}
    if isinstance(cfg, (list, tuple)):
        return [_plain(v) for v in cfg]
    if isinstance(cfg, (int, float)) and not isinstance(cfg, bool):
        return float(cfg)
    if isinstance(cfg, Enum):  # typed configs hold enums (e.g. scaling.mode): hash their names
        return cfg.name
    return cfg


def config_hash(robot_cfg: Any, data_cfg: Any) -> str:
    """Identity of the data: a stable hash of both resolved configs (ints folded into floats)."""
    return stable_hash(_plain({"robot": robot_cfg, "data": data_cfg}))


def _table(p: Patterns) -> np.ndarray:
    return torch.cat((p.X, p.Y), 1).cpu().numpy().astype(np.float64)


def export(path_stem: str | os.PathLike, exemplar: ExemplarSet, tests: TestSets, robot_cfg: Any, data_cfg: Any) -> dict[str, Path]:
    """Write ``<stem>.npz`` and ``<stem>_{exemplar,test10,heldout}.csv`` (``%.17g``: exact float64 round trip)."""
    stem = Path(path_stem)
    h = config_hash(robot_cfg, data_cfg)
    tables = {"exemplar": _table(exemplar), "test10": _table(tests.test10), "heldout": _table(tests.heldout)}
    arrays: dict[str, np.ndarray] = {}
    for name, t in tables.items():
        arrays[f"{name}_X"], arrays[f"{name}_Y"] = t[:, :6], t[:, 6:]
    arrays["test10_from_exemplar"] = tests.test10_from_exemplar.cpu().numpy().astype(bool)
    arrays["input_names"] = np.array(INPUT_NAMES)
    arrays["target_names"] = np.array(TARGET_NAMES)
    arrays["config_hash"] = np.array(h)
    arrays["robot_config"] = np.array(json.dumps(_plain(robot_cfg), sort_keys=True))
    arrays["data_config"] = np.array(json.dumps(_plain(data_cfg), sort_keys=True))

    paths = {"npz": stem.with_name(stem.name + ".npz")}
    atomic_write(paths["npz"], lambda f: np.savez(f, **arrays))
    header = f"# config_hash={h}\n" + ",".join(COLUMN_NAMES)
    for name, t in tables.items():
        paths[name] = stem.with_name(f"{stem.name}_{name}.csv")
        atomic_write(paths[name], lambda f, t=t: np.savetxt(f, t, fmt="%.17g", delimiter=",", header=header, comments=""))
    return paths


def _check_hash(found: str, robot_cfg: Any, data_cfg: Any, path: Any) -> None:
    want = config_hash(robot_cfg, data_cfg)
    if found != want:
        raise DataMismatchError(
            f"{path} was made with config_hash={found}, but the current robot/data config has config_hash={want}; "
            "re-export the data (scripts/export_data.py) or use the matching config"
        )


def load_exported(path_npz: str | os.PathLike, robot_cfg: Any, data_cfg: Any) -> dict[str, np.ndarray]:
    """Arrays of an ``export`` npz; raises DataMismatchError if it was made with another robot/data config."""
    with np.load(path_npz, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    _check_hash(str(arrays["config_hash"]), robot_cfg, data_cfg, path_npz)
    return arrays


def load_csv(path: str | os.PathLike, robot_cfg: Any = None, data_cfg: Any = None) -> tuple[str, tuple[str, ...], np.ndarray]:
    """(config_hash, column names, float64 table) of an exported CSV; checks the hash when configs are given."""
    with open(path) as f:
        first, names = f.readline().strip(), tuple(f.readline().strip().split(","))
    if not first.startswith("# config_hash="):
        raise ValueError(f"{path}: first line should be '# config_hash=...', got {first!r}")
    h = first.split("=", 1)[1]
    if robot_cfg is not None or data_cfg is not None:
        _check_hash(h, robot_cfg, data_cfg, path)
    table = np.loadtxt(path, delimiter=",", skiprows=2, dtype=np.float64, ndmin=2)
    return h, names, table
