"""Sampled exemplar sets for any arm and any n (issue 11, item 4): the paper's recipe without its grid.

The paper's grid (section 5.1: 5 values per angle and rate, 41 per torque) has 5^(2N) 41^N candidates, a
million for two joints and ~10^20 for six, so larger arms and larger sets are drawn instead. Two routes
(``data.route``):

* ``forward``, the paper's own: q, q̇, τ drawn in their boxes, q̈ from the simulator of eq. (5), patterns
  with any |q̈_i| > ``accel_limit`` dropped (the paper's filter). What it keeps shrinks about
  geometrically with N (0.1 % of the paper's two-link boxes); the acceptance rate is reported, and a
  route that would need more than ``MAX_DRAWS`` draws is refused after its first batch, with the rate.
* ``inverse``: q, q̇, q̈ drawn in their boxes (q̈ in ±``accel_limit``), τ from eq. (4). The inputs then
  cover their box evenly and nothing is dropped, unless ``data.tau`` bounds τ (then a filter, rate
  reported). One Newton-Euler pass per pattern: 10^6 PUMA 560 patterns take about a second here.

Points (``data.draw``): ``uniform`` pseudo-random, or ``sobol``, scrambled Sobol points
(``torch.quasirandom.SobolEngine``, Owen scrambling): every prefix of the sequence is low-discrepancy in
the 3N-dimensional unit cube, so a set covers its box more evenly than random points (a filter thins
the sequence but keeps the points it keeps where they were). A pattern's coordinates are one point:
(q, q̇, τ) or (q, q̇, q̈). The exemplar set draws from ``derive_seed(data.seed, "exemplar")`` and the
test sets from ``derive_seed(data.test_seed, "tests")``: independent streams even when the seeds are equal.

Boxes: ``data.q``, ``data.dq``, ``data.tau`` are ``[lo, hi]`` for every joint or one ``[lo, hi]`` per
joint. Defaults from the arm (a URDF's limits): ``data.q: null`` takes each joint's position limits but no
wider than a full turn ([-π, π] for a joint without), ``data.dq: null`` ±``DQ_FRACTION`` of its velocity limit
(±1 rad/s without), ``data.tau: null`` on the forward route ±its effort limit (when every joint has one). An
explicit box always wins; the job logs the boxes it drew from.
Inputs are laid out by quantity, ``q1..qN, dq1..dqN, ddq1..ddqN`` (targets ``tau1..tauN``).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import torch
from torch.quasirandom import SobolEngine

from selpres.arms.two_link import Arm, TwoLinkArm
from selpres.errors import ConfigError
from selpres.seeding import derive_seed

log = logging.getLogger("selpres")
DTYPE = torch.float64
MAX_N = 1_000_000  # exemplar patterns (and held-out patterns) a sampled set may ask for
MAX_DRAWS = 50_000_000  # a filtered route needing more draws than this is refused (minutes of simulation)
FIRST_BATCH = 1 << 16  # draws before the acceptance rate is known
MAX_BATCH = 1 << 20  # draws simulated at once (~0.2 GB of work arrays for six joints)
DQ_FRACTION = 0.5  # data.dq: null draws |q̇_i| within this share of joint i's velocity limit (±1 rad/s without)


def input_names(dof: int) -> tuple[str, ...]:
    """``q1..qN, dq1..dqN, ddq1..ddqN``: the network's inputs for an N-joint arm (grouped by quantity)."""
    return tuple(f"{p}{i}" for p in ("q", "dq", "ddq") for i in range(1, dof + 1))


def output_names(dof: int) -> tuple[str, ...]:
    return tuple(f"tau{i}" for i in range(1, dof + 1))


WRENCH_NAMES = ("k_fx", "k_fy", "k_fz", "k_mx", "k_my", "k_mz")  # eq. (4)'s k: force, then moment


@dataclass(frozen=True)
class Boxes:
    """Where patterns are drawn: ``[N, 2]`` (lo, hi) per joint for q, q̇ and τ (None: unbounded), the |q̈|
    limit, and the constant wrench k (None: zero)."""

    q: torch.Tensor
    dq: torch.Tensor
    accel: float
    tau: torch.Tensor | None
    wrench: torch.Tensor | None

    def third(self, route: str) -> torch.Tensor:
        """The box of the third drawn quantity: τ (forward) or q̈ (inverse)."""
        if route == "forward":
            return self.tau
        return torch.tensor([[-self.accel, self.accel]] * self.q.shape[0], dtype=DTYPE)


def _box(value: Any, key: str, dof: int) -> torch.Tensor:
    """``[lo, hi]`` (every joint) or ``[[lo, hi], ...]`` (one per joint) as ``[dof, 2]``."""
    rows = value if value and isinstance(value[0], (list, tuple)) else [value] * dof
    if len(rows) != dof:
        raise ConfigError(key, value, f"[lo, hi] for every joint or {dof} pairs [lo, hi], one per joint")
    out = []
    for i, row in enumerate(rows):
        where = key if rows is not value else f"{key}[{i}]"
        ok = (
            isinstance(row, (list, tuple))
            and len(row) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in row)
        )
        if not ok or not row[0] <= row[1]:
            raise ConfigError(where, row, "[lo, hi]: two finite numbers with lo <= hi")
        out.append([float(row[0]), float(row[1])])
    return torch.tensor(out, dtype=DTYPE)


def boxes(arm: Arm, data_cfg: Any) -> Boxes:
    """The boxes of a sampled data spec (``selpres.data.spec.DataSpec`` or a plain dict) for ``arm``; ConfigError
    naming ``data.<key>``."""
    dof, route = arm.dof, _value(data_cfg["route"])
    q = data_cfg["q"]
    if q is None:
        qbox = default_q_box(arm)
    else:
        qbox = _box(list(q), "data.q", dof)
    dq = data_cfg["dq"]
    if dq is None:
        rate = arm.rate_limits("velocity")
        dqbox = torch.stack((-rate, rate), 1).mul(DQ_FRACTION).nan_to_num(posinf=1.0, neginf=-1.0)
    else:
        dqbox = _box(list(dq), "data.dq", dof)
    accel = data_cfg["accel_limit"]
    if isinstance(accel, bool) or not isinstance(accel, (int, float)) or not (math.isfinite(accel) and accel > 0):
        raise ConfigError("data.accel_limit", accel, "a positive acceleration bound in rad/s²")
    tau = data_cfg["tau"]
    effort = arm.rate_limits("effort")
    if tau is None and route == "forward" and bool(torch.isfinite(effort).all()):
        tau = torch.stack((-effort, effort), 1).tolist()  # the file's effort limits
    if tau is None and route == "forward":
        raise ConfigError(
            "data.tau",
            None,
            "the torque box [lo, hi] (Nm) to draw τ from, for every joint or one "
            "pair per joint: route=forward simulates q̈ from drawn torques",
        )
    wrench = data_cfg["wrench"]
    k = None
    if wrench is not None:
        if len(wrench) != 6 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in wrench):
            raise ConfigError("data.wrench", list(wrench), "six finite numbers: force (N), then moment (Nm)")
        if any(v != 0 for v in wrench):
            if isinstance(arm, TwoLinkArm):
                raise ConfigError(
                    "data.wrench",
                    list(wrench),
                    "null for robot=two_link (eq. 6 has no wrench term); a serial or urdf arm takes one",
                )
            k = torch.tensor([float(v) for v in wrench], dtype=DTYPE)
    return Boxes(
        qbox,
        dqbox,
        float(accel),
        None if tau is None else _box(list(tau), "data.tau", dof),
        k,
    )


def default_q_box(arm: Arm) -> torch.Tensor:
    """``data.q: null``: each joint's position limits, but no wider than a full turn (a 2π window about the
    limits' middle: wider boxes repeat the same poses under other input values), [-π, π] for a joint without."""
    limits = arm.joint_limits()
    mid = torch.where(torch.isfinite(limits).all(1), limits.mean(1), torch.zeros(arm.dof, dtype=DTYPE))
    turn = torch.stack((mid - math.pi, mid + math.pi), 1)
    return torch.stack((torch.maximum(limits[:, 0], turn[:, 0]), torch.minimum(limits[:, 1], turn[:, 1])), 1)


def describe(box: Boxes, route: str) -> str:
    """The boxes a job draws from, one line (the log; results.json records them in full)."""
    fmt = lambda t: "[" + ", ".join(f"[{lo:.4g}, {hi:.4g}]" for lo, hi in t.tolist()) + "]"
    tau = "" if box.tau is None else f", tau {fmt(box.tau)} Nm"
    return f"boxes: q {fmt(box.q)} rad, dq {fmt(box.dq)} rad/s, |ddq| <= {box.accel:g} rad/s^2{tau} (route {route})"


def _value(v: Any) -> Any:
    return getattr(v, "value", v)  # an enum's value (typed configs), or the value itself


class Points:
    """Points of the unit cube, ``dims`` coordinates each, one stream: pseudo-random or scrambled Sobol."""

    def __init__(self, draw: str, dims: int, seed: int):
        if draw not in ("uniform", "sobol"):
            raise ConfigError("data.draw", draw, "uniform or sobol")
        self.draw, self.dims = draw, dims
        if draw == "sobol":
            self._engine = SobolEngine(dims, scramble=True, seed=seed)
        else:
            self._gen = torch.Generator().manual_seed(seed)

    def take(self, m: int) -> torch.Tensor:
        """The next ``m`` points, ``[m, dims]`` float64 in [0, 1)."""
        if self.draw == "sobol":
            return self._engine.draw(m, dtype=DTYPE)
        return torch.rand(m, self.dims, dtype=DTYPE, generator=self._gen)


@dataclass(frozen=True)
class Drawn:
    """Patterns of one route, ``[count, N]`` each, and how many draws it took to keep them."""

    q: torch.Tensor
    qd: torch.Tensor
    qdd: torch.Tensor
    tau: torch.Tensor
    candidates: int

    @property
    def X(self) -> torch.Tensor:
        """Inputs ``q1..qN, dq1..dqN, ddq1..ddqN``."""
        return torch.cat((self.q, self.qd, self.qdd), 1)


def _simulate(arm: Arm, route: str, q, qd, third, k) -> tuple[torch.Tensor, torch.Tensor]:
    """(q̈, τ): eq. (5) for the forward route, eq. (4) for the inverse one."""
    kw = {} if k is None else {"k": k}
    if route == "forward":
        return arm.forward_dynamics(q, qd, third, **kw), third
    return third, arm.inverse_dynamics(q, qd, third, **kw)


def sample(arm: Arm, box: Boxes, route: str, points: Points, count: int) -> Drawn:
    """``count`` patterns of ``route`` from ``points``, in draw order; the filter of the route keeps a
    pattern iff every |q̈_i| <= limit (forward) or τ lies in ``box.tau`` (inverse, when given)."""
    N = arm.dof
    third = box.third(route)
    lo = torch.cat((box.q[:, 0], box.dq[:, 0], third[:, 0]))
    width = torch.cat((box.q[:, 1], box.dq[:, 1], third[:, 1])) - lo
    filtered = route == "forward" or box.tau is not None
    empty = torch.empty(0, N, dtype=DTYPE)
    parts: list[tuple[torch.Tensor, ...]] = [(empty,) * 4]  # count = 0 (every test pattern from U): no rows
    have, drawn, candidates = 0, 0, 0
    while have < count:
        if not filtered:
            m = min(count - have, MAX_BATCH)
        elif have == 0:
            m = min(max(count, FIRST_BATCH), MAX_BATCH) if drawn == 0 else MAX_BATCH
        else:
            m = int(min(max(math.ceil((count - have) * drawn / have * 1.1), FIRST_BATCH), MAX_BATCH))
        v = lo + width * points.take(m)
        q, qd, x3 = v[:, :N], v[:, N : 2 * N], v[:, 2 * N :]
        qdd, tau = _simulate(arm, route, q, qd, x3, box.wrench)
        if route == "forward":
            keep = (qdd.abs() <= box.accel).all(1)
        elif box.tau is not None:
            keep = ((tau >= box.tau[:, 0]) & (tau <= box.tau[:, 1])).all(1)
        else:
            keep = torch.ones(m, dtype=torch.bool)
        idx = keep.nonzero().flatten()[: count - have]
        if have + len(idx) == count:
            candidates = drawn + int(idx[-1]) + 1
        parts.append(tuple(t[idx] for t in (q, qd, qdd, tau)))
        have, drawn = have + len(idx), drawn + m
        if have < count:
            _check_feasible(route, have, drawn, count)
    return Drawn(*(torch.cat([p[i] for p in parts]) for i in range(4)), candidates=candidates)


def _check_feasible(route: str, have: int, drawn: int, count: int) -> None:
    """Refuse (after a batch, deterministically) a filter that would need more than MAX_DRAWS draws."""
    need = drawn * count / have if have else math.inf
    if need > MAX_DRAWS or (have == 0 and drawn >= MAX_BATCH):
        rate = f"{have / drawn:.2e}" if have else f"0 (none of {drawn:,})"
        key, fix = (
            ("data.accel_limit", "widen the limit or the boxes, or use data.route=inverse")
            if route == "forward"
            else ("data.tau", "widen the torque box or set data.tau=null")
        )
        raise ConfigError(
            f"data.route={route} {key}",
            f"acceptance {rate}",
            f"a filter that keeps enough: {count:,} patterns would need about {need:.2g} draws, "
            f"at most {MAX_DRAWS:,} are allowed ({fix})",
        )


def stream(data_cfg: Any, dof: int, purpose: str) -> Points:
    """Points of 3N coordinates for ``purpose``: "exemplar" draws from ``derive_seed(data.seed,
    "exemplar")``, "tests" from ``derive_seed(data.test_seed, "tests")``."""
    seed = data_cfg[{"exemplar": "seed", "tests": "test_seed"}[purpose]]
    return Points(_value(data_cfg["draw"]), 3 * dof, derive_seed(int(seed), purpose))


def commanded_bounds(box: Boxes) -> tuple[torch.Tensor, ...] | None:
    """(x lo, x hi, τ lo, τ hi) of the boxes, for ``data.scaling.mode=commanded``; None without a τ box."""
    if box.tau is None:
        return None
    a = torch.full((box.q.shape[0],), box.accel, dtype=DTYPE)
    x0 = torch.cat((box.q[:, 0], box.dq[:, 0], -a))
    x1 = torch.cat((box.q[:, 1], box.dq[:, 1], a))
    return x0, x1, box.tau[:, 0], box.tau[:, 1]
