"""Hydra composition of every config option, the typed schema, and semantic validation (ConfigError)."""

from __future__ import annotations

import pytest
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import Glob
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from selpres.errors import ConfigError
from selpres.run.config import EngineName, TrainConfig
from selpres.run.resolve import resolve

from conftest import CONFIGS, compose

SMALL = ("data.heldout=200",)  # held-out set size does not change what is checked; keeps prepare() fast
# (SMALL goes first in every override list, so a test's own data.heldout=... wins)


def _options(group: str) -> list[str]:
    return sorted(p.stem for p in (CONFIGS / group).glob("*.yaml"))


# design/ holds experiment=sensitivity's 148 points, each checked in tests/test_sensitivity.py
GROUPS = sorted(p.name for p in CONFIGS.iterdir() if p.is_dir() and p.name not in ("hydra", "design")) + [
    "hydra/launcher"
]
OPTIONS = [(g, o) for g in GROUPS for o in _options(g)]


def test_every_group_is_listed():
    """Guards the dynamic parametrisation itself: the groups users can pick are all found."""
    assert {"robot", "data", "schedule", "topology", "optim", "experiment", "hydra/launcher"} <= set(GROUPS)
    assert {"selective", "conventional", "matched", "random_growth"} <= set(_options("schedule"))
    assert {"6-4-2", "6-8-2", "6-13-2"} <= set(_options("topology"))
    assert len(OPTIONS) >= 17


def test_defaults_are_the_paper_setup(compose_cfg):
    cfg = compose_cfg()
    assert OmegaConf.get_type(cfg) is TrainConfig
    assert cfg.topology.layers == "6-13-2"
    assert list(cfg.schedule.sizes) == [50, 100, 400, 800, 1002] and list(cfg.schedule.epochs) == [30] * 5
    assert cfg.optim.lr == 0.15 and cfg.optim.momentum == 0.9 and cfg.optim.batch_size == 1
    assert cfg.engine == EngineName.fast and cfg.replicas == 1
    assert resolve(cfg).sizes == (6, 13, 2)


@pytest.fixture(scope="module")
def user_files(tmp_path_factory):
    """A URDF (planar3 exported) for robot=urdf and a small CSV for data=file."""
    import numpy as np

    from selpres.arms.sources import make_arm
    from selpres.arms.urdf import to_urdf
    from selpres.run.specs import robot_spec

    folder = tmp_path_factory.mktemp("user")
    to_urdf(make_arm(robot_spec(compose("robot=planar3", "topology.layers=9-13-3").robot)), folder / "arm.urdf")
    rows = np.random.default_rng(0).uniform(-1, 1, (1500, 4))
    np.savetxt(folder / "data.csv", rows, delimiter=",", header="a,b,c,y", comments="")
    return {"urdf": folder / "arm.urdf", "csv": folder / "data.csv"}


def companions(group: str, option: str, files: dict) -> list[str]:
    """Overrides an option needs to run: an arm other than the paper's samples its data and takes a
    network of its width; a user file needs its path and columns."""
    return {
        ("robot", "planar3"): ["data=sampled", "topology.layers=9-13-3"],
        ("topology", "9-13-3"): ["robot=planar3"],  # its file picks data=sampled
        ("topology", "18-40-6"): ["robot=puma560", "data.n=2000"],
        ("robot", "puma560"): ["data=sampled", "topology.layers=18-40-6"],
        ("robot", "urdf"): [f"robot.path={files['urdf']}", "data=sampled", "topology.layers=9-13-3"],
        ("data", "file"): [
            f"data.path={files['csv']}",
            "data.inputs=[a,b,c]",
            "data.outputs=[y]",
            "topology.layers=3-5-1",
        ],
    }.get((group, option), [])


_HEAVY = {("robot", "puma560"), ("topology", "18-40-6")}  # draw a 6-joint arm's exemplar set
_OPTIONS = [pytest.param(g, o, marks=pytest.mark.slow) if (g, o) in _HEAVY else (g, o) for g, o in OPTIONS]


@pytest.mark.parametrize("group, option", _OPTIONS, ids=[f"{g}={o}" for g, o in OPTIONS])
def test_every_option_composes_validates_and_prepares(compose_cfg, user_files, group, option):
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    extra = companions(group, option, user_files)
    cfg = compose_cfg(*SMALL, f"{group}={option}", *extra)
    assert isinstance(cfg, DictConfig)
    job = resolve(cfg)
    sizes, prob = job.sizes, prepare(job)
    n = prob.X.shape[0]
    assert (
        (sizes[0], sizes[-1])
        == (len(prob.task.input_names), len(prob.task.output_names))
        == (prob.X.shape[1], prob.Y.shape[1])
    )
    if cfg.data.kind == "grid":
        assert n == 1002 and sizes[0] == 6 and sizes[-1] == 2  # the paper's exemplar set
    assert prob.schedule.n == n and prob.schedule.sizes[-1] == n
    assert len(prob.samplers) == len(prob.seeds) == cfg.replicas
    if group == "schedule":
        raw = OmegaConf.load(CONFIGS / "schedule" / f"{option}.yaml")
        if raw.get("p") is not None:  # the parametric schedule: p + 1 stages, ΣN_i its total (tests/test_stages.py)
            assert prob.schedule.p == raw.p and sum(prob.schedule.epochs) == raw.total_epochs
        elif raw.get("budget") is not None:
            assert prob.schedule.presentations == raw.budget
        else:
            assert prob.schedule.epochs == list(raw.epochs)
            assert len(prob.schedule.sizes) == len(raw.sizes)


@pytest.mark.parametrize("engine", [e.value for e in EngineName])
def test_every_engine_name_composes(compose_cfg, engine):
    cfg = compose_cfg(f"engine={engine}")
    assert cfg.engine == EngineName(engine)
    resolve(cfg)


@pytest.mark.parametrize("option", _options("experiment"))
def test_experiments_are_multirun_sweeps(compose_cfg, option):
    cfg = compose_cfg(f"experiment={option}", hydra=True)
    assert cfg.hydra.mode == RunMode.MULTIRUN
    params = cfg.hydra.sweeper.params
    assert params, "an experiment should sweep something"
    if "BasicSweeper" not in str(cfg.hydra.sweeper.get("_target_", "")):
        return  # an Optuna search space (interval, choice): tests/test_search.py checks experiment=search
    for group, values in params.items():
        override = OverridesParser.create().parse_overrides([f"{group}={values}"])[0]
        if isinstance(override.value(), Glob):  # a glob over a group's options (experiment=sensitivity)
            assert override.value().filter(_options(group)), f"experiment {option}: {group}={values} matches nothing"
            continue
        for v in str(values).split(","):
            if (CONFIGS / group).is_dir():  # a group: its options
                assert v in _options(group), f"experiment {option} sweeps unknown {group}={v}"
            else:  # a key: every value composes and validates (the topology must fit the task)
                resolve(compose_cfg(f"experiment={option}", f"{group}={v}"))
    assert str(cfg.hydra.sweep.dir).startswith("outputs/")  # not Hydra's default multirun/


@pytest.mark.parametrize("option", _options("hydra/launcher"))
def test_launchers_compose(compose_cfg, option):
    cfg = compose_cfg(f"hydra/launcher={option}", hydra=True)
    assert cfg.hydra.launcher._target_.startswith("hydra_plugins.")


def test_run_dir_is_named_by_the_overrides(compose_cfg):
    """Same command ⇒ same folder (skip / resume); knobs that cannot change numbers are excluded."""

    def run_dir(*ov):
        cfg = compose_cfg(*ov, hydra=True)
        HydraConfig().set_config(cfg)
        return cfg.hydra.run.dir

    a = run_dir("topology=6-4-2", "seed=3")
    assert a == run_dir("topology=6-4-2", "seed=3")
    assert a != run_dir("topology=6-4-2", "seed=4")
    assert run_dir("topology=6-4-2", "seed=3", "overwrite=true", "threads=1") == a
    assert run_dir() == "outputs/runs/default"
    assert "/" not in run_dir("hydra/launcher=local2", "schedule=matched").removeprefix("outputs/runs/")


# ------------------------------------------------------------------------ typed schema (compose time)


def _compose_error(compose_cfg, *ov) -> str:
    with pytest.raises(Exception) as ei:
        compose_cfg(*ov)
    chain, e = [], ei.value
    while e is not None:
        chain.append(str(e))
        e = e.__cause__ or e.__context__
    return "\n".join(chain)


@pytest.mark.parametrize(
    "override, key",
    [
        ("optim.lrr=0.1", "optim.lrr"),  # unknown key
        ("robot.mass=1", "robot.mass"),
        ("replicas=two", "replicas"),  # wrong types
        ("schedule.epochs=[1,x]", "schedule.epochs"),
        ("topology=6-99-2", "topology"),  # unknown group option
        ("schedule=zigzag", "schedule"),
        ("engine=turbo", "engine"),  # bad enum values
        ("data.thetaa=0", "data.thetaa"),  # the data node is open: a key its file lacks takes Hydra's +
    ],
)
def test_schema_rejects_at_compose(compose_cfg, override, key):
    msg = _compose_error(compose_cfg, override)
    assert key in msg, msg


# ------------------------------------------------------------------------ semantic checks (ConfigError)


def _config_error(compose_cfg, *ov) -> ConfigError:
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    cfg = compose_cfg(*SMALL, *ov)
    with pytest.raises(ConfigError) as ei:
        prepare(resolve(cfg))  # what resolve checks first (cheap), then the checks that need the data
    return ei.value


@pytest.mark.parametrize(
    "overrides, key, value",
    [
        (["topology.layers=6-x-2"], "topology.layers", "6-x-2"),
        (["topology.layers=6-0-2"], "topology.layers", "6-0-2"),
        (["topology.layers=5-8-2"], "topology.layers", "5-8-2"),
        (["topology.layers=6-8-3"], "topology.layers", "6-8-3"),
        (["topology.layers=6"], "topology.layers", "6"),
        (["optim.lr=0"], "optim.lr", "0"),
        (["optim.lr=abc"], "optim.lr", "abc"),  # the optim node is open: its class checks the types
        (["optim.batch_size=1.5"], "optim.batch_size", "1.5"),
        (["+optim.lrr=0.1"], "optim.lrr", "0.1"),  # a key sgd does not take
        (["optim.lr=-0.5"], "optim.lr", "-0.5"),
        (["optim.momentum=1.0"], "optim.momentum", "1.0"),
        (["optim.momentum=-0.1"], "optim.momentum", "-0.1"),
        (["optim.batch_size=-1"], "optim.batch_size", "-1"),
        (["optim=quickprop", "optim.batch_size=1"], "optim.batch_size", "1"),  # a batch method steps per epoch
        (["optim=quickprop", "optim.mu=-1"], "optim.mu", "-1"),
        (["optim=quickprop", "+optim.momentum=0.9"], "optim.momentum", "0.9"),  # a key quickprop does not take
        (["optim=adam", "engine=native"], "engine", "native"),  # batch mode runs in torch
        (["optim=delta_bar_delta", "optim.phi=1.5"], "optim.phi", "1.5"),
        (["replicas=0"], "replicas", "0"),
        (["optim.lr=nan"], "optim.lr", "nan"),
        (["robot.m1=inf"], "robot.m1", "inf"),
        (["data.accel_limit=1e-9"], "data.accel_limit", "1e-09"),  # the filter keeps no pattern
        (["data.tau1.lo=100", "data.tau1.hi=110"], "data.accel_limit", "2.0"),  # ranges whose rows all fail the filter
        (["data.theta.hi=-1"], "data.theta.hi", "-1.0"),
        (["data.dtheta.step=0"], "data.dtheta.step", "0.0"),
        (["data.heldout=0"], "data.heldout", "0"),
        (["data.test_from_exemplar=11"], "data.test_from_exemplar", "11"),
        (["data.scaling.lo=0.9", "data.scaling.hi=0.1"], "data.scaling", "0.9"),
        # the data node is open: its route declares its keys' types, checked and converted as a schema would
        (["data.scaling.mode=auto"], "data.scaling.mode", "one of exemplar, commanded"),
        (["data.theta.lo=abc"], "data.theta.lo", "a number"),
        (["data.theta=3"], "data.theta", "a node {lo: ..., hi: ..., step: ...}"),
        (["+data.theta.lr=3"], "data.theta.lr", "one of the keys lo, hi, step of data.theta"),
        (["~data.theta.step"], "data.theta.step", "a value: data.kind=grid reads it"),
        (["data.test_patterns=1.5"], "data.test_patterns", "a whole number"),
        (["+data.thetaa=1"], "data.thetaa", "unset (null): data.kind=grid (selpres.data.routes.grid.Grid) reads"),
        (["data.kind=zigzag"], "data.kind", "one of file, grid, sampled, or a class by its import path"),
        (["schedule.strata_bins=0"], "schedule.strata_bins", "0"),
        (["schedule.order=zigzag"], "schedule.order", "zigzag"),  # an order is a registry name or import path
        (["eval.every=-1"], "eval.every", "-1"),
        (["schedule.sizes=[100,50,1002]"], "schedule.sizes", "[100, 50, 1002]"),
        (["schedule.sizes=[50,100,400,800,900]"], "schedule.sizes", "900"),
        (["schedule.sizes=[0.1,0.2,0.4,0.8,1.5]"], "schedule.sizes", "1.5"),
        (["schedule.sizes=[nan,100,400,800,1002]"], "schedule.sizes", "nan"),
        (["schedule.epochs=[0,1,1,1,1]"], "schedule.epochs", "[0, 1, 1, 1, 1]"),
        (["schedule.epochs=[30,30]"], "schedule.epochs", "[30, 30]"),
        (["schedule.epochs=null"], "schedule.epochs", "None"),
        (["schedule.budget=1000"], "schedule.budget", "1000"),  # a budget with five stages
        (["schedule=matched", "schedule.budget=0"], "schedule.budget", "0"),
        (["schedule=matched", "schedule.epochs=[5]"], "schedule.epochs", "[5]"),
    ],
    ids=lambda v: ",".join(v) if isinstance(v, list) else None,
)
def test_semantic_errors_name_key_and_value(compose_cfg, overrides, key, value):
    e = _config_error(compose_cfg, *overrides)
    msg = str(e)
    assert e.key.startswith(key) and msg.startswith(e.key), msg
    assert value in msg, msg
    assert "\n" not in msg  # one line for the CLI


def test_topology_message_reads_well(compose_cfg):
    msg = str(_config_error(compose_cfg, "topology.layers=6-x-2"))
    assert "expected expected" not in msg, msg


def test_grid_step_that_does_not_divide_the_range_is_a_config_error(compose_cfg):
    """theta 0..0.5 in steps of 0.3 cannot be a grid: must be a ConfigError naming data.theta, not a bare ValueError."""
    e = _config_error(compose_cfg, "data.theta.step=0.3")
    assert e.key.startswith("data.theta") and "0.3" in str(e)


def test_more_test_patterns_from_the_exemplar_set_than_it_holds_is_a_config_error(compose_cfg):
    """accel_limit=0.1 keeps only 2 patterns, fewer than test_from_exemplar=5: a ConfigError, not a bare ValueError."""
    e = _config_error(compose_cfg, "data.accel_limit=0.1", "schedule.sizes=[1.0]", "schedule.epochs=[1]")
    assert e.key.startswith("data."), str(e)


def test_every_test_pattern_drawn_from_the_exemplar_set_works(compose_cfg):
    """test_from_exemplar == test_patterns is inside the documented range [0, test_patterns]."""
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    prob = prepare(resolve(compose_cfg(*SMALL, "data.test_from_exemplar=10")))
    assert prob.tests["test10"][0].shape[0] == 10


def test_huge_grid_is_rejected_before_allocation(compose_cfg):
    """A tiny grid step would allocate a grid of ~10^12 candidates (hang / out of memory): validate must refuse."""
    cfg = compose_cfg("data.tau1.step=1e-6")
    with pytest.raises(ConfigError) as ei:
        resolve(cfg)  # validate only: never build this grid in a test
    assert ei.value.key.startswith("data.")


@pytest.mark.parametrize(
    "overrides, sizes, presentations",
    [
        (["schedule.sizes=[0.05,0.1,0.4,0.8,1.0]"], [50, 100, 401, 802, 1002], 30 * (50 + 100 + 401 + 802 + 1002)),
        (["schedule=conventional", "schedule.epochs=null", "schedule.budget=5000"], [1002], 5000),
        (["schedule=matched", "schedule.budget=500"], [1002], 500),  # less than one epoch
    ],
)
def test_valid_variants_prepare(compose_cfg, overrides, sizes, presentations):
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    prob = prepare(resolve(compose_cfg(*SMALL, *overrides)))
    assert prob.schedule.sizes == sizes and prob.schedule.presentations == presentations


def test_errors_survive_pickling():
    """Parallel launchers pickle a failed job's exception back to the sweep: it must round-trip."""
    import pickle

    from selpres.engines.model import TopologyError

    e = pickle.loads(pickle.dumps(ConfigError("optim.lr", -1.0, "a learning rate > 0")))
    assert (e.key, e.value, e.allowed) == ("optim.lr", -1.0, "a learning rate > 0") and "optim.lr=-1.0" in str(e)
    t = pickle.loads(pickle.dumps(TopologyError("6-x-2", "layer widths joined by '-'")))
    assert t.allowed == "layer widths joined by '-'" and "6-x-2" in str(t)


@pytest.mark.slow  # a subprocess
def test_validation_checks_the_optimizer_without_building_one():
    """The first torch.optim.Optimizer of a process imports torch._dynamo (about 1.3 s of every job's set-up);
    validating a config must not pay it, and building an optimizer does (so this check can fail)."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from selpres.run.config import CONFIG_DIR, compose_train\n"
        "from selpres.run.problem import prepare\n"
        "from selpres.run.resolve import resolve\n"
        "prepare(resolve(compose_train(CONFIG_DIR, ['replicas=2'])))\n"
        "print('torch._dynamo' in sys.modules)\n"
        "import torch\n"
        "from selpres.engines.optim import make_optimizer\n"
        "make_optimizer('sgd', [torch.zeros(1)], {'lr': 0.1})\n"
        "print('torch._dynamo' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert out.stdout.split() == ["False", "True"], out.stdout + out.stderr
