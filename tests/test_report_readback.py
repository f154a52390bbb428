"""Issue 26: the report never crashes on what a job wrote. NaN and infinities, missing fields and wrong types are
listed as such, the rest of the report is built and report.md written; a replica whose final score is not finite
is not complete (not averaged over the other seeds)."""

from __future__ import annotations

import csv
import json
import math

import pytest
from test_report import CON, RG, SEL, results, write_job

from selpres.report.__main__ import main


def nan_curves(r):  # the case: one job's curve values set to NaN (compare.py:216 crashed)
    for c in r["curves"]:
        c["heldout_rms_nm"] = [math.nan] * len(c["heldout_rms_nm"])
        c["train_mse"] = [math.inf] * len(c["train_mse"])


def nan_final(r):
    r["replica_results"][2]["final"]["heldout"]["nm"]["overall"] = math.nan


def garbage(r):  # "with other garbage beside it" (plots.py:176 crashed)
    r["curves"][0]["presentations"] = "x"
    r["schedule"]["sizes"] = None
    r["schedule"]["presentations_per_stage"] = {"a": 1}


def missing(r):
    del r["wall_seconds"]
    del r["curves"][0]["epoch"]


def wrong_types(r):
    r["replica_results"][0]["seed"] = "a"
    r["curves"][0]["heldout_rms_nm"] = [0.1, "x", 0.1, 0.1, 0.1]


def short_curve(r):
    r["curves"][0]["heldout_rms_nm"] = [0.1]


CASES = {
    "nan_curves": (nan_curves, "complete", "5/5", "10 curve values not finite (read as missing)"),
    "nan_final": (nan_final, "complete", "4/5 (1 not finite)", "seed 2: final heldout.nm.overall is nan"),
    "garbage": (garbage, "unreadable", "", "schedule.sizes is null (a list of integers expected)"),
    "missing": (missing, "unreadable", "", "wall_seconds is missing (an object expected)"),
    "wrong_types": (wrong_types, "unreadable", "", "replica_results[0].seed is a str 'a' (an integer expected)"),
    "short_curve": (short_curve, "unreadable", "", "curves[0].heldout_rms_nm is a list [0.1] (null or a list of 5"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_report_lists_what_a_job_wrote_wrong_and_builds_the_rest(tmp_path, capsys, case):
    damage, status, replicas, note = CASES[case]
    sweep, out = tmp_path / "sweep", tmp_path / "out"
    sel = json.loads(json.dumps(results("selective", "6-4-2", SEL)))
    damage(sel)
    write_job(sweep, "selective", "6-4-2", sel)  # json.dumps writes NaN and Infinity, as results.json does
    write_job(sweep, "conventional", "6-4-2", results("conventional", "6-4-2", CON))
    write_job(sweep, "random_growth", "6-4-2", results("random_growth", "6-4-2", RG))
    assert main([str(sweep), "--out", str(out)]) == 0
    md = (out / "report.md").read_text()
    assert "not built" not in md and "could not be built" not in capsys.readouterr().err  # no section lost
    runs = {r["job"]: r for r in csv.DictReader((out / "runs.csv").open())}
    row = runs["schedule=selective,topology=6-4-2"]
    assert row["status"] == status and row["replicas"] == replicas and note in row["error"], row
    t1 = {r["method"]: r for r in csv.DictReader((out / "table1.csv").open())}
    assert float(t1["conventional"]["heldout_nm_mean"]) == pytest.approx(sum(CON) / 5)  # the rest is built
    if case == "nan_final":  # the mean of the 4 finite seeds, and 4/5 complete, not 5/5
        assert float(t1["selective"]["heldout_nm_mean"]) == pytest.approx((sum(SEL) - SEL[2]) / 4)
        assert "| replicas complete | 5/5 | 4/5 (1 not finite) | 5/5 |" in md


def test_a_section_that_still_fails_is_named_and_the_rest_written(tmp_path, capsys, monkeypatch):
    """The net under the checks: a section that raises is replaced by one line naming it; report.md is written."""
    from selpres_studies import table1

    def broken(ctx):
        raise TypeError("'<=' not supported between instances of 'NoneType' and 'float'")

    sections = [(name, broken if name == "plots" else make) for name, make in table1.GRID_SECTIONS]
    monkeypatch.setattr(table1, "GRID_SECTIONS", sections)
    sweep, out = tmp_path / "sweep", tmp_path / "out"
    write_job(sweep, "selective", "6-4-2", results("selective", "6-4-2", SEL))
    write_job(sweep, "conventional", "6-4-2", results("conventional", "6-4-2", CON))
    assert main([str(sweep), "--out", str(out)]) == 0
    md = (out / "report.md").read_text()
    assert "the plots section could not be built from these results: TypeError" in md
    assert "## Runs" in md and "## Table 1" in md
    assert capsys.readouterr().err.count("could not be built") == 1
