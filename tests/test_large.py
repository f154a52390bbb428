"""experiment=large in one command: the sweep expands to every (arm, network, n, schedule) job - each arm
with the network that fits it, not their product -, each job's folder is named by its overrides (one folder
per n), the replicas fill the native kernel's lanes, and the report labels an arm by its name."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import pytest
from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from selpres.arms.sources import SOURCES
from selpres.report.groups import label_methods
from selpres.report.jobs import Job
from selpres.run.resolve import resolve
from selpres.run.specs import plain as to_container

from conftest import compose, load_group

COMMAND = ["experiment=large"]  # python train.py experiment=large
# by hand: each arm with its network (3N inputs, N outputs), every n, every schedule
ARMS = {"two_link": "6-13-2", "puma560": "18-40-6"}
NS = (1_000, 10_000, 100_000)
SCHEDULES = ("conventional", "selective", "matched")


def swept_jobs(*command: str) -> list[list[str]]:
    """Each job's overrides in launch order, as Hydra's basic sweeper expands them: the experiment's
    hydra.sweeper.params first, then the command line's (a key given on both takes the command's value)."""
    cfg = compose(*command, hydra=True)
    params = [f"{k}={v}" for k, v in cfg.hydra.sweeper.params.items()]
    overrides = OverridesParser.create().parse_overrides([*params, *command])
    (batch,) = BasicSweeper.split_arguments(overrides, None)
    return batch


def arm_of(cfg) -> str:
    return cfg.robot.get("name") or SOURCES.canonical(cfg.robot._target_)  # the two-link file sets no name


@pytest.fixture(scope="module")
def jobs():
    return [(o, compose(*o)) for o in swept_jobs(*COMMAND)]


def test_one_command_runs_both_arms_each_with_its_network_every_n_and_schedule(jobs):
    got = sorted((arm_of(c), c.topology.layers, c.data.n, c.schedule.name) for _, c in jobs)
    want = sorted((a, t, n, s) for (a, t), n, s in itertools.product(ARMS.items(), NS, SCHEDULES))
    assert got == want  # 18 jobs; a product of robot x topology would give 36, half of them refused
    for _, c in jobs:
        sizes = resolve(c).sizes  # the network fits the arm's task: 3N inputs, N outputs
        dof = {"two_link": 2, "puma560": 6}[arm_of(c)]
        assert (sizes[0], sizes[-1]) == (3 * dof, dof)
        assert c.data.kind == "sampled" and c.data.heldout == 10_000
        assert c.seed == 0 and c.replicas >= 10  # the same seeds for every method: paired comparisons


def test_the_experiment_runs_two_jobs_at_a_time_on_one_thread_each():
    cfg = compose(*COMMAND, hydra=True)
    assert cfg.hydra.mode.name == "MULTIRUN"
    assert cfg.hydra.launcher.n_jobs == 2 and cfg.threads == 1


def test_the_longest_jobs_launch_first(jobs):
    """The PUMA's network has ~8x the weights of 6-13-2 and conventional ~2x selective's presentations:
    launch order = falling (arm, n, schedule) cost, so the two cores finish together."""
    order = [(arm_of(c), c.data.n, c.schedule.name) for _, c in jobs]
    assert order[0] == ("puma560", 100_000, "conventional")
    for arm in ARMS:
        ns = [n for a, n, _ in order if a == arm]
        assert ns == sorted(ns, reverse=True)
    assert [a for a, _, _ in order] == ["puma560"] * 9 + ["two_link"] * 9


def test_one_arm_alone_is_the_same_jobs_in_the_same_folders():
    """``python train.py experiment=large design/arm=puma560``: the PUMA's nine jobs only, and their
    folders are those of the full sweep, so running it first and the whole experiment later skips them."""
    alone = swept_jobs(*COMMAND, "design/arm=puma560")
    assert len(alone) == 9
    full = {folder(o) for o in swept_jobs(*COMMAND)}
    assert {folder(o) for o in alone} <= full


def folder(overrides: list[str]) -> str:
    """The job's folder below hydra.sweep.dir, as Hydra resolves it for that job."""
    cfg = compose(*overrides, hydra=True)
    HydraConfig.instance().set_config(cfg)
    try:
        return OmegaConf.to_container(cfg.hydra.sweep, resolve=True)["subdir"]
    finally:
        HydraConfig.instance().cfg = None


def test_each_folder_is_named_by_its_overrides_inside_one_folder_per_n(jobs):
    cfg = compose(*COMMAND, hydra=True)
    assert cfg.hydra.sweep.dir == "outputs/sweeps/large"
    names = []
    for overrides, c in jobs:
        # by hand: Hydra's override_dirname sorts the job's overrides, "/" of a group path becomes "_"
        want = f"n={c.data.n}/" + ",".join(sorted(overrides)).replace("/", "_")
        assert folder(overrides) == want
        names.append(want)
    assert "n=100000/data.n=100000,design_arm=puma560,experiment=large,schedule=matched" in names
    assert len(set(names)) == len(names) == 18


# ------------------------------------------------------------------ the report's label of an arm
def job(name: str, topology: str, robot: str, n: int, **robot_changes) -> Job:
    """A finished job as the report reads it: only the config matters for its label."""
    arm = {**to_container(load_group("robot", robot)), **robot_changes}
    arm["_target_"] = SOURCES.canonical(arm["_target_"])  # results.json records a built-in source by its alias
    config = {"schedule": {"name": name}, "topology": {"layers": topology}, "robot": arm, "data": {"n": n}}
    return Job(Path(f"{robot}-{topology}-{name}-{n}"), "complete", name, topology, results={"config": config})


def labels(jobs: list[Job]) -> list[str]:
    label_methods(jobs)
    return [j.schedule for j in jobs]


def test_arms_the_topology_tells_apart_are_not_spelled_out_in_labels():
    """experiment=large: each topology has one arm, so the label says what else differs (n), not the arm's
    links (thousands of characters before) - and no (topology, method) cell of the other arm is missing."""
    got = labels([job("selective", t, arm, n) for arm, t in ARMS.items() for n in (1_000, 10_000)])
    assert got == ["selective data.n=1000", "selective data.n=10000"] * 2


def test_arms_on_one_topology_are_labelled_by_their_names():
    both = [job("selective", "6-13-2", "two_link", 1_000), job("selective", "6-13-2", "puma560", 1_000)]
    got = labels(both)
    assert got == ["selective robot=two_link", "selective robot=puma560"]


def test_arms_of_one_name_that_differ_say_how():
    """Labels stay distinct: a mass overridden on one of two two-link arms is named beside the arm."""
    got = labels(
        [
            job("selective", "6-13-2", "two_link", 1_000),
            job("selective", "6-13-2", "two_link", 1_000, m2=3.5),
            job("selective", "6-13-2", "puma560", 1_000),
        ]
    )
    assert got == [
        "selective robot=two_link robot.m2=3.0",
        "selective robot=two_link robot.m2=3.5",
        "selective robot=puma560",
    ]
    assert len(json.dumps(got)) < 200
