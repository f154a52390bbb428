"""The studies apart from the report: a study is a plug-in the report is given (a package of them is a module each,
no list), the study the sweep ran leads, and the modern section takes what the jobs recorded — a pruning policy or
an arm no code knows gets its rows, and the compute-matched partner is the one the study's design names."""

from __future__ import annotations

import dataclasses
import json
import shutil
import sys

import pytest

from selpres.report import build, plugins
from selpres.report.build import Report
from selpres.report.compare import Options
from selpres.report.context import Context, Section, experiment_of
from selpres.run.stats import holm, t_test
from selpres.run.train import train
from selpres_studies import modern

from conftest import cfg_of

# the tiny runs here stall by the study's rule (a few epochs): with no stall and no trimming the converged error is
# the plain paired t-test these tests check by hand (the stall rule and the trimmed mean: tests/test_report_modern.py)
PLAIN = dict(stall_share=10.0, trim=0.0)

COMMON = ["optim=adam_minibatch", "model.activation=relu", "replicas=3", "schedule.budget=3006", "schedule.epochs=null"]
NEW = ("seta", "dynamic_random")  # pruning policies no code of the report knows (issue 31's SeTa and its control)


@pytest.fixture(scope="module")
def real(tmp_path_factory):
    """A small real sweep: the partner and one rival, trained."""
    s = tmp_path_factory.mktemp("real")
    for name in ("matched", "infobatch"):
        train(cfg_of(f"schedule={name}", *COMMON), s / name)
    return s


def _copy(real, sweep, src: str, dst: str, method: str | None = None, arm: str | None = None, shift: float = 0.0):
    """A copy of a real job folder, its recorded schedule name (and arm) renamed, its final RMS shifted by
    ``shift`` x (seed + 1) so the paired differences are not all equal."""
    shutil.copytree(real / src, sweep / dst)
    res = json.loads((sweep / dst / "results.json").read_text())
    if method:
        res["schedule"]["name"] = res["config"]["schedule"]["name"] = method
    if arm:
        res["config"]["robot"]["name"] = arm
    for rep in res["replica_results"]:
        rep["final"]["heldout"]["nm"]["overall"] += shift * (rep["seed"] + 1)
    (sweep / dst / "results.json").write_text(json.dumps(res))
    return {r["seed"]: r["final"]["heldout"]["nm"]["overall"] for r in res["replica_results"]}


@pytest.fixture(scope="module")
def sweep(real, tmp_path_factory):
    """The real jobs, the rival copied as two methods no code knows, and the lot again on an arm no code knows."""
    s = tmp_path_factory.mktemp("studies")
    rms = {}
    for arm in ("two_link", "hexapod_leg"):
        rms[arm, "matched"] = _copy(real, s, "matched", f"{arm}_matched", arm=arm)
        rms[arm, "infobatch"] = _copy(real, s, "infobatch", f"{arm}_infobatch", arm=arm)
        for k, method in enumerate(NEW):
            rms[arm, method] = _copy(real, s, "infobatch", f"{arm}_{method}", method, arm, shift=0.01 * (k + 1))
    return s, rms


def test_a_pruning_policy_and_an_arm_no_code_knows_get_their_rows(sweep):
    s, rms = sweep
    ctx = Context.load(s, Options())
    rows = modern.summary_rows(modern.cells(ctx))
    # the design's listed methods in its order, the new ones after them by name; each arm as the config names it
    assert [(r["arm"], r["method"]) for r in rows] == [
        (arm, m) for arm in ("hexapod_leg", "two-link") for m in ("matched", "infobatch", "seta", "dynamic_random")
    ]
    seta = next(r for r in rows if r["method"] == "seta" and r["arm"] == "hexapod_leg")
    assert seta["rms_mean"] == pytest.approx(sum(rms["hexapod_leg", "seta"].values()) / 3, rel=1e-12)
    assert seta["rms_n"] == 3

    plain = dataclasses.replace(modern.DESIGN, **PLAIN)
    verdicts = modern.verdict_rows(modern.cells(ctx, plain), ctx.options, plain)
    modern.judge(verdicts, [], ctx.options)
    assert [r["comparison"] for r in verdicts] == [
        f"{m} − matched" for _ in range(2) for m in ("infobatch", "seta", "dynamic_random")
    ]
    # Δ by hand, paired by seed; Holm over the whole family of six comparisons
    ps = []
    for r, arm, m in zip(verdicts, ["hexapod_leg"] * 3 + ["two_link"] * 3, ("infobatch", "seta", "dynamic_random") * 2):
        d = [rms[arm, m][seed] - rms[arm, "matched"][seed] for seed in sorted(rms[arm, "matched"])]
        assert r["rms_diff_mean"] == pytest.approx(sum(d) / len(d), abs=1e-15)
        assert r["rms_family_size"] == 6
        ps.append(t_test(d)["p"] if len(set(d)) > 1 else None)
    tested = [(r, p) for r, p in zip(verdicts, ps) if p is not None]
    for (r, _), p in zip(tested, holm([p for _, p in tested])):
        assert r["rms_p_holm"] == pytest.approx(p)

    md = Report.build(s, Options()).markdown
    assert "| hexapod_leg |" in md and "| seta |" in md and "seta − matched" in md


def test_the_partner_is_the_one_the_studys_design_names(sweep):
    s, rms = sweep
    ctx = Context.load(s, Options())
    design = modern.Design(reference="conventional", partner="infobatch", order=("infobatch", "matched"), **PLAIN)
    rows = modern.verdict_rows(modern.cells(ctx, design), ctx.options, design)
    assert [r["comparison"] for r in rows][:3] == [f"{m} − infobatch" for m in ("matched", "dynamic_random", "seta")]
    seta, partner = rms["hexapod_leg", "seta"], rms["hexapod_leg", "infobatch"]
    d = [seta[seed] - partner[seed] for seed in sorted(partner)]  # 0.01, 0.02, 0.03 by construction
    assert rows[2]["rms_diff_mean"] == pytest.approx(sum(d) / 3, abs=1e-15) and sum(d) / 3 == pytest.approx(0.02)
    assert "the partner `infobatch`" in modern.note(ctx.options, design)
    # the design file the study ships names matched
    assert modern.Design.load().partner == "matched" and modern.DESIGN.reference == "conventional"


def test_the_figure_keeps_each_methods_colour_and_draws_new_ones(sweep, tmp_path):
    s, _ = sweep
    files = Report.build(s, Options()).write(tmp_path)
    assert "modern_error_cost.png" in files and (tmp_path / "modern_error_cost.png").stat().st_size > 10_000


def test_the_experiment_a_sweep_ran_is_read_from_its_multirun_yaml(tmp_path):
    assert experiment_of(tmp_path) is None  # folders gathered by hand
    (tmp_path / "multirun.yaml").write_text("hydra:\n  runtime:\n    choices:\n      experiment: modern\n")
    assert experiment_of(tmp_path) == "modern"
    (tmp_path / "multirun.yaml").write_text("hydra:\n  runtime:\n    choices:\n      optim: sgd\n")
    assert experiment_of(tmp_path) is None


def _mystudies(tmp_path, monkeypatch) -> None:
    """A package of studies of our own on the path: each module's SECTION; one gives None, one two sections."""
    pkg = tmp_path / "mystudies"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    for name, body in {
        "alpha": "Section('alpha', [])",
        "beta": "[Section('beta', []), Section('beta plane', [])]",
        "gamma": "None",
        "_helper": "Section('helper', [])",
    }.items():
        (pkg / f"{name}.py").write_text(f"from selpres.report import Section\n\nSECTION = lambda ctx: {body}\n")
    monkeypatch.syspath_prepend(str(tmp_path))


def test_a_study_is_a_plug_in_given_by_import_path_and_the_sweeps_own_leads(tmp_path, monkeypatch):
    """A package of studies: each public module's SECTION, no list; the study the sweep ran first, the others in the
    order given (a package's by name); one that does not apply (None) left out; one may give several sections; a
    module is a plug-in of its own; one that cannot be imported is one line, the rest kept."""
    _mystudies(tmp_path, monkeypatch)
    found = plugins.studies(["mystudies"])
    assert [(s.name, s.path) for s in found] == [(n, f"mystudies.{n}") for n in ("alpha", "beta", "gamma")]
    ctx = Context(tmp_path, [], {}, [], [], experiment=None)
    assert [s.title for s in build.study_sections(ctx, found)] == ["alpha", "beta", "beta plane"]
    ctx.experiment = "beta"
    assert [s.title for s in build.study_sections(ctx, found)] == ["beta", "beta plane", "alpha"]
    assert isinstance(build.study_sections(ctx, found)[0], Section)
    # modules given one by one, in the order given; one that is not there is named, the rest written
    found = plugins.studies(["mystudies.gamma", "mystudies.nowhere", "mystudies.beta", "mystudies.alpha"])
    ctx.experiment = None
    made = build.study_sections(ctx, found)
    assert [s.title for s in made] == ["nowhere (not built)", "beta", "beta plane", "alpha"]
    (line,) = made[0].blocks
    assert "mystudies.nowhere" in line and "could not be imported" in line and "\n" not in line
    for name in list(sys.modules):
        if name.startswith("mystudies"):
            sys.modules.pop(name)


def test_the_report_takes_its_plug_ins_from_the_command_line_the_sweep_or_the_installation(tmp_path, monkeypatch):
    """--sections first, then the sweep's record (multirun.yaml's hydra.callbacks.report.sections, which the
    experiment configs set), then the entry points installed; and the library names none itself."""
    _mystudies(tmp_path, monkeypatch)
    sweep = tmp_path / "sweep"
    sweep.mkdir()
    monkeypatch.setattr(plugins, "installed", lambda: ["mystudies.alpha"])
    assert plugins.given(sweep) == ["mystudies.alpha"]  # a sweep that names none: the installed ones
    (sweep / "multirun.yaml").write_text(
        "hydra:\n  callbacks:\n    report:\n      _target_: selpres.report.callback.ReportSections\n"
        "      sections: [mystudies.beta]\n  runtime:\n    choices:\n      experiment: beta\n"
    )
    assert plugins.recorded(sweep) == ["mystudies.beta"] and plugins.given(sweep) == ["mystudies.beta"]
    assert plugins.given(sweep, ["mystudies.gamma"]) == ["mystudies.gamma"]
    for name in list(sys.modules):
        if name.startswith("mystudies"):
            sys.modules.pop(name)


def test_every_experiment_names_the_studies_for_its_report_and_leaves_the_job_alone(compose_cfg):
    """Each experiment config gives its sweep's report the repository's studies (recorded by Hydra in multirun.yaml);
    the node is Hydra's, so the jobs' configs and identities do not see it."""
    from selpres.run.results import job_hash

    from conftest import CONFIGS

    for path in sorted((CONFIGS / "experiment").glob("*.yaml")):
        cfg = compose_cfg(f"experiment={path.stem}", hydra=True)
        node = cfg.hydra.callbacks.report
        assert node._target_ == "selpres.report.callback.ReportSections", path.stem
        assert list(node.sections) == ["selpres_studies"], path.stem
        assert "report" not in compose_cfg(f"experiment={path.stem}")
    # what the callback says at a sweep's start when a plug-in is not installed here: one line each, nothing raised
    assert plugins.unavailable(["selpres_studies"]) == []
    (line,) = plugins.unavailable(["no_such_studies"])
    assert "no_such_studies" in line and "\n" not in line
    assert job_hash(compose_cfg("experiment=table1", "schedule=selective", "topology=6-13-2")) == job_hash(
        compose_cfg("schedule=selective", "topology=6-13-2", "replicas=30", "threads=1", "eval.every=5", "name=table1")
    )


def test_the_callback_says_at_the_sweeps_start_which_plug_ins_are_missing(capsys):
    from selpres.report.callback import ReportSections

    ReportSections(["selpres_studies", "no_such_studies"]).on_multirun_start(config=None)
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("warning: the report plug-in no_such_studies is not installed here")
