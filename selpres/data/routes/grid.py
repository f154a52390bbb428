"""``data.kind: grid`` (``data=paper``): the paper's section 5.1 on the two-link arm of eq. (6), exactly as Table 1
was computed (1002 patterns; the 10-pattern and held-out test sets of ``selpres.data.paper``)."""

from __future__ import annotations

from dataclasses import dataclass, replace

from selpres.arms.sources import SOURCES, make_arm
from selpres.arms.two_link import TwoLinkArm
from selpres.data import paper as D
from selpres.data.routes import DataRoute
from selpres.data.spec import DataSpec
from selpres.data.task import Shape, Task, check_test_split
from selpres.errors import ConfigError
from selpres.registry import Choice

MAX_GRID_CANDIDATES = 50_000_000  # ~3 GB of float64 work arrays in build_exemplar_set


@dataclass
class Range:
    lo: float
    hi: float
    step: float


class Grid(DataRoute):
    @dataclass
    class Keys:
        theta: Range  # both joints' angles (rad) and rates (rad/s), the torque boxes (Nm)
        dtheta: Range
        tau1: Range
        tau2: Range
        accel_limit: float  # keep rows with both |θ̈| <= accel_limit (rad/s²)

    def check(self, data: DataSpec) -> None:
        """A positive filter, whole steps, and not so many candidates that building the grid would exhaust memory."""
        if not data.accel_limit > 0:
            raise ConfigError("data.accel_limit", data.accel_limit, "a positive acceleration bound in rad/s²")
        points = {}
        for k in ("theta", "dtheta", "tau1", "tau2"):
            r = data.params[k]
            if not r["step"] > 0:
                raise ConfigError(f"data.{k}.step", r["step"], "a positive grid step")
            if not r["hi"] >= r["lo"]:
                raise ConfigError(f"data.{k}.hi", r["hi"], f"a value >= data.{k}.lo = {r['lo']}")
            try:
                points[k] = D.grid_points(r["lo"], r["hi"], r["step"], f"data.{k}")
            except ValueError:
                why = f"a step that divides hi - lo = {r['hi'] - r['lo']:g} into whole steps"
                raise ConfigError(f"data.{k}.step", r["step"], why) from None
        candidates = points["theta"] ** 2 * points["dtheta"] ** 2 * points["tau1"] * points["tau2"]
        if candidates > MAX_GRID_CANDIDATES:
            finest = max(points, key=points.get)
            raise ConfigError(
                f"data.{finest}.step",
                data.params[finest]["step"],
                f"a coarser step: the grid (θ² × θ̇² × τ1 × τ2 points) would have {candidates:,} candidates, "
                f"at most {MAX_GRID_CANDIDATES:,} are allowed (the paper's has 1,050,625)",
            )

    def shape(self, robot: Choice, data: DataSpec) -> Shape:
        arm = make_arm(robot)
        if not isinstance(arm, TwoLinkArm):
            raise ConfigError(
                "data.kind",
                "grid",
                f"sampled (data=sampled) for robot={arm.name} ({arm.dof} joints): "
                "the paper's grid (data=paper) is defined for robot=two_link only",
            )
        return Shape(D.INPUT_NAMES, D.TARGET_NAMES, "robot=two_link (2 joints, data=paper)")

    def build(self, robot: Choice, data_cfg: DataSpec) -> Task:
        arm = make_arm(robot)
        exemplar = D.build_exemplar_set(arm, data_cfg)
        n = len(exemplar)
        if n == 0:
            raise ConfigError(
                "data.accel_limit",
                data_cfg.accel_limit,
                f"a filter that keeps at least one of the {exemplar.n_candidates:,} grid candidates of "
                "data.theta/dtheta/tau1/tau2 (none has both |θ̈| within it: widen the limit or move the ranges)",
            )
        check_test_split(data_cfg, n)
        heldout = D.heldout_count(data_cfg.heldout, n, f"n = {n}")
        data_cfg = replace(data_cfg, heldout=heldout)
        try:
            tests = D.make_test_sets(arm, data_cfg, exemplar, seed=data_cfg.test_seed)
        except ValueError as e:  # the continuous ranges leave nothing to draw test patterns from
            raise ConfigError("data", "theta/dtheta/tau1/tau2 ranges", str(e)) from None
        info = {
            "kind": "grid",
            "source": "the paper's grid on robot=two_link",
            "candidates": exemplar.n_candidates,
            "acceptance_rate": n / exemplar.n_candidates,
            "n": n,
            "arm": arm.to_config(),
            "arm_source": SOURCES.path_of(robot.target),
        }
        task = Task(exemplar, tests, None, info=info, arm=arm.to_config(), commanded=D.grid_bounds(data_cfg))
        return replace(task, scaler=task.fit_scaler(data_cfg))


ROUTE = Grid
