"""``data.kind: grid`` (``data=paper``): the paper's section 5.1 on the two-link arm of eq. (6), exactly as Table 1
was computed (1002 patterns; the 10-pattern and held-out test sets of ``selpres.data.paper``)."""

from __future__ import annotations

from dataclasses import replace

from selpres.arms.sources import SOURCES, make_arm
from selpres.arms.two_link import TwoLinkArm
from selpres.data import paper as D
from selpres.data.routes import DataRoute
from selpres.data.spec import DataSpec
from selpres.data.task import Shape, Task, check_test_split
from selpres.errors import ConfigError
from selpres.registry import Choice


class Grid(DataRoute):
    KEYS = ("theta", "dtheta", "tau1", "tau2", "accel_limit")

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
