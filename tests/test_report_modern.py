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
from selpres.run.stats import holm, t_test
from selpres.run.train import train
from selpres.studies import modern

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
    return s


def _seeds(sweep, name, key="overall"):
    res = json.loads((sweep / name / "results.json").read_text())
    return {r["seed"]: r["final"]["heldout"]["nm"][key] for r in res["replica_results"]}, res


def test_rivals_against_the_matched_partner_paired_by_seed_with_holm(sweep):
    ctx = Context.load(sweep, Options())
    rows = modern.verdict_rows(modern.cells(ctx), ctx.options)
    assert [r["comparison"] for r in rows] == ["infobatch − matched", "selective_backprop − matched"]
    m, _ = _seeds(sweep, "matched")
    ps = []
    for r, name in zip(rows, ("infobatch", "selective_backprop")):
        a, res = _seeds(sweep, name)
        d = [a[s] - m[s] for s in sorted(m)]
        assert r["rms_diff_mean"] == pytest.approx(sum(d) / len(d), abs=1e-15)
        assert r["cost_ratio"] == pytest.approx(1.0, abs=2e-3)  # stopped at the same total cost
        ps.append(t_test(d)["p"])
        assert r["rms_family_size"] == 2
    for r, p in zip(rows, holm(ps)):
        assert r["rms_p_holm"] == pytest.approx(p)
    diffs = [r["rms_diff_mean"] for r in rows]
    better = sum(p < 0.05 and d < 0 for p, d in zip(holm(ps), diffs))  # by hand, from the adjusted p-values
    worse = sum(p < 0.05 and d > 0 for p, d in zip(holm(ps), diffs))
    assert (
        "held-out RMS: of 2 comparisons with compute-matched training, after Holm's correction "
        f"{better} better, {worse} worse" in modern.headline(rows)
    )


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
    assert "Modern training and data pruning" in rep.markdown
