"""The modern-training section on a real (tiny) sweep: costs, paired Δ by seed against the compute-matched
partner, Holm's family, nMSE by an independent formula, and the figure."""

from __future__ import annotations

import json
import math

import pytest

from selpres.data.task import load_task
from selpres.report.build import Report
from selpres.report.compare import Options
from selpres.report.context import Context
from selpres.run.specs import data_spec, robot_spec
from selpres.run.stats import holm, t_test, tost
from selpres.run.train import train
from selpres_studies import modern

from conftest import cfg_of

COMMON = ["optim=adam_minibatch", "model.activation=relu", "replicas=3", "schedule.budget=3006", "schedule.epochs=null"]


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    s = tmp_path_factory.mktemp("modern")
    for name, ov in {
        "matched": ["schedule=matched"],
        "infobatch": ["schedule=infobatch"],
        "selective_backprop": ["schedule=selective_backprop"],
    }.items():
        train(cfg_of(*ov, *COMMON), s / name)
    # at full cost: the reference, and two methods judged on their own claims
    full = [*COMMON[:3], "schedule.epochs=[6]"]
    for name, ov in {
        "conventional": ["schedule=conventional"],
        "infobatch_full": ["schedule=infobatch", "schedule.name=infobatch_full"],
        "selective_backprop_full": ["schedule=selective_backprop", "schedule.name=selective_backprop_full"],
    }.items():
        train(cfg_of(*ov, *full), s / name)
    return s


def _seeds(sweep, name, key="overall"):
    res = json.loads((sweep / name / "results.json").read_text())
    return {r["seed"]: r["final"]["heldout"]["nm"][key] for r in res["replica_results"]}, res


def test_rivals_against_the_matched_partner_paired_by_seed_with_holm(sweep):
    ctx = Context.load(sweep, Options())
    cs = modern.cells(ctx)
    rows, claims = modern.verdict_rows(cs, ctx.options), modern.claim_rows(cs, ctx.options)
    modern.judge(rows, claims, ctx.options)
    # the methods at full cost are not of the partner's cost: they are judged on their claims instead
    assert [r["comparison"] for r in rows] == ["infobatch − matched", "selective_backprop − matched"]
    m, _ = _seeds(sweep, "matched")
    ps = []
    for r, name in zip(rows, ("infobatch", "selective_backprop")):
        a, res = _seeds(sweep, name)
        d = [a[s] - m[s] for s in sorted(m)]
        assert r["rms_diff_mean"] == pytest.approx(sum(d) / len(d), abs=1e-15)
        assert r["cost_ratio"] == pytest.approx(1.0, abs=2e-3)  # stopped at the same total cost
        ps.append(t_test(d)["p"])
        assert r["rms_family_size"] == 3  # the family: both comparisons and the one tested claim
    c, _ = _seeds(sweep, "conventional")
    a, _ = _seeds(sweep, "infobatch_full")
    ps.append(t_test([a[s] - c[s] for s in sorted(c)])["p"])
    for r, p in zip(rows, holm(ps)):
        assert r["rms_p_holm"] == pytest.approx(p)
    diffs = [r["rms_diff_mean"] for r in rows]
    better = sum(p < 0.05 and d < 0 for p, d in zip(holm(ps), diffs))  # by hand, from the adjusted p-values
    worse = sum(p < 0.05 and d > 0 for p, d in zip(holm(ps), diffs))
    assert (
        "held-out RMS: of 2 comparisons with compute-matched training, after Holm's correction "
        f"{better} better, {worse} worse" in modern.headline(rows)
    )


def test_lossless_claim_is_tost_within_a_share_of_the_references_mean(sweep):
    ctx = Context.load(sweep, Options())
    cs = modern.cells(ctx)
    rows, claims = modern.verdict_rows(cs, ctx.options), modern.claim_rows(cs, ctx.options)
    modern.judge(rows, claims, ctx.options)
    (row,) = [r for r in claims if r["claim"] == "lossless"]
    c, conv = _seeds(sweep, "conventional")
    a, res = _seeds(sweep, "infobatch_full")
    d = [a[s] - c[s] for s in sorted(c)]
    m = 0.05 * sum(c.values()) / len(c)  # 5 % of conventional's mean, not the method's
    assert row["rms_margin"] == pytest.approx(m, rel=1e-12)
    assert row["rms_tost_p"] == pytest.approx(tost(d, m)["p"], rel=1e-12)
    assert row["cost_share"] == pytest.approx(modern.job_cost(res) / conv["schedule"]["presentations"], rel=1e-12)
    assert row["cost_share"] < 1  # InfoBatch's own saving
    holds = row["rms_p_holm"] < 0.05 and sum(d) < 0 or row["rms_tost_p_holm"] < 0.05
    assert row["claim_rms"] == ("holds" if holds else "contradicted" if row["rms_p_holm"] < 0.05 else "not shown")


def test_speedup_is_read_off_the_curves_seed_by_seed():
    ref = modern.Cell("a", "r", "conventional", curves={0: [(0, 0, 5.0), (100, 1.0, 2.0), (200, 2.0, 1.0)],
                                                       1: [(0, 0, 5.0), (200, 4.0, 2.0)]})  # fmt: skip
    sb = modern.Cell("a", "r", "sb", curves={0: [(0, 0, 5.0), (50, 0.2, 1.5), (120, 0.5, 0.9)],
                                            1: [(0, 0, 5.0), (300, 3.0, 2.5)]})  # fmt: skip
    got = modern.speedup(sb, ref)
    assert got == {"seeds": 2, "reached": 1, "cost_to_reach_share": 0.6, "wall_to_reach_share": 0.25}


def test_the_curve_records_the_methods_own_seconds(sweep):
    _, res = _seeds(sweep, "selective_backprop_full")
    work = [rec["work_seconds"] for rec in res["curves"]]
    assert work[0] == 0.0 and all(b >= a for a, b in zip(work, work[1:])) and work[-1] > 0
    w = res["wall_seconds"]
    assert work[-1] == pytest.approx(w["select"] + w["shuffle"] + w["train"], rel=1e-9)
    assert modern.job_work(res) == pytest.approx(work[-1], rel=1e-9)
    # Selective Backprop at full cost on its curves: its cost to reach conventional's final error, seed by seed
    ctx = Context.load(sweep, Options())
    cs = modern.cells(ctx)
    (row,) = [r for r in modern.claim_rows(cs, ctx.options) if r["claim"] == "speedup"]
    assert row["seeds"] == 3 and 0 <= row["reached"] <= 3


def test_nmse_is_mse_over_the_heldout_targets_variance(sweep):
    ctx = Context.load(sweep, Options())
    job = next(j for j in ctx.jobs if j.path.name == "matched")
    cfg = job.results["config"]

    Y = load_task(robot_spec(cfg["robot"]), data_spec(cfg["data"])).tests.heldout.Y
    var = ((Y - Y.mean(0)) ** 2).mean(0)  # by hand: the population variance
    t1, _ = _seeds(sweep, "matched", "tau1")
    t2, _ = _seeds(sweep, "matched", "tau2")
    got = modern.heldout_nmse(job)
    for s in t1:
        assert got[s] == pytest.approx(0.5 * (t1[s] ** 2 / float(var[0]) + t2[s] ** 2 / float(var[1])), rel=1e-12)
    assert all(v > 0 and not math.isnan(v) for v in got.values())


def test_report_shows_the_section_and_draws_the_figure(sweep, tmp_path):
    rep = Report.build(sweep, Options())
    files = rep.write(tmp_path)
    assert "modern_error_cost.png" in files and (tmp_path / "modern_error_cost.png").stat().st_size > 10_000
    assert (tmp_path / "modern_error_wall.png").stat().st_size > 10_000
    assert "Each method on its own claim" in rep.markdown and "modern_claims.csv" in files
    assert "Modern training and data pruning" in rep.markdown
