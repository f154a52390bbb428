"""The plug-in contracts of docs/extending.md, enforced: every ``_target_`` of the shipped configs is an import path
Hydra resolves (and builds, where the class takes the node's keys), a built-in's path and its alias are one job (the
same hash as before the files named paths), and a key no code reads is refused before any work."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
import torch
from hydra.utils import get_class, instantiate
from omegaconf import OmegaConf

from selpres.arms.sources import SOURCES
from selpres.engines.optim import OPTIMIZERS
from selpres.errors import ConfigError
from selpres.presentation.pruning import REGISTRY as PRUNING
from selpres.run.config import unread
from selpres.run.results import job_hash
from selpres.run.specs import recorded

from conftest import CONFIGS, REPO, compose

ENGINE_KEYS = ("batch_size", "reduction", "lr_schedule", "sigmoid_prime_offset")


def _targets():
    """(file, dotted place, value) of every ``_target_`` in the shipped config files."""
    found = []

    def walk(node, where, path):
        if isinstance(node, dict):
            for k, v in node.items():
                if k == "_target_":
                    found.append((path, where or "<top>", v))
                walk(v, f"{where}.{k}" if where else str(k), path)
        elif isinstance(node, list):
            for v in node:
                walk(v, where, path)

    for path in sorted(CONFIGS.rglob("*.yaml")):
        walk(OmegaConf.to_container(OmegaConf.load(path)), "", path.relative_to(CONFIGS))
    return found


TARGETS = _targets()


def test_the_shipped_configs_name_their_classes_by_import_path():
    assert len(TARGETS) >= 18  # 8 optimizers, 4 robots, 4 pruning schedules, the output guard, the sweeper
    short = [(str(f), v) for f, _, v in TARGETS if "." not in v]
    assert not short, f"short names instead of import paths: {short}"


@pytest.mark.parametrize("path, where, target", TARGETS, ids=[f"{f}:{w}" for f, w, _ in TARGETS])
def test_every_target_resolves_with_hydra(path, where, target):
    """``hydra.utils.get_class`` finds each one; a registry's is the built-in its alias names."""
    cls = get_class(target)
    group = Path(path).parts[0]
    registry = {"optim": OPTIMIZERS, "robot": SOURCES, "schedule": PRUNING}.get(group)
    if registry is not None:
        alias = registry.canonical(target)
        assert alias in registry.names and registry.get(alias) is cls


@pytest.mark.parametrize("option", sorted(p.stem for p in (CONFIGS / "optim").glob("*.yaml")))
def test_every_optimizer_file_is_instantiated_by_hydra_into_the_optimizer_a_job_runs(option):
    """Its node without the engines' keys is the class's keyword arguments: Hydra builds the optimizer from it."""
    node = OmegaConf.load(CONFIGS / "optim" / f"{option}.yaml")
    for k in ENGINE_KEYS:
        node.pop(k, None)
    w = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    opt = instantiate(node, params=[w])
    assert isinstance(opt, OPTIMIZERS.get(OPTIMIZERS.canonical(node._target_)))
    assert opt.param_groups[0]["lr"] == node.lr


@pytest.mark.parametrize("option", ["two_link", "planar3"])
def test_a_robot_file_is_instantiated_by_hydra_into_the_arm_a_job_builds(option):
    """Hydra builds the arm source from the file; its arm's inverse dynamics are the job's arm's."""
    from selpres.arms.sources import make_arm

    node = OmegaConf.load(CONFIGS / "robot" / f"{option}.yaml")
    node.pop("defaults", None)
    ours, hydras = make_arm(OmegaConf.to_container(node)), instantiate(node, _convert_="all").arm()
    q = torch.linspace(-1, 1, 3 * ours.dof, dtype=torch.float64).reshape(3, ours.dof)
    assert torch.equal(ours.inverse_dynamics(q, q * 0.5, q * 0.2), hydras.inverse_dynamics(q, q * 0.5, q * 0.2))


# config hashes (results.json config_hash, what finds a finished job) computed by the code before the config files
# named import paths (PYTHONPATH=<that checkout> python -c "... job_hash(compose_train(CONFIG_DIR, overrides))")
KNOWN = [
    ([], "d8fadaa1d4080fe3"),
    (["optim=adam"], "511258a72bf547da"),
    (["optim=quickprop"], "4b33097ebe0b488a"),
    (["optim=adam_minibatch", "model.activation=relu"], "2129c7e903fd6786"),
    (["schedule=infobatch"], "24f0767d3d5bdc8a"),
    (["schedule=seta"], "e572329d8fa7d633"),
    (["robot=planar3", "data=sampled", "topology.layers=9-13-3"], "b7d5508e4638a8b0"),
    (["optim=rprop", "schedule=conventional"], "044f4849fdcb1fd6"),
    (["optim._target_=torch.optim.NAdam", "optim=adam_minibatch"], "51ba6b1bbe709a9d"),
    (["schedule=selective_backprop"], "d48f49252d0ec382"),
    (["robot=puma560"], "bb9f66ff557b3433"),
]


@pytest.mark.parametrize("overrides, chash", KNOWN)
def test_a_config_keeps_its_hash(overrides, chash):
    assert job_hash(compose(*overrides)) == chash


def test_the_serial_spec_knows_its_source_by_both_names():
    from selpres.arms.spec import SERIAL

    assert SERIAL == ("serial", SOURCES.path_of("serial"))


def test_a_built_in_by_its_path_or_its_alias_is_one_job():
    pairs = [
        ("optim._target_=adam", "optim._target_=selpres.engines.optim.adam.Adam"),
        ("robot._target_=two_link", "robot._target_=selpres.arms.sources.two_link.TwoLink"),
        ("schedule.pruning._target_=seta", "schedule.pruning._target_=selpres.presentation.pruning.seta.SeTa"),
    ]
    for alias, path in pairs:
        base = ["optim=adam"] if "optim" in alias else ["schedule=infobatch"] if "pruning" in alias else []
        a, b = compose(*base, alias), compose(*base, path)
        assert job_hash(a) == job_hash(b) and recorded(a) == recorded(b)
    assert recorded(compose("optim=adam"))["optim"]["_target_"] == "adam"  # results.json keeps the alias


@pytest.mark.parametrize(
    "overrides, key",
    [
        (["+schedule.q=1"], "schedule.q"),
        (["+eval.foo=1"], "eval.foo"),
        (["+foo=1"], "foo"),
        (["+optim.foo=1"], "optim.foo"),
        (["+robot.wingspan=1"], "robot.wingspan"),
        (["+data.foo=1"], "data.foo"),
        (["schedule=infobatch", "+schedule.pruning.foo=1"], "schedule.pruning.foo"),
    ],
)
def test_an_appended_key_no_code_reads_is_refused_in_every_node(overrides, key):
    from selpres.run.resolve import resolve

    with pytest.raises(ConfigError) as e:
        resolve(compose(*overrides))
    assert e.value.key == key and e.value.value == 1


@pytest.mark.parametrize(
    "overrides, refused",
    [
        (["-m", "+schedule.q=1,2"], "schedule.q=1,2: schedule has no such key"),
        (["+model.units=3"], "model.units=3: model has no such key (it declares activation)"),
        (["+experiment=table1", "+data.n=30", "+optim.foo=1", "+hydra.job.foo=1"], None),  # groups; open nodes
    ],
)
def test_the_command_line_refuses_an_appended_key_before_hydra_starts(overrides, refused):
    got = unread(overrides)
    assert got == refused if refused is None else got.startswith(refused)


def test_a_sweep_over_an_unread_key_is_refused_before_any_job(tmp_path):
    """``-m +schedule.p=1,2`` ran p = 4 twice and recorded p: 1 and p: 2 (before the schema declared p); a key the
    schema does not declare is now refused in one line, exit 2, nothing written, before any job."""
    import subprocess

    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    sweep = tmp_path / "sweep"
    done = subprocess.run(
        [sys.executable, "train.py", "-m", "+schedule.q=1,2", f"hydra.sweep.dir={sweep}"],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2 and not sweep.exists(), done.stderr[-2000:]
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("error: schedule.q=1,2: schedule has no such key (it declares name, sizes, epochs")
    assert line.endswith("): no code would read it")
