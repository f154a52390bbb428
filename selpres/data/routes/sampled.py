"""``data.kind: sampled`` (``data=sampled``): any arm, any n, drawn by ``selpres.data.sampled`` (route forward or
inverse, uniform or Sobol points); test sets drawn the same way from ``data.test_seed``."""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from enum import Enum
from typing import Any

import torch

from selpres.arms.sources import SOURCES, make_arm
from selpres.data import paper as D
from selpres.data import sampled as S
from selpres.data.routes import DataRoute
from selpres.data.spec import DataSpec
from selpres.data.task import Shape, Task, check_test_split
from selpres.errors import ConfigError
from selpres.patterns import ExemplarSet, Patterns, TestSets
from selpres.registry import Choice

log = logging.getLogger("selpres")


class Route(Enum):
    forward = "forward"  # the paper's route: q, q̇, τ drawn, q̈ simulated (eq. 5), |q̈| > accel_limit dropped
    inverse = "inverse"  # q, q̇, q̈ drawn, τ from eq. (4); kept unless data.tau bounds it


class Draw(Enum):
    uniform = "uniform"  # pseudo-random points (a seeded torch.Generator)
    sobol = "sobol"  # scrambled Sobol points (torch.quasirandom.SobolEngine): every prefix low-discrepancy


class Sampled(DataRoute):
    @dataclass
    class Keys:
        n: int  # exemplar set size
        route: Route
        draw: Draw
        seed: int  # the exemplar set's draws (the test sets draw from test_seed)
        accel_limit: float  # |q̈| bound (rad/s²): q̈'s box (inverse) or a filter (forward)
        q: list[Any] | None = None  # [lo, hi] for every joint or one per joint; null: the joint limits
        dq: list[Any] | None = None
        tau: list[Any] | None = None  # torque box (forward: drawn from it; inverse: a filter)
        wrench: list[float] | None = None  # constant k of eq. (4), base frame, (force, moment)

    def check(self, data: DataSpec) -> None:
        if not data.accel_limit > 0:
            raise ConfigError("data.accel_limit", data.accel_limit, "a positive acceleration bound in rad/s²")
        if not 1 <= data.n <= S.MAX_N:
            raise ConfigError("data.n", data.n, f"a whole number of patterns in [1, {S.MAX_N:,}]")
        if isinstance(data.heldout, int) and data.heldout > S.MAX_N:
            raise ConfigError("data.heldout", data.heldout, f"at most {S.MAX_N:,} held-out patterns")

    def shape(self, robot: Choice, data: DataSpec) -> Shape:
        arm = make_arm(robot)
        N = arm.dof
        S.boxes(arm, data)  # data.q, dq, tau, wrench against the arm's joints
        return Shape(
            S.input_names(N),
            S.output_names(N),
            f"robot={arm.name} ({N} joints)",
            f"q1..q{N}, dq1..dq{N}, ddq1..ddq{N}",
            f"tau1..tau{N}",
        )

    def build(self, robot: Choice, data_cfg: DataSpec) -> Task:
        arm = make_arm(robot)
        box = S.boxes(arm, data_cfg)
        route, draw, n = data_cfg.route, data_cfg.draw, int(data_cfg.n)
        log.info("%s", S.describe(box, route))
        drawn = S.sample(arm, box, route, S.stream(data_cfg, arm.dof, "exemplar"), n)
        exemplar = ExemplarSet(drawn.X, drawn.tau, n_candidates=drawn.candidates)
        n_test, n_ex = check_test_split(data_cfg, n)
        gen = torch.Generator().manual_seed(int(data_cfg.test_seed))
        idx = torch.randperm(n, generator=gen)[:n_ex]
        points = S.stream(data_cfg, arm.dof, "tests")
        outside = S.sample(arm, box, route, points, n_test - n_ex)
        heldout = S.sample(arm, box, route, points, D.heldout_count(data_cfg.heldout, n, f"n = {n}"))
        test10 = Patterns(torch.cat((exemplar.X[idx], outside.X)), torch.cat((exemplar.Y[idx], outside.tau)))
        tests = TestSets(test10, torch.arange(n_test) < n_ex, Patterns(heldout.X, heldout.tau))
        info = {
            "kind": "sampled",
            "source": f"robot={arm.name}, route {route}, {draw} points",
            "route": route,
            "draw": draw,
            "n": n,
            "candidates": drawn.candidates,
            "acceptance_rate": n / drawn.candidates,
            "heldout_candidates": heldout.candidates,
            "arm": arm.to_config(),
            "arm_source": SOURCES.path_of(robot.target),
            "wrench": None if box.wrench is None else box.wrench.tolist(),
            "boxes": {
                k: None if v is None else v.tolist() for k, v in (("q", box.q), ("dq", box.dq), ("tau", box.tau))
            },
            **({"urdf": arm.source} if getattr(arm, "source", None) else {}),
        }
        task = Task(
            exemplar,
            tests,
            None,
            S.input_names(arm.dof),
            S.output_names(arm.dof),
            info,
            arm.to_config(),
            box.wrench,
            S.commanded_bounds(box),
        )
        return replace(task, scaler=task.fit_scaler(data_cfg))


ROUTE = Sampled
