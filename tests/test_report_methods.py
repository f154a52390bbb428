"""A method is keyed one way in every report section and study (issue 37): a user's policy run from InfoBatch's
schedule file is its own row, named by its import path, at its own measured cost; two jobs of one schedule name never
overwrite each other's seeds."""

from __future__ import annotations

import json
import sys

import pytest

from selpres.report.compare import Options
from selpres.report.context import Context
from selpres.run.train import train
from selpres_studies import modern

from conftest import REPO, cfg_of

COMMON = ["schedule=infobatch", "schedule.epochs=[4]", "replicas=2"]
JOBS = {
    "infobatch": [],
    "uniform": ["schedule.pruning._target_=my_pruning.UniformPruning"],
    "infobatch_r03": ["schedule.pruning.prune_ratio=0.3"],  # the same seeds, another setting
}
USER = "infobatch[my_pruning.UniformPruning]"


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    s = tmp_path_factory.mktemp("mix")
    sys.path.insert(0, str(REPO / "examples" / "extending"))
    try:
        for name, ov in JOBS.items():
            train(cfg_of(*COMMON, *ov), s / name)
    finally:
        sys.path.remove(str(REPO / "examples" / "extending"))
    return s


def _res(sweep, name) -> dict:
    return json.loads((sweep / name / "results.json").read_text())


def _rms(res) -> dict[int, float]:
    return {r["seed"]: r["final"]["heldout"]["nm"]["overall"] for r in res["replica_results"]}


def test_every_section_keys_the_users_policy_apart_and_nothing_is_overwritten(sweep):
    ctx = Context.load(sweep, Options())
    labels = {j.path.name: j.schedule for j in ctx.jobs}
    assert labels == {
        "infobatch": "infobatch schedule.pruning.prune_ratio=0.5",
        "infobatch_r03": "infobatch schedule.pruning.prune_ratio=0.3",
        "uniform": USER,  # alone under its name: no settings to tell it apart by
    }
    assert sorted(m for _, m in ctx.groups) == sorted(labels.values())
    cells = modern.cells(ctx)
    assert sorted(m for _, _, m in cells) == sorted(labels.values())  # the modern study keys them alike
    for name, method in labels.items():
        (cell,) = [c for (_, _, m), c in cells.items() if m == method]
        res = _res(sweep, name)
        assert cell.rms == _rms(res) and len(cell.costs) == 1  # its own seeds, not another job's
        assert cell.cost == res["cost"]["presentations"] == ctx.groups[(res["topology"], method)].cost


def test_the_cost_and_its_ratio_are_what_each_method_presented(sweep):
    """UniformPruning keeps int(0.5 x 1002) = 501 patterns in the epochs before delta x 4 = 3.5 (0..3: all four),
    so 4 x 501 of conventional's 4 x 1002: a ratio of 0.5 exactly; InfoBatch's is read from its own ledger."""
    user, ib = _res(sweep, "uniform"), _res(sweep, "infobatch")
    assert user["selector"]["name"] == user["selector"]["class"] == "my_pruning.UniformPruning"
    assert user["cost"]["presentations"] == 4 * 501 and user["schedule"]["cost_ratio"] == 0.5
    assert user["schedule"]["conventional_presentations"] == 4 * 1002
    trained = ib["cost"]["per_replica"]["trained"]
    assert ib["schedule"]["cost_ratio"] == sum(trained) / (2 * 4 * 1002) < 1
    assert ib["selector"]["name"] == "infobatch" and ib["selector"]["user_classes"] == []
    assert ib["cost"]["per_replica"]["spent"] == trained and ib["selector"]["checkpointed"] is True
    assert "pruning" not in ib and set(ib) == set(user)  # every method records the same nodes
