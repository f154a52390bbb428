"""A method's seed blocks are one method: jobs of one config that differ only in their seeds pool in the report's
groups, even where a budget stops them at different epochs (what a method was asked to run is its plan; the
epochs it reached are what it measured)."""

from __future__ import annotations

from selpres.report.groups import aggregate
from selpres.report.jobs import load_jobs
from selpres.run.train import train

from conftest import cfg_of

# one replica per job: InfoBatch stopped at 6,000 presentations reaches epoch 8 with seed 0 and 9 with seed 1
BLOCK = ("schedule=infobatch", "schedule.epochs=null", "schedule.budget=6000", "replicas=1")
QUIET = ("logging.tensorboard=false", "checkpoint.enabled=false")


def test_seed_blocks_stopped_by_a_budget_at_different_epochs_pool(tmp_path):
    for seed in (0, 1):
        train(cfg_of(*BLOCK, *QUIET, f"seed={seed}"), tmp_path / f"seed={seed}")
    jobs = load_jobs(tmp_path)
    reached = sorted(j.results["schedule"]["epochs"][0] for j in jobs)
    assert reached[0] != reached[1]  # the case this test is about: the blocks stopped at different epochs
    groups, _, methods = aggregate(jobs)
    assert methods == ["infobatch"]
    (g,) = groups.values()
    assert len(g.used) == 2 and not g.warnings
    assert sorted(g.by_seed) == [0, 1]


def test_jobs_of_different_plans_are_not_pooled(tmp_path):
    """Two epochs plans of one method are two methods (their labels differ), never one group with a warning."""
    for epochs in ("[4]", "[5]"):
        train(cfg_of("schedule=infobatch", f"schedule.epochs={epochs}", "replicas=1", *QUIET), tmp_path / epochs)
    groups, _, methods = aggregate(load_jobs(tmp_path))
    assert len(methods) == 2 and all(len(g.used) == 1 and not g.warnings for g in groups.values())
