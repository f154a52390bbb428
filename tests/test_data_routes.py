"""Data routes as a registry kind (issue 25): a new route is one module of selpres/data/routes and one YAML of
configs/data, nothing else edited (the config schema holds no route's keys: the route declares them and their
types); a user's own route runs by its import path in ``data.kind``; recorded configs keep the keys and the job
hash they had when the schema typed every route's keys."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from selpres.errors import ConfigError

from conftest import REPO, compose

# y = slope x on n points of [0, 1]: a route written as a contributor writes one (module docstring of
# selpres.data.routes), used below both as a built-in (copied into the package) and as a user's own class
LINE = '''"""y = slope x on n points of [0, 1]."""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from selpres.patterns import ExemplarSet, Patterns, TestSets
from selpres.data.routes import DataRoute
from selpres.data.task import Shape, Task, check_test_split
from selpres.errors import ConfigError


class Line(DataRoute):
    USES_ARM = False

    @dataclass
    class Keys:
        n: int
        slope: float = 1.0

    def check(self, data):
        if data.n < 2:
            raise ConfigError("data.n", data.n, "at least 2 points")

    def shape(self, robot, data):
        return Shape(("x",), ("y",), "data=line")

    def build(self, robot, data):
        x = torch.linspace(0.0, 1.0, data.n, dtype=torch.float64)[:, None]
        exemplar = ExemplarSet(x, data.slope * x, n_candidates=data.n)
        n_test, n_ex = check_test_split(data, data.n)
        held = torch.linspace(0.005, 0.995, 99, dtype=torch.float64)[:, None]
        t10 = torch.cat((x[:n_ex], held[: n_test - n_ex]))
        tests = TestSets(Patterns(t10, data.slope * t10), torch.arange(n_test) < n_ex,
                         Patterns(held, data.slope * held))
        task = Task(exemplar, tests, None, ("x",), ("y",), {"kind": "line", "source": "data=line", "n": data.n})
        return replace(task, scaler=task.fit_scaler(data))


ROUTE = Line
'''

LINE_YAML = """kind: line
n: 40
slope: 1.0
test_patterns: 10
test_from_exemplar: 5
heldout: 99
test_seed: 0
scaling: {mode: exemplar, margin: 0.1, lo: 0.1, hi: 0.9}
"""

JOB = ["topology.layers=1-3-1", "schedule=conventional", "schedule.epochs=[2]", "eval.heldout_curve=99"]


@pytest.mark.slow
def test_a_new_route_is_one_module_and_one_yaml(tmp_path):
    """On a copy of the package, ``data/routes/line.py`` and ``configs/data/line.yaml`` added and nothing else: the
    registry lists it, ``data=line`` composes, validates and builds, its keys' types are checked as the schema
    checked the built-ins' (``data.slope=abc`` refused naming the key), its own check runs."""
    shutil.copytree(REPO / "selpres", tmp_path / "selpres", ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    shutil.copytree(REPO / "configs", tmp_path / "configs")
    (tmp_path / "selpres" / "data" / "routes" / "line.py").write_text(LINE)
    (tmp_path / "configs" / "data" / "line.yaml").write_text(LINE_YAML)
    code = f"""
import sys; sys.path.insert(0, sys.argv[1])
import selpres
assert selpres.__file__.startswith(sys.argv[1]), selpres.__file__
from selpres.data.routes import ROUTES
from selpres.errors import ConfigError
from selpres.run.resolve import resolve
from selpres.run.config import CONFIG_DIR, compose_train
from selpres.run.problem import prepare
from selpres.run.resolve import resolve
print(ROUTES.names)
cfg = compose_train(CONFIG_DIR, ["data=line", "data.slope=2", *{JOB!r}])
print(resolve(cfg).sizes)
task = prepare(resolve(cfg)).task
print(bool((task.exemplar.Y == 2 * task.exemplar.X).all()), task.n, task.info["route_class"])
for bad in (["data.slope=abc"], ["data.n=1"], ["data.kind=lines"]):
    try:
        resolve(compose_train(CONFIG_DIR, ["data=line", *{JOB!r}, *bad]))
    except ConfigError as e:
        print(e)
"""
    env = {**os.environ, "SELPRES_DATA_CACHE": "off"}
    done = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, timeout=300, env=env
    )
    assert done.returncode == 0, done.stderr[-3000:]
    lines = done.stdout.splitlines()
    assert lines[:3] == [
        "('file', 'grid', 'line', 'sampled')",
        "(1, 3, 1)",
        "True 40 selpres.data.routes.line.Line",
    ], done.stdout
    assert lines[3] == "data.slope='abc' is not allowed: expected a number"
    assert lines[4] == "data.n=1 is not allowed: expected at least 2 points"
    assert lines[5].startswith("data.kind='lines' is not allowed: expected one of file, grid, line, sampled, or a")


@pytest.fixture
def user_route(tmp_path, monkeypatch):
    (tmp_path / "my_line.py").write_text(LINE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "my_line", raising=False)  # this test's file, not an earlier test's module
    yield tmp_path
    sys.modules.pop("my_line", None)


# data=file's node: the common keys, and its own left unset (null), which another route's node may hold
USERS = ["data=file", "data.kind=my_line.Line", "data.heldout=99"]


def test_a_users_route_by_its_import_path(user_route):
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    cfg = compose(*USERS, "+data.n=30", "+data.slope=-0.5", *JOB)
    assert resolve(cfg).sizes == (1, 3, 1)
    task = prepare(resolve(cfg)).task
    assert task.n == 30 and (task.exemplar.Y == -0.5 * task.exemplar.X).all()
    assert task.info["route_class"] == "my_line.Line"
    with pytest.raises(ConfigError, match=r"^data.n='many' is not allowed: expected a whole number$"):
        resolve(compose(*USERS, "+data.n=many", *JOB))
    with pytest.raises(ConfigError, match=r"^data.n=None is not allowed: expected a value: data.kind=my_line.Line"):
        resolve(compose(*USERS, *JOB))
    with pytest.raises(ConfigError, match=r"^data.kind='my_line.Nope' is not allowed: .*it has no 'Nope'"):
        resolve(compose(*USERS, "data.kind=my_line.Nope", *JOB))


def test_a_users_route_module_is_part_of_the_stored_tasks_key(user_route, tmp_path, monkeypatch):
    """Its task is stored (it reads no file), and an edit to its module is an edit to the task's code."""
    import selpres.data.task as T
    from selpres.run.specs import task_specs

    monkeypatch.setenv("SELPRES_DATA_CACHE", str(tmp_path / "cache"))
    specs = task_specs(compose(*USERS, "+data.n=30", *JOB))
    T._task.cache_clear()
    assert T.load_task(*specs).info["cache"].startswith("stored")
    T._task.cache_clear()
    assert T.load_task(*specs).info["cache"].startswith("hit")
    (user_route / "my_line.py").write_text(LINE + "# edited\n")
    T._task.cache_clear()
    assert T.load_task(*specs).info["cache"].startswith("stored")


@pytest.mark.slow
def test_a_users_route_runs_from_the_command_line(user_route, tmp_path):
    """``PYTHONPATH=. python train.py data=file data.kind=my_line.Line +data.n=30 ...``: results.json
    records the class that made the data; a bad value of its keys is one line naming it, exit 2, nothing kept."""
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    env["PYTHONPATH"] = os.pathsep.join([str(user_route), env.get("PYTHONPATH", "")])
    args = [*USERS, "+data.n=30", *JOB, "logging.tensorboard=false", "threads=1"]
    run = lambda *more: subprocess.run(  # noqa: E731
        [sys.executable, "train.py", *args, *more], cwd=REPO, env=env, capture_output=True, text=True, timeout=300
    )
    done = run(f"hydra.run.dir={tmp_path / 'run'}")
    assert done.returncode == 0, done.stderr[-2000:]
    res = json.loads((tmp_path / "run" / "results.json").read_text())
    assert res["status"] == "complete" and res["data"]["route_class"] == "my_line.Line"
    assert res["config"]["data"]["kind"] == "my_line.Line" and res["config"]["data"]["slope"] == 1.0  # its default
    bad = run("+data.slope=steep", f"hydra.run.dir={tmp_path / 'bad'}")
    assert bad.returncode == 2 and "error: data.slope='steep' is not allowed: expected a number" in bad.stderr
    assert "Traceback" not in bad.stderr and not (tmp_path / "bad").exists()


def test_recorded_configs_keep_the_keys_and_hash_of_the_typed_schema():
    """results.json's config holds every key the typed schema held (unset where the route does not read it), so a
    finished job's config_hash is found again; values are converted as the schema converted them."""
    from selpres.run.results import job_hash
    from selpres.run.specs import TYPED_BEFORE, recorded

    cfg = compose("data.accel_limit=3")
    data = recorded(cfg)["data"]
    assert set(TYPED_BEFORE) <= set(data) and data["n"] is None and data["accel_limit"] == 3.0
    assert data["theta"] == {"lo": 0.0, "hi": 0.5, "step": 0.125} and data["scaling"]["mode"] == "exemplar"
    assert job_hash(cfg) == job_hash(compose("data.accel_limit=3.0"))
    # the hashes main gave these configs before the data node was opened (a0ffa29)
    assert job_hash(compose()) == "d8fadaa1d4080fe3"
    assert job_hash(compose("data=sampled")) == "a18ed62083ecded8"


def test_a_spec_reads_by_name_as_a_dict_and_a_config_node_do():
    """The data room's functions read their node by name (``data["theta"]``): a spec, a plain dict and a config node
    alike, so no room below ``run`` needs a config reader; a key the route does not have is a KeyError naming it."""
    from selpres.run.specs import data_spec, plain

    node = compose("data=sampled").data
    spec = data_spec(node)
    for key in ("kind", "heldout", "scaling", "q", "accel_limit"):  # common keys and the route's own
        assert spec[key] == plain(node)[key] == plain(node[key]), key
    assert spec["accel_limit"] == spec.accel_limit
    with pytest.raises(KeyError, match="theta"):
        spec["theta"]  # the grid route's key: not one of data.kind=sampled
