"""results.json has one shape for every method (the selector that ran and its ledger's cost), and a file written
before that shape existed is read through one fallback (selpres.run.legacy) by the report and the sweep's
partners alike."""

from __future__ import annotations

import json

import pytest

from selpres.report.groups import job_cost, presents_all, replica_costs
from selpres.run.legacy import selector_and_cost
from selpres.run.partners import costs
from selpres.run.train import train

from conftest import cfg_of

TINY = ("replicas=2", "logging.tensorboard=false", "checkpoint.enabled=false")
INFOBATCH = "selpres.presentation.pruning.infobatch.InfoBatch"


def test_a_staged_job_and_a_pruning_job_record_the_same_nodes(tmp_path):
    staged = train(cfg_of("schedule=selective", "schedule.epochs=[1,1,1,1,2]", *TINY), tmp_path / "staged")
    pruned = train(cfg_of("schedule=infobatch", "schedule.epochs=[4]", *TINY), tmp_path / "infobatch")
    assert set(staged) == set(pruned) and "pruning" not in staged
    on_disk = [json.loads((tmp_path / d / "results.json").read_text()) for d in ("staged", "infobatch")]
    assert set(on_disk[0]) == set(on_disk[1]) == set(staged)
    assert staged["selector"]["name"] == "staged" and pruned["selector"]["class"] == INFOBATCH
    assert pruned["selector"]["prune_ratio"] == 0.5 and pruned["selector"]["delta"] == 0.875  # what pruning held
    # by hand: the staged plan presents 50 + 100 + 400 + 800 + 2 x 1002 patterns to every replica alike
    assert staged["cost"]["per_replica"]["spent"] == [3354.0, 3354.0] == replica_costs(staged)
    assert job_cost(pruned) == sum(pruned["cost"]["per_replica"]["spent"]) / 2 < 4 * 1002
    assert not presents_all(staged) and not presents_all(pruned)


# what versions before the selector protocol wrote: no selector and no cost; a pruning job's pruning node
OLD_PRUNING = {
    "kind": "infobatch",
    "policy": INFOBATCH,
    "prune_ratio": 0.5,
    "delta": 0.875,
    "budget": None,
    "selection_cost": 0.0,
    "cost": [3000.0, 3101.0],
    "trained_presentations": [3000.0, 3101.0],
    "charged_presentations": [0.0, 0.0],
    "left_out": [1008.0, 907.0],
    "epochs": [4, 4],
    "checkpointed": False,
}


def _old(sizes: list[int], epochs: list[int], presentations: int, pruning: dict | None = None) -> dict:
    sch = {"sizes": sizes, "epochs": epochs, "presentations": presentations, "extra_presentations": [0] * len(sizes)}
    res = {"status": "complete", "schedule": sch, "seeds": [0, 1], "presentations_done": presentations}
    return {**res, "selection_presentations": 0, "pruning": pruning}


def test_an_older_file_is_read_as_todays_shape():
    pruned = _old([1002], [4], 3050, OLD_PRUNING)
    selector, cost = selector_and_cost(pruned)
    assert selector == {
        "name": "infobatch",
        "class": INFOBATCH,
        "prune_ratio": 0.5,
        "delta": 0.875,
        "checkpointed": False,
    }
    assert cost["per_replica"]["left_out"] == [1008.0, 907.0] and cost["per_replica"]["epochs"] == [4, 4]
    assert job_cost(pruned) == 3050.5 and replica_costs(pruned) == [3000.0, 3101.0]
    assert not presents_all(pruned)
    conventional = _old([1002], [4], 4008)
    assert presents_all(conventional) and job_cost(conventional) == 4008 == replica_costs(conventional)[1]
    # a file of the version before this one carried both: its cost node is what is read, not its pruning node
    both = {**pruned, "selector": {"name": "infobatch"}, "cost": {"presentations": 7, "per_replica": {"spent": [7]}}}
    assert job_cost(both) == 7 and replica_costs(both) == [7]


@pytest.mark.parametrize("old", [True, False])
def test_partners_match_settings_whose_replicas_cost_one_budget(tmp_path, old):
    """A two-stage setting every replica of which cost 4,704 gets a partner at that budget; one whose replicas cost
    differently (a pruning policy's choices per seed) has no one budget and gets none, in an old file or a new."""
    staged = _old([50, 1002], [2, 4], 4704)
    pruned = _old([501, 1002], [2, 4], 3050, OLD_PRUNING)
    if not old:
        for res, spent in ((staged, [4704, 4704]), (pruned, [3000.0, 3101.0])):
            res.pop("pruning")
            res["cost"] = {"presentations": sum(spent) / 2, "per_replica": {"spent": spent}}
    for name, res in (("staged", staged), ("pruned", pruned)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "results.json").write_text(json.dumps(res))
    assert costs(tmp_path) == [4704, 1002 * 6]  # the staged setting's, and n·ΣN_i (its own 6 epochs)
