"""Stages, costs and validation of selective-presentation schedules (paper section 3, Table 1)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from selpres.errors import ConfigError
from selpres.presentation.schedule import Schedule, Stage, build_schedule, resolve_sizes

from conftest import load_group

N = 1002  # the paper's exemplar set


# ------------------------------------------------------------------------------------ Table 1 costs


def test_table1_selective_cost():
    s = build_schedule([50, 100, 400, 800, 1002], [30] * 5, N)
    # the paper's sum, written out: (50·30 + 100·30 + 400·30 + 800·30 + 1002·30)
    assert s.presentations == 1500 + 3000 + 12000 + 24000 + 30060 == 70_560
    assert s.p == 4 and s.n == N and s.total_epochs == 150
    d = s.describe()
    assert d["presentations_per_stage"] == [1500, 3000, 12000, 24000, 30060]
    assert d["presentations"] == 70_560
    assert d["conventional_presentations"] == 150_300  # T_con/t = 1002 × 150 (the paper prints 1,50,000t)
    assert d["cost_ratio"] == pytest.approx(70_560 / 150_300)
    assert 0.46 < d["cost_ratio"] < 0.48  # "≈ T_con/2": the paper's "speed up of nearly 50 %"


def test_table1_conventional_cost():
    s = build_schedule([1002], [150], N)
    assert s.presentations == 150_300 and s.p == 0 and s.total_epochs == 150
    assert s.describe()["cost_ratio"] == 1.0


def test_table1_from_config_files():
    """The shipped schedule configs reproduce Table 1's numbers."""
    for option, expected in (("selective", 70_560), ("conventional", 150_300), ("random_growth", 70_560)):
        c = load_group("schedule", option)
        s = build_schedule(list(c.sizes), list(c.epochs), N, c.get("budget"))
        assert s.presentations == expected, option
    c = load_group("schedule", "matched")
    m = build_schedule(list(c.sizes), None, N, c.budget)
    assert m.presentations == 70_560  # compute-matched to the selective schedule


def test_plan_matches_stages():
    s = build_schedule([50, 100, 1002], [2, 3, 1], N)
    plan = s.plan()
    assert [(p.index, p.stage, p.size, p.presentations) for p in plan] == [
        (0, 0, 50, 50),
        (1, 0, 50, 50),
        (2, 1, 100, 100),
        (3, 1, 100, 100),
        (4, 1, 100, 100),
        (5, 2, 1002, 1002),
    ]
    assert s.stage_ends() == [1, 4, 5]
    assert sum(p.presentations for p in plan) == s.presentations == 50 * 2 + 100 * 3 + 1002


# ---------------------------------------------------------------------------------- fractions → counts


@pytest.mark.parametrize(
    "sizes, expected",
    [
        ([0.05, 0.1, 0.4, 0.8, 1.0], [50, 100, 401, 802, 1002]),  # 50.1, 100.2, 400.8, 801.6
        ([0.2, 0.4, 0.6, 0.8, 1.0], [200, 401, 601, 802, 1002]),  # 200.4, 400.8, 601.2, 801.6
        ([0.1, 1.0], [100, 1002]),
        ([1.0], [1002]),
        ([0.0001, 1.0], [1, 1002]),  # 0.1 pattern rounds up to at least one
        ([50, 0.5, 1.0], [50, 501, 1002]),  # counts and fractions mixed
        ([50, 100, 1002], [50, 100, 1002]),  # counts stay counts
    ],
)
def test_fractions_to_counts(sizes, expected):
    assert resolve_sizes(sizes, N) == expected
    assert build_schedule(sizes, [1] * len(sizes), N).sizes == expected


def test_count_one_is_not_a_fraction():
    """``1`` (int) is one pattern, ``1.0`` (float) is all of them."""
    assert resolve_sizes([1.0], N) == [N]
    assert resolve_sizes([1], 1) == [1]
    with pytest.raises(ConfigError):
        resolve_sizes([1], N)


# ------------------------------------------------------------------------------ budget → partial epoch


def test_budget_matched_to_selective():
    s = build_schedule([1.0], None, N, budget=70_560)
    full, extra = 70, 420  # 70 × 1002 = 70,140; 70,560 − 70,140 = 420
    assert full * N + extra == 70_560
    assert s.stages == (Stage(N, full, extra),)
    plan = s.plan()
    assert len(plan) == full + 1 == s.total_epochs
    assert all(p.presentations == N and p.size == N for p in plan[:-1])
    assert plan[-1].presentations == extra and plan[-1].size == N and plan[-1].index == full
    assert sum(p.presentations for p in plan) == 70_560 == s.presentations
    assert s.describe()["extra_presentations"] == [extra]


@pytest.mark.parametrize("budget, full, extra", [(N, 1, 0), (3 * N, 3, 0), (500, 0, 500), (N + 1, 1, 1), (1, 0, 1)])
def test_budget_edges(budget, full, extra):
    s = build_schedule([N], None, N, budget=budget)
    plan = s.plan()
    assert [p.presentations for p in plan] == [N] * full + ([extra] if extra else [])
    assert sum(p.presentations for p in plan) == budget
    assert s.describe()["presentations"] == budget


def test_describe_is_json_safe_for_a_budget_below_one_epoch():
    """A budget smaller than n gives zero full epochs: the partial epoch is its own conventional equivalent."""
    import json

    d = build_schedule([N], None, N, budget=500).describe()
    json.dumps(d)
    assert d["conventional_presentations"] == 500 and d["cost_ratio"] == 1.0
    assert d["presentations"] == 500


# ------------------------------------------------------------------------------------ validation


def _raises(key, bad, sizes, epochs, n=N, budget=None):
    with pytest.raises(ConfigError) as ei:
        build_schedule(sizes, epochs, n, budget)
    e = ei.value
    msg = str(e)
    assert e.key == key and msg.startswith(key), msg
    assert bad in msg, f"{bad!r} not in {msg!r}"
    return msg


@pytest.mark.parametrize(
    "sizes, bad",
    [
        ([100, 50, 1002], "[100, 50, 1002]"),  # not strictly increasing
        ([50, 50, 1002], "[50, 50, 1002]"),  # equal stages: A1 = A2 is not an enlargement
        ([0.5, 0.5, 1.0], "[0.5, 0.5, 1.0]"),
        ([0.0001, 0.0002, 1.0], "[0.0001, 0.0002, 1.0]"),  # both round to 1 pattern
        ([50, 2000], "2000"),  # > n
        ([50, 100, 1003], "1003"),
        ([50, 500], "[50, 500]"),  # does not end at n
        ([0.05, 0.5], "[0.05, 0.5]"),
        ([0.0, 1.0], "0.0"),  # fractions outside (0, 1]
        ([-0.1, 1.0], "-0.1"),
        ([0.5, 1.5], "1.5"),
        ([1.0000001], "1.0000001"),
        ([0, 1002], "[0, 1002]"),  # non-positive counts
        ([-5, 1002], "-5"),
        ([float("nan"), 1.0], "nan"),
        ([0.5, float("inf")], "inf"),
        ([], "[]"),
        (["abc", 1002], "abc"),
        ([True, 1002], "True"),
        (None, "None"),
    ],
)
def test_bad_sizes(sizes, bad):
    epochs = [1] * len(sizes) if isinstance(sizes, list) else [1]
    _raises("schedule.sizes", bad, sizes, epochs)


@pytest.mark.parametrize(
    "sizes, epochs, bad",
    [
        ([50, 1002], [0, 30], "[0, 30]"),  # epochs ≤ 0
        ([50, 1002], [30, -1], "-1"),
        ([50, 100, 1002], [30, 30], "[30, 30]"),  # length mismatch
        ([50, 1002], [30, 30, 30], "[30, 30, 30]"),
        ([1002], [1.5], "1.5"),  # not whole
        ([1002], [True], "True"),
        ([50, 1002], None, "None"),  # no epochs and no budget
        ([1002], [3], "[3]"),  # epochs together with a budget (below)
    ],
)
def test_bad_epochs(sizes, epochs, bad):
    budget = 5000 if epochs == [3] else None
    _raises("schedule.epochs", bad, sizes, epochs, budget=budget)


@pytest.mark.parametrize(
    "sizes, budget, bad",
    [
        ([50, 1002], 5000, "5000"),  # a budget with several stages
        ([50, 100, 400, 800, 1002], 70_560, "70560"),
        ([1002], 0, "0"),
        ([1002], -10, "-10"),
        ([1002], 100.5, "100.5"),
        ([1002], True, "True"),
    ],
)
def test_bad_budget(sizes, budget, bad):
    _raises("schedule.budget", bad, sizes, None, budget=budget)


def test_error_message_explains_the_fix():
    msg = _raises("schedule.sizes", "[50, 500]", [50, 500], [1, 1])
    assert "1002" in msg  # tells the user what n is


def test_schedule_is_immutable():
    s = build_schedule([1002], [1], N)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.stages[0].size = 5  # type: ignore[misc]
    assert isinstance(s, Schedule) and not math.isnan(s.describe()["cost_ratio"])
