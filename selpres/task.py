"""The learning task a robot/data config defines: the exemplar set U, the test sets and the scaler.

Built once per (robot, data) config and cached, so the jobs of an in-process sweep (Hydra's basic launcher)
build the data once; cached tensors are never modified in place. Problems a config causes here (a filter
that keeps nothing, ranges with nothing to draw test patterns from) are ConfigErrors naming the key.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass

import torch
from omegaconf import DictConfig, OmegaConf

from selpres import data as D
from selpres.config import to_container
from selpres.errors import ConfigError
from selpres.robot import TwoLinkArm


@dataclass(frozen=True)
class Task:
    """Exemplar inputs/targets (raw units), the paper's 10 test patterns and the held-out set, the scaler."""

    exemplar: D.ExemplarSet
    tests: D.TestSets
    scaler: D.Scaler
    input_names: tuple[str, ...] = D.INPUT_NAMES
    output_names: tuple[str, ...] = D.TARGET_NAMES

    @property
    def n(self) -> int:
        return len(self.exemplar)

    def scaled_tests(self) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
        """name -> (inputs scaled, targets in Nm): what the network is scored on."""
        return {
            name: (self.scaler.transform_x(p.X), p.Y)
            for name, p in (("test10", self.tests.test10), ("heldout", self.tests.heldout))
        }


def load_task(robot_cfg: DictConfig, data_cfg: DictConfig) -> Task:
    """The task of a robot/data config (cached); raises ConfigError, writes nothing."""
    return _task(
        json.dumps(to_container(robot_cfg), sort_keys=True), json.dumps(to_container(data_cfg), sort_keys=True)
    )


@functools.lru_cache(maxsize=4)
def _task(robot_json: str, data_json: str) -> Task:
    arm, data_cfg = TwoLinkArm.from_config(json.loads(robot_json)), OmegaConf.create(json.loads(data_json))
    exemplar = D.build_exemplar_set(arm, data_cfg)
    n = len(exemplar)
    if n == 0:
        raise ConfigError(
            "data.accel_limit",
            data_cfg.accel_limit,
            f"a filter that keeps at least one of the {exemplar.n_candidates:,} grid candidates of "
            "data.theta/dtheta/tau1/tau2 (none has both |θ̈| within it: widen the limit or move the ranges)",
        )
    if data_cfg.test_from_exemplar > n:
        raise ConfigError(
            "data.test_from_exemplar", data_cfg.test_from_exemplar, f"at most the exemplar set's size n = {n}"
        )
    try:
        tests = D.make_test_sets(arm, data_cfg, exemplar, seed=data_cfg.test_seed)
    except ValueError as e:  # the continuous ranges leave nothing to draw test patterns from
        raise ConfigError("data", "theta/dtheta/tau1/tau2 ranges", str(e)) from None
    return Task(exemplar, tests, D.Scaler.fit(exemplar, data_cfg))
