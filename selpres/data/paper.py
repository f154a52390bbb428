"""Exemplar set, test sets, sigmoid-range scaling and export (paper section 5.1).

The paper's grid route: network input (θ1, θ̇1, θ̈1, θ2, θ̇2, θ̈2) and target (τ1, τ2), patterns that the
forward simulator (eq. 5) generated on a grid. Other arms and sizes are drawn by ``selpres.data.sampled``,
users' tables read by ``selpres.data.file``; scaling, the RMS metric and export here serve all of them
(any number of inputs and outputs). All functions are pure in their arguments; randomness comes only from
an explicit ``torch.Generator`` or seed.
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

from selpres.arms.two_link import TwoLinkArm, cfg_get, make_arm
from selpres.data.file import file_digest
from selpres.errors import ConfigError
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
    """Input rows ``X [n, inputs]`` and targets ``Y [n, outputs]`` (Nm for an arm), float64; the grid
    route's columns are INPUT_NAMES and TARGET_NAMES."""

    X: torch.Tensor
    Y: torch.Tensor

    def __iter__(self):  # allows ``X, Y = patterns``
        return iter((self.X, self.Y))

    def __len__(self) -> int:
        return int(self.X.shape[0])


@dataclass(frozen=True)
class ExemplarSet(Patterns):
    """The exemplar set U (the paper's 1002 patterns with the default robot) and how many candidates (grid
    points, draws or file rows) it came from."""

    n_candidates: int = 0


@dataclass(frozen=True)
class TestSets:
    """``test10``: the paper's 10 random test patterns (``test10_from_exemplar`` marks the rows taken from
    the exemplar set); ``heldout``: many outside patterns, for a metric that is not dominated by noise."""

    test10: Patterns
    test10_from_exemplar: torch.Tensor
    heldout: Patterns


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


def grid_bounds(data_cfg: Any) -> tuple[torch.Tensor, ...]:
    """(x lo, x hi, τ lo, τ hi) the grid route commands: its θ, θ̇ ranges, ±accel_limit and τ boxes."""
    th, w = _range(data_cfg, "theta"), _range(data_cfg, "dtheta")
    a = float(cfg_get(data_cfg, "accel_limit"))
    x0 = torch.tensor([th[0], w[0], -a, th[0], w[0], -a], dtype=DTYPE)
    x1 = torch.tensor([th[1], w[1], a, th[1], w[1], a], dtype=DTYPE)
    t1, t2 = _range(data_cfg, "tau1"), _range(data_cfg, "tau2")
    return x0, x1, torch.tensor([t1[0], t2[0]], dtype=DTYPE), torch.tensor([t1[1], t2[1]], dtype=DTYPE)


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

    x_min: torch.Tensor  # data-side bounds (margin already applied), [inputs]
    x_max: torch.Tensor
    y_min: torch.Tensor  # [outputs]
    y_max: torch.Tensor
    lo: float = 0.1
    hi: float = 0.9

    @classmethod
    def fit(cls, exemplar: Patterns, data_cfg: Any, commanded: tuple[torch.Tensor, ...] | None = None) -> Scaler:
        """Bounds from the exemplar set (mode exemplar) or the commanded boxes: ``commanded`` = (x lo, x hi,
        y lo, y hi) when given, else the grid route's θ, θ̇, ±accel_limit and τ boxes."""
        sc = cfg_get(data_cfg, "scaling")
        mode = str(getattr(cfg_get(sc, "mode"), "value", cfg_get(sc, "mode")))  # a typed config holds an enum
        margin = float(cfg_get(sc, "margin"))
        if mode == "exemplar":
            x0, x1 = exemplar.X.min(0).values, exemplar.X.max(0).values
            y0, y1 = exemplar.Y.min(0).values, exemplar.Y.max(0).values
        elif mode == "commanded":
            x0, x1, y0, y1 = grid_bounds(data_cfg) if commanded is None else commanded
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


def metric_names(n_outputs: int) -> tuple[str, ...]:
    """``overall, tau1..tauK``: the per-output keys of ``rms_errors`` (output k is "tau<k>" whatever its
    column is called, so results.json reads alike for every arm and data file)."""
    return ("overall", *(f"tau{k}" for k in range(1, n_outputs + 1)))


def rms_errors(pred_scaled: torch.Tensor, Y_true_Nm: torch.Tensor, scaler: Scaler) -> dict[str, torch.Tensor]:
    """The paper's criterion, RMS of (network output − actual output), in Nm and in scaled units.

    ``pred_scaled`` is ``[..., N, K]`` (e.g. a leading replica dim R); every value has the leading shape
    ``[...]``. Keys ``<name>_Nm`` and ``<name>_scaled`` for every name of ``metric_names(K)`` (tau1_Nm, …,
    overall_Nm, …); overall = sqrt of the mean squared error over all outputs and all patterns.
    """
    Y_true_Nm = Y_true_Nm.to(pred_scaled)
    out: dict[str, torch.Tensor] = {}
    for unit, err in (
        ("Nm", scaler.inverse_y(pred_scaled) - Y_true_Nm),
        ("scaled", pred_scaled - scaler.transform_y(Y_true_Nm)),
    ):
        sq = err.square()
        per_joint = sq.mean(-2).sqrt()  # [..., K]
        for k, name in enumerate(metric_names(per_joint.shape[-1])[1:]):
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


def data_kind(data_cfg: Any) -> str:
    """grid, sampled or file (a data config without ``kind`` is the paper's grid)."""
    try:
        kind = cfg_get(data_cfg, "kind")
    except (KeyError, AttributeError):
        return "grid"
    return str(getattr(kind, "value", kind))


def _set_keys(node: Any) -> Any:
    """Drop unset (None) keys: the keys another kind uses, which a composed config holds and a YAML lacks."""
    if isinstance(node, dict):
        return {k: _set_keys(v) for k, v in node.items() if v is not None}
    return node


def config_hash(robot_cfg: Any, data_cfg: Any) -> str:
    """Identity of the data: a stable hash of what made it. The arm enters canonically, by
    ``make_arm(robot).to_config()`` (a URDF's content, not its path; no arm for a data file); a data
    file by the sha256 of its bytes instead of its path; unset keys are left out and ints folded into
    floats, so a composed config, its YAML and ``m2: 3`` vs ``3.0`` hash alike."""
    data = _set_keys(_plain(data_cfg))
    if data_kind(data_cfg) == "file":
        data["path"] = file_digest(cfg_get(data_cfg, "path"))
        robot = None
    else:
        robot = _plain(make_arm(robot_cfg).to_config())
    return stable_hash({"robot": robot, "data": data})


def _table(p: Patterns, wrench: torch.Tensor | None) -> np.ndarray:
    cols = [p.X, p.Y] + ([] if wrench is None else [wrench.expand(len(p), -1)])
    return torch.cat(cols, 1).cpu().numpy().astype(np.float64)


def export(
    path_stem: str | os.PathLike,
    exemplar: ExemplarSet,
    tests: TestSets,
    robot_cfg: Any,
    data_cfg: Any,
    *,
    input_names: tuple[str, ...] = INPUT_NAMES,
    target_names: tuple[str, ...] = TARGET_NAMES,
    arm: dict | None = None,
    wrench: torch.Tensor | None = None,
) -> dict[str, Path]:
    """Write ``<stem>.npz`` and ``<stem>_{exemplar,test10,heldout}.csv`` (``%.17g``: exact float64
    round trip). The CSVs start with ``# config_hash=...`` and, when an arm made the data,
    ``# arm=<its to_config() as JSON>``; then the header: the input names, the target names and, for a
    non-zero wrench k, its six constant columns ``k_fx..k_mz`` (eq. 4's force, then moment, base frame)."""
    stem = Path(path_stem)
    h = config_hash(robot_cfg, data_cfg)
    if wrench is not None and not bool(wrench.ne(0).any()):
        wrench = None
    from selpres.data.sampled import WRENCH_NAMES  # the wrench's column names belong to the sampled routes

    columns = tuple(input_names) + tuple(target_names) + (WRENCH_NAMES if wrench is not None else ())
    n_in = len(input_names)
    tables = {
        name: _table(p, wrench)
        for name, p in (("exemplar", exemplar), ("test10", tests.test10), ("heldout", tests.heldout))
    }
    arrays: dict[str, np.ndarray] = {}
    for name, t in tables.items():
        arrays[f"{name}_X"], arrays[f"{name}_Y"] = t[:, :n_in], t[:, n_in : n_in + len(target_names)]
    arrays["test10_from_exemplar"] = tests.test10_from_exemplar.cpu().numpy().astype(bool)
    arrays["input_names"] = np.array(input_names)
    arrays["target_names"] = np.array(target_names)
    arrays["config_hash"] = np.array(h)
    arrays["robot_config"] = np.array(json.dumps(_plain(robot_cfg), sort_keys=True))
    arrays["data_config"] = np.array(json.dumps(_plain(data_cfg), sort_keys=True))
    if arm is not None:
        arrays["arm"] = np.array(json.dumps(arm, sort_keys=True))
    if wrench is not None:
        arrays["wrench"] = wrench.cpu().numpy()

    paths = {"npz": stem.with_name(stem.name + ".npz")}
    atomic_write(paths["npz"], lambda f: np.savez(f, **arrays))
    arm_line = f"# arm={json.dumps(arm, sort_keys=True)}\n" if arm else ""
    header = f"# config_hash={h}\n" + arm_line + ",".join(columns)
    for name, t in tables.items():
        paths[name] = stem.with_name(f"{stem.name}_{name}.csv")
        atomic_write(
            paths[name], lambda f, t=t: np.savetxt(f, t, fmt="%.17g", delimiter=",", header=header, comments="")
        )
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


def load_csv(
    path: str | os.PathLike, robot_cfg: Any = None, data_cfg: Any = None
) -> tuple[str, tuple[str, ...], np.ndarray]:
    """(config_hash, column names, float64 table) of an exported CSV; checks the hash when configs are given."""
    comments = []
    with open(path) as f:
        line = f.readline().strip()
        while line.startswith("#"):
            comments.append(line)
            line = f.readline().strip()
    names = tuple(line.split(","))
    if not comments or not comments[0].startswith("# config_hash="):
        raise ValueError(f"{path}: first line should be '# config_hash=...', got {(comments or [line])[0]!r}")
    h = comments[0].split("=", 1)[1]
    if robot_cfg is not None or data_cfg is not None:
        _check_hash(h, robot_cfg, data_cfg, path)
    table = np.loadtxt(path, delimiter=",", skiprows=len(comments) + 1, dtype=np.float64, ndmin=2)
    return h, names, table
