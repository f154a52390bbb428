"""Arm sources (selpres.arms.sources): a registry of modules, a user's own class by its import path from the
command line, and the files a source reads keying its task, so an edited file is never served stale."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
import torch
from omegaconf import OmegaConf

import selpres.data.task as T
from selpres.arms.sources import SOURCES, as_choice, make_arm
from selpres.arms.two_link import TwoLinkArm
from selpres.errors import ConfigError
from selpres.registry import Choice
from selpres.run.specs import data_spec

from conftest import CONFIGS, REPO, compose

EXTENDING = REPO / "examples" / "extending"
SMALL = ("data=sampled", "data.n=200", "data.heldout=50")


@pytest.fixture
def extending(monkeypatch):
    monkeypatch.syspath_prepend(str(EXTENDING))
    T._task.cache_clear()
    yield
    T._task.cache_clear()


def test_the_built_in_sources_are_the_modules_and_every_robot_file_names_one():
    assert SOURCES.names == ("serial", "two_link", "urdf")
    assert SOURCES.path_of("two_link") == "selpres.arms.sources.two_link.TwoLink"
    for path in (CONFIGS / "robot").glob("*.yaml"):  # by import path, whose alias is the built-in's name
        assert SOURCES.canonical(OmegaConf.load(path)["_target_"]) in SOURCES.names, path


def test_the_old_kind_is_refused_naming_target_and_old_results_still_read():
    with pytest.raises(ConfigError, match=r"robot.kind='urdf' is not allowed: expected unset: the arm source is robot"):
        as_choice({"_target_": "two_link", "m1": 1.0, "kind": "urdf"})
    with pytest.raises(ConfigError, match=r"robot._target_=None is not allowed: expected an arm source: one of serial"):
        as_choice({"m1": 1.0})
    # a results.json of before issue 25: kind plus every other kind's keys unset
    old = {"kind": "two_link", "m1": 0.42, "m2": 3.0, "l1": 0.2, "l2": 0.26, "g": 9.81, "path": None, "links": None}
    assert make_arm(old) == TwoLinkArm(0.42, 3.0, 0.2, 0.26, 9.81)


def test_the_dh_table_example_is_the_papers_arm(extending):
    """An independent derivation: the DH table of two point masses is eq. (6)'s closed form."""
    from dh_arm import DHTable

    arm = DHTable(str(EXTENDING / "two_link.dh"), [0, -9.81, 0]).arm()
    g = torch.Generator().manual_seed(0)
    q, qd, qdd = (4 * torch.rand(200, 2, dtype=torch.float64, generator=g) - 2 for _ in range(3))
    paper = TwoLinkArm(0.42, 3.0, 0.2, 0.26, 9.81).inverse_dynamics(q, qd, qdd)
    assert (arm.inverse_dynamics(q, qd, qdd) - paper).abs().max() < 1e-12
    with pytest.raises(ConfigError, match=r"robot.gravity=\[0, 1\] is not allowed"):
        DHTable("x.dh", [0, 1])


def _dh_task(table, target="dh_arm.DHTable", key="path"):
    robot = Choice(target, {key: str(table), "gravity": [0.0, -9.81, 0.0]})
    return T.load_task(robot, data_spec(compose(*SMALL).data))


def _mass(table, m2):
    table.write_text((EXTENDING / "two_link.dh").read_text().replace("3.00", str(m2)))


@pytest.mark.parametrize("forgetful", [False, True])
def test_a_users_file_reading_source_is_never_served_stale(extending, tmp_path, monkeypatch, forgetful):
    """A source from outside the package that reads a file: its task is keyed by the file's stamp and not stored,
    so an edit is read again, in the same process and by the next one (the job's identity changes too). A source
    that forgets to declare the file (no reads_files) is still covered: a parameter naming a file counts."""
    from selpres.run.results import job_hash

    cache = tmp_path / "cache"
    monkeypatch.setenv("SELPRES_DATA_CACHE", str(cache))
    (tmp_path / "forgets.py").write_text(
        "from dh_arm import DHTable\n\n\nclass Forgets:  # reads a table, declares nothing\n"
        "    def __init__(self, table, gravity=None):\n        self.inner = DHTable(table, gravity)\n\n"
        "    def arm(self):\n        return self.inner.arm()\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    target, key = ("forgets.Forgets", "table") if forgetful else ("dh_arm.DHTable", "path")
    table = tmp_path / "arm.dh"
    means, hashes = [], []
    for m2 in (3.0, 4.5):
        _mass(table, m2)
        task = _dh_task(table, target, key)
        means.append(float(task.exemplar.Y.abs().mean()))
        assert task.info["cache"].startswith("not stored") and task.info["arm_source"] == target
        cfg = compose(*SMALL, "~robot", f"+robot._target_={target}", f"+robot.{key}={table}")
        hashes.append(job_hash(cfg))
    assert means[0] != means[1] and hashes[0] != hashes[1] and not cache.exists()
    assert T.task_files(Choice(target, {key: str(table)}), data_spec(compose(*SMALL).data)) == [table]


def test_a_users_source_module_is_part_of_the_stored_tasks_key(extending, tmp_path, monkeypatch):
    """A user's source that reads no file is stored; an edit to its module is an edit to the task's code."""
    monkeypatch.setenv("SELPRES_DATA_CACHE", str(tmp_path / "cache"))
    module = tmp_path / "inline_arm.py"
    module.write_text(
        "from selpres.arms.two_link import TwoLinkArm\n\n\nclass Inline:\n    def __init__(self, m2):\n"
        "        self.m2 = m2\n\n    def arm(self):\n        return TwoLinkArm(0.42, self.m2, 0.2, 0.26, 9.81)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    robot, data = Choice("inline_arm.Inline", {"m2": 3.0}), data_spec(compose(*SMALL).data)
    assert T.load_task(robot, data).info["cache"].startswith("stored")
    T._task.cache_clear()
    assert T.load_task(robot, data).info["cache"].startswith("hit")
    module.write_text(module.read_text() + "# edited\n")
    T._task.cache_clear()
    assert T.load_task(robot, data).info["cache"].startswith("stored")  # a new key, not the old entry


@pytest.mark.slow
def test_a_users_arm_source_runs_from_the_command_line(tmp_path):
    """``PYTHONPATH=examples/extending python train.py '~robot' +robot._target_=dh_arm.DHTable ...``: the job runs
    the user's class and results.json records its path; a bad key of it is one line naming robot.<key>."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(["examples/extending", os.environ.get("PYTHONPATH", "")])}
    env.pop("HYDRA_FULL_ERROR", None)
    args = [
        "~robot",
        "+robot._target_=dh_arm.DHTable",
        "+robot.path=examples/extending/two_link.dh",
        "+robot.gravity=[0,-9.81,0]",
        *SMALL,
        "topology.layers=6-4-2",
        "schedule=conventional",
        "schedule.epochs=[2]",
        "logging.tensorboard=false",
    ]
    run = lambda *more: subprocess.run(  # noqa: E731
        [sys.executable, "train.py", *args, *more], cwd=REPO, env=env, capture_output=True, text=True, timeout=300
    )
    done = run(f"hydra.run.dir={tmp_path / 'run'}")
    assert done.returncode == 0, done.stderr[-2000:]
    res = json.loads((tmp_path / "run" / "results.json").read_text())
    assert res["status"] == "complete" and res["data"]["arm_source"] == "dh_arm.DHTable"
    assert res["config"]["robot"]["_target_"] == "dh_arm.DHTable"
    bad = run("+robot.mass=3", f"hydra.run.dir={tmp_path / 'bad'}")
    assert bad.returncode == 2 and "error: robot.mass=3 is not allowed: expected one of the keys" in bad.stderr
    assert "Traceback" not in bad.stderr and not (tmp_path / "bad").exists()
    old = subprocess.run(  # the spelling before issue 25, appended as Hydra's own refusal of robot.kind=urdf suggests
        [sys.executable, "train.py", "+robot.kind=urdf", f"hydra.run.dir={tmp_path / 'old'}"],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert (
        old.returncode == 2
        and "error: robot.kind='urdf' is not allowed: expected unset: the arm source is " in old.stderr
    )
    assert "robot._target_ now (robot=urdf picks its node)" in old.stderr and not (tmp_path / "old").exists()


def test_data_routes_are_the_modules_and_say_what_they_read(tmp_path):
    """The data routes (selpres.data.routes) the same way: the built-ins are the modules, each names the keys it
    reads (what run.checks holds a config to) and the files it reads (a data file, not the arm's)."""
    from selpres.data.routes import ROUTES

    assert ROUTES.names == ("file", "grid", "sampled")
    assert T.route_keys() == {
        "file": ("path", "inputs", "outputs"),
        "grid": ("theta", "dtheta", "tau1", "tau2", "accel_limit"),
        "sampled": ("n", "route", "draw", "seed", "accel_limit", "q", "dq", "tau", "wrench"),
    }
    (tmp_path / "arm.dh").write_text("0.2 0 0 1 0 0 0 0 0 0\n")
    robot = Choice("urdf", {"path": str(tmp_path / "arm.dh")})  # a file-reading source: read only when used
    csv = tmp_path / "s.csv"
    assert T.task_files(robot, data_spec(compose("data=file", f"data.path={csv}").data)) == [csv]
    assert T.task_files(robot, data_spec(compose(*SMALL).data)) == [tmp_path / "arm.dh"]
