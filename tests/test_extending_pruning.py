"""A user's own pruning policy from outside the package (examples/extending/my_pruning.py), named by its import path
on the command line: it runs, checks its own parameters, and results.json records its class path."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from conftest import REPO

CMD = ["train.py", "schedule=infobatch", "schedule.pruning._target_=my_pruning.UniformPruning"]


def _run(*args: str, cmd: list[str] = CMD):
    path = os.pathsep.join([str(REPO / "examples" / "extending"), str(REPO), os.environ.get("PYTHONPATH", "")])
    env = {**{k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}, "PYTHONPATH": path}
    return subprocess.run([sys.executable, *cmd, *args], cwd=REPO, env=env, capture_output=True, text=True, timeout=600)


def test_a_users_pruning_policy_runs_from_the_command_line(tmp_path):
    p = _run("schedule.epochs=[3]", "replicas=2", f"hydra.run.dir={tmp_path}")
    assert p.returncode == 0, p.stderr[-2000:]
    res = json.loads((tmp_path / "results.json").read_text())
    pr = res["cost"]["per_replica"]
    assert res["selector"]["class"] == "my_pruning.UniformPruning" == res["selector"]["name"]
    assert res["schedule"]["sizes"] == [1002]  # the paper's exemplar set
    # by hand: all 3 epochs before delta * 3 = 2.625, each keeping int(0.5 * 1002) = 501 patterns, leaving out 501
    assert pr["trained"] == [3 * 501] * 2 and pr["left_out"] == [3 * 501.0] * 2
    assert res["status"] == "complete"
    # its name and cost come from it: its import path, and 3 x 501 of conventional's 3 x 1002 presentations
    assert res["selector"]["name"] == "my_pruning.UniformPruning" and res["schedule"]["cost_ratio"] == 0.5
    assert "(T_con/t at equal epochs 3,006; ratio 0.500)" in p.stdout


def test_a_users_own_selector_runs_the_schedules_stages_through_the_one_protocol(tmp_path):
    """examples/extending/my_selector.py: a plain Selector (no policy) on the paper's stages: it presents what the
    staged selector does (the same cost), weighted by its own scores (other numbers), and is named by its path."""
    args = ("schedule.epochs=[2,2,2,2,2]", "replicas=2")
    p = _run(
        *args, f"hydra.run.dir={tmp_path}", cmd=["train.py", "schedule.pruning={_target_:my_selector.LossWeighted}"]
    )
    assert p.returncode == 0, p.stderr[-2000:]
    plain = _run(*args, f"hydra.run.dir={tmp_path / 'plain'}", cmd=["train.py"])
    assert plain.returncode == 0, plain.stderr[-2000:]
    res = json.loads((tmp_path / "results.json").read_text())
    ref = json.loads((tmp_path / "plain" / "results.json").read_text())
    assert res["selector"]["name"] == "my_selector.LossWeighted" and ref["selector"]["name"] == "staged"
    assert res["selector"]["user_classes"] == ["my_selector.LossWeighted"] and set(res) == set(ref)
    assert res["cost"]["presentations"] == ref["cost"]["presentations"] == 2 * (50 + 100 + 400 + 800 + 1002)
    assert res["schedule"]["cost_ratio"] == ref["schedule"]["cost_ratio"] == 4704 / (10 * 1002)
    assert res["summary"]["heldout_rms_nm_overall"] != ref["summary"]["heldout_rms_nm_overall"]  # the weights count


def test_a_users_policy_checks_its_own_parameters(tmp_path):
    p = _run("schedule.epochs=[3]", "schedule.pruning.prune_ratio=1.5", f"hydra.run.dir={tmp_path / 'x'}")
    assert p.returncode == 2
    assert p.stderr.strip().splitlines() == [
        "error: schedule.pruning.prune_ratio=1.5 is not allowed: expected a share of the patterns in [0, 1)"
    ]
