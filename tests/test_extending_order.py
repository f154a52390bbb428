"""A user's own order from outside the package (examples/extending/my_order.py, and a module written here), named by
its import path on the command line: it is what the job presents, a stage-wise one is charged by the one rule,
results.json records its class path, and a bad path is one line naming schedule.order."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

from conftest import REPO, numbers

TWINS = """
import torch
from selpres.presentation.orders import Order


class RandomTwin(Order):  # written again from the built-in's definition: one torch.randperm per replica
    def orders(self, X, gens):
        return [torch.randperm(X.shape[0], generator=g) for g in gens]


class Backwards(RandomTwin):
    def orders(self, X, gens):
        return [o.flip(0) for o in super().orders(X, gens)]
"""
SMALL = ("replicas=2", "schedule.epochs=[2,1,1,1,1]", "engine=torch")
SIZES = [50, 100, 400, 800, 1002]  # the paper's stages (configs/schedule/selective.yaml)


def _run(tmp_path, name: str, *args: str):
    path = os.pathsep.join([str(tmp_path), str(REPO / "examples" / "extending"), str(REPO)])
    env = {**{k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}, "PYTHONPATH": path}
    cmd = [sys.executable, "train.py", *SMALL, *args, f"hydra.run.dir={tmp_path / name}"]
    return subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)


def _results(tmp_path, name: str, *args: str) -> dict:
    p = _run(tmp_path, name, *args)
    assert p.returncode == 0, p.stderr[-2000:]
    return json.loads((tmp_path / name / "results.json").read_text())


def _numbers(res: dict) -> dict:
    """The numbers (conftest.numbers) without the schedule and the job's hash, which name the order that ran."""
    kept = {k: v for k, v in numbers(res).items() if k not in ("schedule", "config_hash")}
    return kept | {"done": res["presentations_done"]}


def test_a_users_order_is_what_the_job_presents(tmp_path):
    (tmp_path / "twin_orders.py").write_text(TWINS)
    builtin = _results(tmp_path, "random", "schedule.order=random")
    twin = _results(tmp_path, "twin", "schedule.order=twin_orders.RandomTwin")
    backwards = _results(tmp_path, "backwards", "schedule.order=twin_orders.Backwards")
    assert twin["schedule"]["order"] == twin["schedule"]["order_class"] == "twin_orders.RandomTwin"
    assert builtin["schedule"]["order_class"] == "selpres.presentation.orders.random.Random"
    assert _numbers(twin) == _numbers(builtin)  # the same permutations, written twice: the same numbers
    assert _numbers(backwards)["summary"] != _numbers(builtin)["summary"]  # another order: other numbers


def test_the_example_orders_run_from_the_command_line(tmp_path):
    res = _results(tmp_path, "centre", "schedule.order=my_order.CentreOut")
    assert res["schedule"]["order_class"] == "my_order.CentreOut" and res["status"] == "complete"
    assert res["selection_presentations"] == 0
    staged = _results(tmp_path, "redrawn", "schedule.order=my_order.Redrawn")
    assert staged["schedule"]["order_class"] == "my_order.Redrawn"
    # by hand: every pattern of U scored at each of the 4 enlargements at 1/3 of a presentation: 4 x ceil(334)
    assert staged["selection_presentations"] == 4 * math.ceil(1002 / 3) == 1336
    training = 2 * SIZES[0] + sum(SIZES[1:])
    assert staged["training_presentations"] == training and staged["presentations_done"] == training + 1336


def test_a_bad_order_is_one_line_naming_schedule_order(tmp_path):
    for value, why in (
        ("zigzag", "one of coverage, loss_high, loss_low, random, reselect, stratified, or a class"),
        ("my_order.Nowhere", "a name defined in module my_order (it has no 'Nowhere')"),
        ("no_such_module.Order", "an importable module (no_such_module"),
        ("my_order.generator", "a subclass of selpres.presentation.orders.Order or StagewiseOrder"),
    ):
        p = _run(tmp_path, value, f"schedule.order={value}")
        assert p.returncode == 2, (value, p.stderr[-2000:])
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"error: schedule.order={value!r} is not allowed: expected ")
        assert why in lines[0], lines[0]
        assert not (tmp_path / value).exists() or not any((tmp_path / value).iterdir())
