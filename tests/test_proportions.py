"""Named schedules on any n (selpres.presentation.proportions through selpres.run.problem.prepare): the paper's counts
by their proportions, its budget scaled, the user's own counts kept or refused with the fraction form."""

from __future__ import annotations

import logging

import pytest

from selpres.errors import ConfigError
from selpres.presentation.proportions import fit_schedule

from conftest import cfg_of

SAMPLED = ("data=sampled", "data.n=10000")


def test_paper_counts_keep_their_proportions():
    # 50/1002*1e4 = 499.0, 100/1002*1e4 = 998.0, 400/1002*1e4 = 3992.0, 800/1002*1e4 = 7984.03 (by hand)
    sizes, budget, note = fit_schedule([50, 100, 400, 800, 1002], None, 10_000)
    assert [max(1, int(f * 10_000 + 0.5)) for f in sizes] == [499, 998, 3992, 7984, 10_000]
    assert budget is None and "applied as fractions" in note
    assert fit_schedule([50, 100, 1002], 70560, 1002) == (
        [50, 100, 1002],
        70560,
        None,
    )  # the paper's n: as given
    assert fit_schedule([100, 200, 500], None, 500) == ([100, 200, 500], None, None)  # the user's own counts


def test_budget_scales_with_n():
    _, budget, note = fit_schedule([1.0], 70560, 10_000)
    assert budget == 704_192 and "scaled by n/1002" in note  # 70560 * 10000 / 1002 = 704,191.6


def test_prepare_applies_and_logs_it(caplog):
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    with caplog.at_level(logging.INFO, logger="selpres"):
        prob = prepare(resolve(cfg_of(*SAMPLED)))
    assert prob.schedule.sizes == [499, 998, 3992, 7984, 10_000] and prob.schedule.epochs == [30] * 5
    assert prob.schedule.presentations == 30 * (499 + 998 + 3992 + 7984 + 10_000) == 704_190
    assert prob.schedule_note in caplog.text
    matched = prepare(resolve(cfg_of(*SAMPLED, "schedule=matched")))
    assert matched.schedule.presentations == 704_192  # within 2 presentations of the selective cost


def test_other_counts_are_refused_with_the_fraction_form():
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    with pytest.raises(ConfigError) as ei:
        prepare(resolve(cfg_of(*SAMPLED, "schedule.sizes=[100,200,5000]", "schedule.epochs=[1,1,1]")))
    assert ei.value.key == "schedule.sizes" and "schedule.sizes=[0.02,0.04,1.0]" in str(ei.value), str(ei.value)
