"""The sweep section of the report (selpres.report.sections.sweep): a parametric sweep with and without its
partners, read back by the real report, checked against scipy's paired t-test, a hand-written Holm and a brute-force
Pareto set; the partners' full run equals conventional training; the sweep's progress line."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from selpres.report.build import Report
from selpres.run.partners import costs, partner_overrides
from selpres.run.train import train

from conftest import cfg_of, numbers

TINY = ("schedule.total_epochs=4", "replicas=4", "logging.tensorboard=false", "checkpoint.enabled=false")
GRID = [(p, f) for p in (1, 2) for f in (0.05, 0.1)]


def job(sweep: Path, name: str, *overrides: str) -> dict:
    return train(cfg_of(*overrides), sweep / name)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """A 2 x 2 parametric sweep (p x first) of tiny jobs with its partners, as partners=on runs them."""
    root = tmp_path_factory.mktemp("sweep")
    for p, f in GRID:
        job(
            root,
            f"schedule.first={f},schedule.p={p}",
            "schedule=stages",
            f"schedule.p={p}",
            f"schedule.first={f}",
            *TINY,
        )
    given = ["schedule=stages", "schedule.p=1,2", "schedule.first=0.05,0.1", *TINY[1:]]
    one_stage = [o for o in partner_overrides(given, costs(root)) if o.startswith("schedule.")]
    for budget in costs(root):
        over = [o if not o.startswith("schedule.budget=") else f"schedule.budget={budget}" for o in one_stage]
        job(root / "partners", f"budget={budget}", "schedule=stages", *over, *TINY[1:])
    hydra = {"overrides": {"task": given, "hydra": []}, "runtime": {"choices": {"hydra/launcher": "basic"}}}
    OmegaConf.save(OmegaConf.create({"hydra": hydra}), root / "multirun.yaml")
    return root


def section_of(report: Report):
    return next(s for s in report.sections if s.title.startswith("Sweep over"))


def test_the_partners_are_every_cost_and_the_full_run(sweep):
    staged = []
    for path in sweep.glob("schedule.first=*/results.json"):
        r = json.loads(path.read_text())
        staged.append(r["presentations_done"])
    assert costs(sweep) == sorted({*staged, 1002 * 4})  # and n·ΣN_i: the full conventional run


def test_the_full_partner_is_conventional_training(sweep, tmp_path):
    """The partner at n·N presentations has the conventional preset's stages, so its numbers (N = 4 epochs)."""
    full = json.loads((sweep / "partners" / f"budget={1002 * 4}" / "results.json").read_text())
    conv = train(cfg_of("schedule=conventional", "schedule.epochs=[4]", *TINY[1:]), tmp_path / "conv")
    a, b = numbers(full), numbers(conv)
    assert a["summary"] == b["summary"] and a["replica_results"] == b["replica_results"] and a["curves"] == b["curves"]


def test_the_section_answers_the_sweep(sweep):
    from scipy.stats import ttest_rel

    report = Report.build(sweep)
    assert report.title == "Sweep over schedule.first × schedule.p"  # titled by what the sweep varied
    sec = section_of(report)
    rows = sec.csv["sweep.csv"]
    assert [(int(r["schedule.p"]), float(r["schedule.first"])) for r in rows] == [
        (p, f) for f in (0.05, 0.1) for p in (1, 2)
    ]
    groups = {g.schedule: g for g in report.ctx.groups.values()}
    # Δ against the partner, paired by seed, by scipy; Holm over the family of four, by hand
    raw = []
    for r in rows:
        me, partner = groups[r["setting"]], groups[r["partner_run"]]
        assert partner.cost == me.cost and partner.sched["sizes"] == [1002]
        seeds = sorted(set(me.values("heldout")) & set(partner.values("heldout")))
        a = [me.values("heldout")[s] for s in seeds]
        b = [partner.values("heldout")[s] for s in seeds]
        assert math.isclose(r["partner_diff_mean"], sum(x - y for x, y in zip(a, b)) / len(a), rel_tol=1e-9)
        raw.append(ttest_rel(a, b).pvalue)
    order = sorted(range(4), key=lambda i: raw[i])
    holm, running = [0.0] * 4, 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (4 - rank) * raw[i]))
        holm[i] = running
    for r, p in zip(rows, holm):
        assert math.isclose(r["partner_p_holm"], p, rel_tol=1e-6)
        assert (r["partner_verdict"] in ("better", "worse")) == (p < 0.05)
    # the Pareto set over every run (settings and conventional ones), brute force
    pts = [(g.cost, sum(g.values("heldout").values()) / len(g.values("heldout")), g.schedule) for g in groups.values()]
    front = {n for c, e, n in pts if not any(c2 <= c and e2 <= e and (c2, e2) != (c, e) for c2, e2, _ in pts)}
    assert {r["setting"] for r in rows if r["pareto"] == "Pareto"} == {n for n in front if n.startswith("stages")}
    text = sec.markdown()
    assert "Missing partners" not in text and "sweep_heatmap.png" in text and "sweep_error_cost.png" in text
    assert "**Best is a trade-off" in text and "--budget N" in text


def test_budget_names_the_lowest_error_within_it(sweep):
    from selpres.report.compare import Options

    rows = section_of(Report.build(sweep)).csv["sweep.csv"]
    cap = sorted(r["presentations"] for r in rows)[1]  # the two cheapest settings fit
    best = min((r for r in rows if r["presentations"] <= cap), key=lambda r: r["heldout_nm_mean"])
    text = section_of(Report.build(sweep, Options(budget=cap))).markdown()
    assert f"Within {cap:,} presentations (`--budget`): #{best['number']} " in text


def test_without_partners_the_report_names_them_and_the_command(sweep, tmp_path):
    import shutil

    bare = tmp_path / "bare"
    shutil.copytree(sweep, bare, ignore=shutil.ignore_patterns("partners"))
    report = Report.build(bare)
    text = section_of(report).markdown()
    assert "**Missing partners:** one-stage training stopped at" in text and "the full one-stage run" in text
    command = "python train.py -m schedule=stages schedule.p=1,2 schedule.first=0.05,0.1"
    assert f"`{command}" in text and "partners=on`" in text
    assert "No heat map: the settings' compute-matched partners are missing" in text
    files = report.write(tmp_path / "out")
    assert "sweep_error_cost.png" in files and "sweep.csv" in files


def test_one_key_gets_its_reason_for_no_heat_map(tmp_path):
    for p in (1, 2):
        job(tmp_path, f"p={p}", "schedule=stages", f"schedule.p={p}", *TINY)
    text = section_of(Report.build(tmp_path)).markdown()
    assert "No heat map: it needs a schedule swept over exactly two keys (stages: 1 swept key)." in text


def test_a_studys_sweep_keeps_its_own_sections(sweep, tmp_path):
    """experiment=<a study>: the study's report, not this section."""
    import shutil

    study = tmp_path / "study"
    shutil.copytree(sweep, study)
    hydra = OmegaConf.load(study / "multirun.yaml")
    hydra.hydra.runtime.choices.experiment = "sensitivity"
    OmegaConf.save(hydra, study / "multirun.yaml")
    assert not any(s.title.startswith("Sweep over") for s in Report.build(study).sections)


# ----------------------------------------------------------------------------------------------- progress lines
def test_the_sweeps_line_counts_jobs_and_estimates_the_rest(tmp_path):
    from selpres.run.progress import sweep_line

    f = tmp_path / "p.jsonl"
    lines = [{"total": 8, "start": 1000.0}, {"status": "COMPLETED"}, {"status": "FAILED"}, {"more": 4}]
    f.write_text("\n".join(json.dumps(x) for x in lines) + "\n")
    # 2 of 12 jobs in 30 s: 15 s a job, 10 left -> 2 min 30 s
    assert sweep_line(f, now=1030.0) == "sweep: 2/12 jobs done (1 failed), 30 s elapsed, about 2 min 30 s left"


@pytest.mark.parametrize(
    "params, task, jobs",
    [
        ({"seed": "0,1000"}, ["replicas=1,2,3"], 6),  # disjoint keys: the product, 2 x 3
        ({"seed": "0,1000", "replicas": "1,2,3"}, ["replicas=4,5", "seed=0"], 2),  # the command line's value wins
        ({"seed": "0,1000"}, ["seed=0"], 1),  # one value given: one job (Hydra launched 1, the count said 2)
    ],
)
def test_the_sweeps_count_is_hydras_own(params, task, jobs):
    """The count takes each key once, the command line's value over the experiment's, as Hydra's basic sweeper
    merges them (an experiment's list narrowed on the command line was once counted as the product of both)."""
    from selpres.run.progress import sweep_size

    cfg = OmegaConf.create({"hydra": {"sweeper": {"params": params}, "overrides": {"task": task}}})
    assert sweep_size(cfg) == jobs


class Tty(io.StringIO):
    def isatty(self):
        return True


def test_a_job_on_a_terminal_rewrites_one_line_and_a_pipe_gets_none(monkeypatch):
    import sys
    from types import SimpleNamespace

    from selpres.presentation.schedule import build_schedule
    from selpres.run import progress

    sched = build_schedule([50, 1002], [10, 10], 1002)
    prob = SimpleNamespace(schedule=sched, plan=sched.plan(), stage_ends=frozenset(sched.stage_ends()))
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert progress.EpochLine.for_run(multirun=False) is None  # not a terminal: only the usual lines
    monkeypatch.setattr(sys, "stderr", Tty())
    assert progress.EpochLine.for_run(multirun=True) is None  # a sweep's workers share the terminal
    line = progress.EpochLine.for_run(multirun=False)
    line.t0 -= 10  # as if the job had run 10 s already
    rec = {"epoch": 12, "stage": 1, "size": 1002, "presentations": 500 + 3 * 1002}
    line(rec, prob)
    out = sys.stderr.getvalue()
    assert out.startswith("\r\033[K") and "stage 2/2" in out and "epoch 13/20" in out and "3,506/10,520 (33 %)" in out
    assert "left" in out
    line({**rec, "epoch": 19, "presentations": 10_520}, prob)  # the stage's end: cleared for the stage line
    assert sys.stderr.getvalue().endswith("\r\033[K")
