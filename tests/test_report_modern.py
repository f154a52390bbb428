"""The modern-training section on a real (tiny) sweep: costs, paired Δ by seed against the compute-matched
partner, Holm's family, nMSE by an independent formula, and the figure."""

from __future__ import annotations

import dataclasses
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

# the tiny runs below stall by the study's rule (a few epochs): with no stall and no trimming, the converged error
# is the plain paired t-test, checked by hand here; the stall rule and the trimmed mean: the tests at the end
PLAIN = dataclasses.replace(modern.DESIGN, stall_share=10.0, trim=0.0)
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
    cs = modern.cells(ctx, PLAIN)
    rows, claims = modern.verdict_rows(cs, ctx.options, PLAIN), modern.claim_rows(cs, ctx.options, PLAIN)
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
    cs = modern.cells(ctx, PLAIN)
    rows, claims = modern.verdict_rows(cs, ctx.options, PLAIN), modern.claim_rows(cs, ctx.options, PLAIN)
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
    cs = modern.cells(ctx, PLAIN)
    (row,) = [r for r in modern.claim_rows(cs, ctx.options, PLAIN) if r["claim"] == "speedup"]
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


def _cell(method, regime="Adam", rms=None, stalled=None, dead=None):
    c = modern.Cell("two-link", regime, method, rms=dict(rms or {}), stalled=dict(stalled or {}))
    c.dead = dict(dead or {})
    c.linear = {s: 1 for s in c.dead}
    return c


def test_converged_error_leaves_out_the_stalled_pairs_and_trims():
    from scipy.stats import mstats

    seeds = range(12)
    ref = _cell("conventional", rms={s: 1.0 + 0.01 * s for s in seeds}, stalled={s: s == 3 for s in seeds})
    # the method: a stall at seed 5, an outlier at seed 7 (converged, but far off)
    rms = {s: 1.0 + 0.012 * s + (2.0 if s == 7 else 0.0) + (3.0 if s == 5 else 0.0) for s in seeds}
    c = _cell("m", rms=rms, stalled={s: s == 5 for s in seeds})
    v = modern.converged_paired(c, ref, "rms", Options(), modern.DESIGN)
    ok = [s for s in seeds if s not in (3, 5)]
    d = [rms[s] - ref.rms[s] for s in ok]
    assert v["n"] == 10 and v["stalled_pairs"] == 2 and v["plain_n"] == 12
    assert v["mean"] == pytest.approx(float(mstats.trimmed_mean(d, limits=(0.2, 0.2))))
    assert v["se"] == pytest.approx(float(mstats.trimmed_stde(d, limits=(0.2, 0.2))))
    assert v["plain_mean"] == pytest.approx(sum(rms[s] - ref.rms[s] for s in seeds) / 12)
    loc = float(mstats.trimmed_mean([rms[s] for s in ok], limits=(0.2, 0.2)))
    assert v["margin"] == pytest.approx(0.05 * loc)  # 5 % of the method's own converged error
    claim = modern.converged_paired(c, ref, "rms", Options(), modern.DESIGN, of="other")
    ref_loc = float(mstats.trimmed_mean([ref.rms[s] for s in ok], limits=(0.2, 0.2)))
    assert claim["margin"] == pytest.approx(0.05 * ref_loc)  # a claim: 5 % of the reference's


def test_stall_rows_exact_interval_mcnemar_and_holm():
    from scipy import stats as sps

    seeds = range(20)
    ref = _cell("conventional", stalled={s: s < 2 for s in seeds}, dead={s: 3 if s < 2 else 1 for s in seeds})
    a = _cell("selective", stalled={s: s < 8 for s in seeds}, dead={s: 9 if s < 8 else 2 for s in seeds})
    b = _cell("matched", stalled={s: s in (0, 1, 19) for s in seeds}, dead={s: 0 for s in seeds})
    for c in (ref, a, b):
        c.rms = {s: 1.0 for s in seeds}
    cs = {("two-link", "Adam", c.method): c for c in (ref, a, b)}
    rows = {r["method"]: r for r in modern.stall_rows(cs)}
    r = rows["selective"]
    ci = sps.binomtest(8, 20).proportion_ci(method="exact")
    assert (r["stalls"], r["seeds"]) == (8, 20) and (r["rate_lo"], r["rate_hi"]) == pytest.approx((ci.low, ci.high))
    assert (r["vs_ref_only_this"], r["vs_ref_only_other"]) == (6, 0)  # seeds 2..7 stalled only with selective
    assert r["vs_ref_p"] == pytest.approx(2 / 2**6)
    assert (r["stalled_dead"], r["other_dead"]) == (9, 2)
    assert rows["matched"]["vs_ref_p"] == 1.0 and "vs_ref_p" not in rows["conventional"]
    assert r["vs_ref_p_holm"] == pytest.approx(min(1.0, 2 * 2 / 2**6))  # two tests: Holm doubles the smaller
    assert "6 / 0" in modern.stall_markdown(list(rows.values()))


def test_the_remedy_is_paired_with_the_regime_it_remedies():
    seeds = range(10)
    base = _cell("conventional", regime="Adam (batch 32, cosine lr), ReLU", stalled={s: s < 4 for s in seeds})
    fixed = _cell("conventional", regime="Adam (batch 32, cosine lr), leaky ReLU", stalled={s: s == 9 for s in seeds})
    other = _cell("conventional", regime="paper: sigmoid", stalled={s: False for s in seeds})
    cs = {("two-link", c.regime, c.method): c for c in (base, fixed, other)}
    (row,) = modern.remedy_rows(cs)
    assert row["remedies"] == base.regime and row["regime"] == fixed.regime
    assert (row["base_stalls"], row["remedy_stalls"]) == (4, 1)
    assert (row["vs_base_only_this"], row["vs_base_only_other"]) == (1, 4)
    assert row["vs_base_p"] == pytest.approx(2 * (1 + 5) / 2**5)


def test_cells_read_each_seeds_stall_and_units_from_results(sweep):
    ctx = Context.load(sweep, Options())
    cs = modern.cells(ctx)
    c = next(c for c in cs.values() if c.method == "conventional")
    rms, res = _seeds(sweep, "conventional")
    floor = res["floor"]["heldout"]["nm"]["overall"]
    assert c.stalled == {s: v >= modern.DESIGN.stall_share * floor for s, v in rms.items()}
    assert c.dead == {e["seed"]: e["dead"] for e in res["stalls"]["replicas"]} and c.hidden == 13


def test_a_method_on_the_epochs_clock_stays_in_its_regime():
    cfg = {"robot": {"name": "two_link"}, "model": {"activation": "relu"}}
    on = [modern.regime_of({**cfg, "optim": {"_target_": "adam", "batch_size": 32, "lr": 0.003, "lr_schedule": s}})
          for s in ("cosine", "cosine_epochs")]  # fmt: skip
    assert on[0] == on[1] == "Adam (batch 32, cosine lr), ReLU"
