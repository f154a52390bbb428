"""The selection verdict on a synthetic sweep with hand-worked numbers: compute-matched partners, paired Δ
and its interval, the three readings, Holm over the table, time to target, the headline, and when the
section is shown."""

from __future__ import annotations

import math

import pytest
from test_report import PAPER_SGD, write_setting

from selpres.report import aggregate, load_jobs
from selpres.report.build import Report
from selpres.report.compare import Margin, Options
from selpres.run.stats import t_test
from selpres_studies._families import matched_partner
from selpres_studies.selection import headline, selection_rows, shown

T = "6-4-2"
M1 = [0.20, 0.21, 0.19, 0.20, 0.20]  # compute-matched conventional at 31,560 t (1002 × 31 + 498)
M2 = [0.15] * 5  # at 63,120 t (1002 × 62 + 996)
D_STRAT = [-0.010, -0.020, -0.010, -0.015, -0.005]  # mean −0.012: better
D_RANDOM = [0.01, -0.01, 0.01, -0.01, 0.0]  # mean 0, sd 0.01: equivalent within ±5 % of 0.20 = ±0.01
D_COVER = [0.020, 0.030, 0.020, 0.025, 0.025]  # mean +0.024: worse
D_STRAT2 = [0.01, -0.01, 0.02, -0.02, 0.0]  # mean 0, sd √(2.5e-4): no detectable difference at ±0.0075


def plus(base, d):
    return [b + x for b, x in zip(base, d)]


@pytest.fixture
def sweep(tmp_path):
    s = tmp_path / "sel"
    sel_curve = [(1500, [0.5] * 5), (16530, [0.15] * 5), (31560, [0.09] * 5)]
    write_setting(s, "strat1", "selective", T, plus(M1, D_STRAT), [50, 1002], [30, 30], curves=sel_curve)
    write_setting(s, "random1", "random_growth", T, plus(M1, D_RANDOM), [50, 1002], [30, 30], order="random")
    write_setting(s, "cover1", "coverage", T, plus(M1, D_COVER), [50, 1002], [30, 30], order="coverage")
    write_setting(s, "strat2", "selective", T, plus(M2, D_STRAT2), [50, 1002], [60, 60])
    write_setting(s, "cover3", "coverage", T, [0.2] * 5, [100, 1002], [30, 30], order="coverage")  # 33,060 t
    write_setting(s, "m1", "matched", T, M1, [1002], [31], extra=498, curves=[(10020, [0.4] * 5), (31560, [0.2] * 5)])
    write_setting(s, "m1lr", "matched", T, [0.5] * 5, [1002], [31], extra=498, optim={**PAPER_SGD, "lr": 0.1})
    write_setting(s, "m2", "matched", T, M2, [1002], [62], extra=996)
    write_setting(
        s, "con", "conventional", T, [0.1] * 5, [1002], [150], curves=[(75150, [0.3] * 5), (150300, [0.1] * 5)]
    )
    return s


def rows_by(sweep, options=Options()):
    groups, tops, _ = aggregate(load_jobs(sweep))
    return {(r["order"], r["budget"]): r for r in selection_rows(groups, tops, options)}


def test_partner_is_the_one_stage_run_of_the_same_budget_and_settings(sweep):
    groups, _, _ = aggregate(load_jobs(sweep))
    by_folder = {g.used[0].path.name: g for g in groups.values()}
    assert matched_partner(groups, by_folder["strat1"]) is by_folder["m1"]  # not m1lr (lr 0.1, named first)
    assert matched_partner(groups, by_folder["strat2"]) is by_folder["m2"]
    assert matched_partner(groups, by_folder["cover3"]) is None  # 33,060 / 31,560 − 1 = 4.8 % > 1 %


def test_paired_delta_interval_and_readings_by_hand(sweep):
    rows = rows_by(sweep)
    assert list(rows) == [
        ("stratified", 31560),
        ("stratified", 63120),
        ("random", 31560),
        ("coverage", 31560),
        ("coverage", 33060),
    ]
    r = rows[("stratified", 31560)]
    # d: mean −0.012, squared deviations 4+64+4+9+49 = 130e-6, sd √(130e-6 / 4), t(0.975, 4) = 2.776445
    half = 2.776445 * math.sqrt(130e-6 / 4) / math.sqrt(5)
    assert (r["heldout_pairs"], r["cost_ratio"]) == (5, 1.0)
    assert r["heldout_diff_mean"] == pytest.approx(-0.012)
    assert [r["heldout_ci_lo"], r["heldout_ci_hi"]] == pytest.approx([-0.012 - half, -0.012 + half], abs=1e-7)
    assert r["outcome"] == "better"
    assert r["reading_heldout"].startswith("stratified order better by 0.0120 Nm (6.0 %")
    rnd = rows[("random", 31560)]
    # margin 5 % of random's mean 0.20; 90 % interval 0 ± t(0.95, 4)·0.01/√5 = ±0.009534 lies inside ±0.01
    assert rnd["heldout_margin"] == pytest.approx(0.01)
    assert [rnd["heldout_ci90_lo"], rnd["heldout_ci90_hi"]] == pytest.approx([-0.009534, 0.009534], abs=1e-6)
    assert rnd["outcome"] == "equivalent"
    assert rnd["reading_heldout"].startswith("equivalent within ±0.0100 Nm")
    assert rows[("coverage", 31560)]["outcome"] == "worse"
    s2 = rows[("stratified", 63120)]  # 90 % half-width 2.131847 · √(2.5e-4 / 5) = 0.01507 > 0.0075
    assert s2["outcome"] == "no detectable difference" and s2["heldout_margin"] == pytest.approx(0.0075)
    assert "no compute-matched one-stage run at 33,060 t" in rows[("coverage", 33060)]["reading_heldout"]
    assert all(r.get("heldout_family_size") == 4 for k, r in rows.items() if k != ("coverage", 33060))


def test_time_to_conventional_and_matched_final(sweep):
    r = rows_by(sweep)[("stratified", 31560)]
    # conventional's final curve RMS 0.1: the curve gets to 0.09 at 31,560 (0.15 at 16,530 before it)
    assert (r["to_conventional_target"], r["to_conventional_reached"]) == (pytest.approx(0.1), "yes")
    assert (r["to_conventional_presentations"], r["to_conventional_previous_point"]) == (31560, 16530)
    # the matched run's final curve RMS 0.2: reached at 16,530
    assert (r["to_matched_target"], r["to_matched_presentations"]) == (pytest.approx(0.2), 16530)


def test_holm_over_the_table(sweep):
    raw, adj = rows_by(sweep), rows_by(sweep, Options(holm=True))
    keys = [k for k in raw if "heldout_p" in raw[k]]
    diffs = {
        ("stratified", 31560): D_STRAT,
        ("random", 31560): D_RANDOM,
        ("coverage", 31560): D_COVER,
        ("stratified", 63120): D_STRAT2,
    }
    p = {k: t_test(d)["p"] for k, d in diffs.items()}  # the paired test is the one-sample test of the Δs
    assert {k: raw[k]["heldout_p"] for k in keys} == pytest.approx(p)
    order = sorted(keys, key=lambda k: p[k])  # Holm by hand: k-th smallest × (4 − k), running maximum
    expected, running = {}, 0.0
    for rank, k in enumerate(order):
        running = max(running, min(1.0, (4 - rank) * p[k]))
        expected[k] = running
    assert {k: adj[k]["heldout_p_holm"] for k in keys} == pytest.approx(expected)
    assert order[0] == ("coverage", 31560) and expected[order[0]] == pytest.approx(4 * p[order[0]])


def test_headline_names_the_winner_or_states_the_null(sweep, tmp_path):
    groups, tops, _ = aggregate(load_jobs(sweep))
    options = Options()
    rows = selection_rows(groups, tops, options)
    text = headline(rows, options)
    half = 2.776445 * math.sqrt(130e-6 / 4) / math.sqrt(5)
    assert text.startswith(
        "**Beats compute-matched conventional training** (95 % interval of Δ below 0): "
        f"stratified order at 31,560 t on 6-4-2: lower by 0.0120 Nm (6.0 %; 95 % interval "
        f"[{-0.012 - half:+.4f}, {-0.012 + half:+.4f}])"
    )
    assert "4 comparisons: orders stratified, random, coverage; budgets 31,560, 63,120 t" in text
    assert "readings: 1 better, 1 equivalent, 1 no detectable difference, 1 worse" in text
    # without the winner: the null result, what was tried and how large an effect the intervals allow
    (sweep / "strat1" / "results.json").unlink()
    groups, tops, _ = aggregate(load_jobs(sweep))
    rows = selection_rows(groups, tops, Options(margin=Margin(0.001, relative=False)))
    text = headline(rows, Options())
    assert text.startswith(
        "**No order beats compute-matched conventional training** with a 95 % interval of "
        "Δ below 0 (3 comparisons: orders stratified, random, coverage;"
    )
    lo = min(r["heldout_ci_lo"] for r in rows if "heldout_ci_lo" in r)
    assert f"The 95 % intervals reach from {lo:+.4f} to " in text


def test_shown_only_beyond_table_1s_comparison(sweep, tmp_path):
    assert "## Selection verdict" in Report.build(sweep).markdown
    t1 = tmp_path / "t1"  # Table 1's shape: stratified and random at one budget, with a matched run
    write_setting(t1, "s", "selective", T, M1, [50, 1002], [30, 30])
    write_setting(t1, "r", "random_growth", T, M1, [50, 1002], [30, 30], order="random")
    write_setting(t1, "m", "matched", T, M1, [1002], [31], extra=498)
    groups, tops, _ = aggregate(load_jobs(t1))
    assert not shown(selection_rows(groups, tops))
    assert "Selection verdict" not in Report.build(t1).markdown
    write_setting(t1, "c", "coverage", T, M1, [50, 1002], [30, 30], order="coverage")  # a new order: shown
    groups, tops, _ = aggregate(load_jobs(t1))
    assert shown(selection_rows(groups, tops))
    files = Report.build(t1).write(tmp_path / "out")
    assert "selection.csv" in files
