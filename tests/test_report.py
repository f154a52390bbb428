"""selpres.report on synthetic sweeps with known numbers: paired verdicts, time-to-target, runs, files,
CLI."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from selpres.report import aggregate, load_jobs
from selpres.report.__main__ import main
from selpres.report.compare import Margin, Options, reading, verdict_rows
from selpres.report.context import Context
from selpres.report.jobs import job_folders
from selpres.run.stats import t_quantile
from selpres_studies._paper import paper_setting
from selpres_studies.table1 import ORDER, table1_rows, time_to_target_rows

SCHED = {
    "conventional": ([1002], [150]),
    "selective": ([50, 100, 400, 800, 1002], [30] * 5),
    "random_growth": ([50, 100, 400, 800, 1002], [30] * 5),
    "matched": ([1002], [70]),
}


def results(schedule, topology, heldout, test10=None, curves=None, diverged=(), seed0=0):
    """A minimal but format-correct results.json dict: heldout/test10 are final Nm values per replica
    (scaled = Nm / 2); curves is [(presentations, [heldout curve per replica] or None)]."""
    sizes, epochs = SCHED[schedule]
    extra = [420] if schedule == "matched" else [0]
    pres = sum(n * e for n, e in zip(sizes, epochs)) + (420 if schedule == "matched" else 0)
    test10 = test10 or heldout
    seeds = [seed0 + r for r in range(len(heldout))]
    reps = []
    for r, s in enumerate(seeds):
        ok = s not in diverged
        final = {
            name: {
                u: {j: (vals[r] * k if ok else None) for j in ("overall", "tau1", "tau2")}
                for u, k in (("nm", 1.0), ("scaled", 0.5))
            }
            for name, vals in (("test10", test10), ("heldout", heldout))
        }
        reps.append(
            {
                "seed": s,
                "status": "complete" if ok else "diverged",
                "diverged": None if ok else {"epoch": 3, "presentations": 150},
                "final": final,
                "train_mse": 0.01 if ok else None,
            }
        )
    curves = curves or [(pres, list(heldout))]
    recs = [
        {
            "epoch": i,
            "stage": 0,
            "size": sizes[0],
            "presentations": p,
            "train_mse": [0.1] * len(seeds),
            "test10_rms_nm": [0.1] * len(seeds),
            "heldout_rms_nm": h,
        }
        for i, (p, h) in enumerate(curves)
    ]
    n_div = sum(r["status"] == "diverged" for r in reps)
    return {
        "status": "diverged" if n_div == len(seeds) else "complete",
        "diverged_replicas": n_div,
        "config_hash": "x",
        "schedule": {
            "name": schedule,
            "order": "stratified",
            "p": len(sizes) - 1,
            "sizes": sizes,
            "epochs": epochs,
            "extra_presentations": extra * len(sizes),
            "presentations_per_stage": [n * e for n, e in zip(sizes, epochs)],
            "presentations": pres,
            "conventional_presentations": 1002 * sum(epochs),
            "cost_ratio": pres / (1002 * sum(epochs)),
        },
        "topology": topology,
        "engine": "fast",
        "replicas": len(seeds),
        "seeds": seeds,
        "presentations_done": pres,
        "wall_seconds": {"total": 3.0, "train": 2.0, "loop": 2.5},
        "seconds_per_presentation": 1e-6,
        "summary": {},
        "replica_results": reps,
        "curves": recs,
        "config": {},
    }


def write_job(sweep: Path, schedule: str, topology: str, res: dict | None) -> Path:
    d = sweep / f"schedule={schedule},topology={topology}"
    (d / ".hydra").mkdir(parents=True)
    hydra_cfg = f"schedule:\n  name: {schedule}\ntopology:\n  layers: {topology}\n"
    (d / ".hydra" / "config.yaml").write_text(hydra_cfg)
    if res is not None:
        (d / "results.json").write_text(json.dumps(res))
    return d


PAPER_SGD = {"name": "paper", "lr": 0.15, "momentum": 0.9, "batch_size": 1}


def write_setting(
    sweep: Path,
    folder: str,
    name: str,
    topology: str,
    heldout: list,
    sizes: list,
    epochs: list,
    optim: dict | None = None,
    order: str = "stratified",
    extra: int = 0,
    curves=None,
    diverged=(),
    seed0: int = 0,
) -> Path:
    """One job of a parameter sweep: a results.json with the given stages (``extra`` presentations after the
    last full epoch, as a budget leaves), order, optimizer config and final held-out RMS per replica."""
    res = results("selective", topology, heldout, curves=curves, diverged=diverged, seed0=seed0)
    pres = sum(n * e for n, e in zip(sizes, epochs)) + extra
    res["schedule"].update(
        name=name,
        order=order,
        p=len(sizes) - 1,
        sizes=sizes,
        epochs=epochs,
        extra_presentations=[0] * (len(sizes) - 1) + [extra],
        presentations_per_stage=[n * e for n, e in zip(sizes, epochs)],
        presentations=pres,
        conventional_presentations=sizes[-1] * sum(epochs),
        cost_ratio=pres / (sizes[-1] * sum(epochs)),
    )
    res["presentations_done"] = pres
    res["config"] = {
        "schedule": {"name": name, "sizes": sizes, "epochs": epochs, "order": order},
        "topology": {"layers": topology},
        "optim": dict(optim or PAPER_SGD),
        "seed": seed0,
        "replicas": len(heldout),
    }
    d = sweep / folder
    d.mkdir(parents=True)
    (d / "results.json").write_text(json.dumps(res))
    return d


SEL = [0.10, 0.12, 0.11, 0.13, 0.09]
CON = [0.15, 0.14, 0.16, 0.15, 0.17]  # selective − conventional = -0.05 -0.02 -0.05 -0.02 -0.08
RG = [0.11, 0.11, 0.12, 0.12, 0.10]  # selective − random_growth = -0.01 +0.01 -0.01 +0.01 -0.01


@pytest.fixture
def sweep(tmp_path):
    s = tmp_path / "sweep"
    write_job(s, "selective", "6-4-2", results("selective", "6-4-2", SEL))
    write_job(s, "conventional", "6-4-2", results("conventional", "6-4-2", CON))
    write_job(s, "random_growth", "6-4-2", results("random_growth", "6-4-2", RG))
    write_job(s, "matched", "6-4-2", {"status": "failed", "error": "ValueError('boom')", "kind": "exception"})
    write_job(s, "selective", "6-8-2", results("selective", "6-8-2", SEL, diverged=(1,)))
    write_job(s, "conventional", "6-8-2", None)  # killed: no results.json
    return s


def test_paired_difference_and_interval_by_hand(sweep):
    groups, tops, methods = aggregate(load_jobs(sweep), ORDER)  # Table 1's order (studies/table1.yaml)
    assert tops == ["6-4-2", "6-8-2"] and methods == ["conventional", "selective", "matched", "random_growth"]
    # the report knows no method: without a study's order, by name
    assert aggregate(load_jobs(sweep))[2] == ["conventional", "matched", "random_growth", "selective"]
    rows = {(r["topology"], r["comparison"]): r for r in verdict_rows(groups, tops, methods, "selective")}
    v = rows[("6-4-2", "selective vs conventional")]
    d = [a - b for a, b in zip(SEL, CON)]
    mean = sum(d) / 5
    sd = math.sqrt(sum((x - mean) ** 2 for x in d) / 4)
    half = 2.7764451 * sd / math.sqrt(5)  # t_{0.975, 4}
    assert abs(t_quantile(0.975, 4) - 2.7764451) < 1e-5
    assert v["heldout_pairs"] == 5
    assert v["heldout_diff_mean"] == pytest.approx(-0.044)
    assert v["heldout_ci_lo"] == pytest.approx(mean - half, abs=1e-9)
    assert v["heldout_ci_hi"] == pytest.approx(mean + half, abs=1e-9)
    assert v["heldout_ci_hi"] < 0
    pct = 0.044 / (sum(CON) / 5) * 100
    assert v["reading_heldout"] == (
        f"selective better by 0.0440 Nm ({pct:.1f} %; 95 % interval [{mean - half:+.4f}, {mean + half:+.4f}])"
    )
    assert v["cost_ratio"] == pytest.approx(70560 / 150300)
    # CI containing 0 (d = −0.01 +0.01 −0.01 +0.01 −0.01: mean −0.002, sd √(480e-6 / 4)), and the 90 % TOST
    # interval −0.002 ± t(0.95, 4)·sd/√5 = −0.002 ± 2.131847·0.0048990 pokes out of ±5 % of selective's mean
    rg = rows[("6-4-2", "selective vs random_growth")]
    se = math.sqrt(480e-6 / 4) / math.sqrt(5)
    assert rg["heldout_margin"] == pytest.approx(0.05 * sum(SEL) / 5)  # 0.0055 Nm
    assert [rg["heldout_ci90_lo"], rg["heldout_ci90_hi"]] == pytest.approx(
        [-0.002 - 2.131847 * se, -0.002 + 2.131847 * se], abs=1e-6
    )
    assert rg["reading_heldout"] == (
        "no detectable difference (95 % interval "
        f"[{rg['heldout_ci_lo']:+.4f}, {rg['heldout_ci_hi']:+.4f}]); "
        "not shown equivalent within ±0.0055 Nm"
    )
    # failed other side
    assert rows[("6-4-2", "selective vs matched")]["reading_heldout"] == "no results for matched"


def test_reading_wording_three_readings_never_merged():
    base = {"n": 30, "other_mean": 0.1, "margin": 0.004, "ci90": [-0.0013, 0.0018]}
    worse = {**base, "mean": 0.02, "ci95": [0.01, 0.03], "p": 0.001, "p_tost": 0.9}
    assert reading(worse, "selective") == "selective worse by 0.0200 Nm (20.0 %; 95 % interval [+0.0100, +0.0300])"
    same = {**base, "mean": 0.0003, "ci95": [-0.0016, 0.0021], "p": 0.76, "p_tost": 0.01}
    assert reading(same, "selective") == "equivalent within ±0.0040 Nm (90 % interval [-0.0013, +0.0018])"
    unsure = {**base, "mean": -0.0014, "ci95": [-0.0039, 0.0010], "p": 0.24, "p_tost": 0.42}
    assert reading(unsure, "selective") == (
        "no detectable difference (95 % interval [-0.0039, +0.0010]); not shown equivalent within ±0.0040 Nm"
    )
    small = {**base, "mean": -0.001, "ci95": [-0.0018, -0.0002], "p": 0.02, "p_tost": 0.001}
    assert reading(small, name="x") == (
        "x better by 0.0010 Nm (1.0 %; 95 % interval [-0.0018, -0.0002]); "
        "yet within the margin: equivalent within ±0.0040 Nm"
    )
    # after Holm's correction an interval that excludes 0 no longer reads as a difference, and says why
    held = {**base, "mean": 0.0014, "ci95": [0.0002, 0.0025], "p": 0.074, "p_tost": 0.8, "holm": True}
    assert reading(held, "selective") == (
        "no detectable difference after Holm's correction (95 % interval "
        "[+0.0002, +0.0025]; Holm p = 0.074); not shown equivalent within ±0.0040 Nm"
    )
    assert reading({"n": 1, "mean": 0.02, "ci95": [None, None], "p": None}, "selective").startswith("too few pairs (1)")


# three seeds (df = 2, where the t CDF is 1/2 + t / (2√(t² + 2))): selective − other = 0, 0.1, 0.2
SEL3, OTHER3 = [2.0, 2.0, 2.0], [2.0, 1.9, 1.8]


def test_equivalence_and_t_test_end_to_end_by_hand(tmp_path):
    s = tmp_path / "sw"
    write_job(s, "selective", "6-4-2", results("selective", "6-4-2", SEL3))
    write_job(s, "matched", "6-4-2", results("matched", "6-4-2", OTHER3))
    groups, tops, methods = aggregate(load_jobs(s), ORDER)
    (v,) = verdict_rows(groups, tops, methods, "selective")  # default margin: 5 % of selective's mean 2.0 = 0.1
    assert v["heldout_margin"] == pytest.approx(0.1)
    assert v["heldout_p"] == pytest.approx(1 - math.sqrt(3 / 5), abs=1e-9)  # t = √3
    assert v["heldout_tost_p"] == pytest.approx(0.5, abs=1e-9)  # the mean sits on the margin: t_upper = 0
    assert v["heldout_family_size"] == 1
    assert v["reading_heldout"].startswith("no detectable difference (95 % interval")
    (v,) = verdict_rows(groups, tops, methods, "selective", Options(margin=Margin(0.3, relative=False)))
    # p_upper = F(−2√3) = 1/2 − √(3/14) = 0.0370900 > p_lower = 1/2 − √(12/50): equivalent within ±0.3
    assert v["heldout_tost_p"] == pytest.approx(0.5 - math.sqrt(3 / 14), abs=1e-9)
    assert v["reading_heldout"] == "equivalent within ±0.3000 Nm (90 % interval [-0.0686, +0.2686])"


def test_holm_adjusts_within_the_family_of_one_metric(sweep):
    groups, tops, methods = aggregate(load_jobs(sweep), ORDER)
    plain = {r["comparison"]: r for r in verdict_rows(groups, tops, methods, "selective") if r["topology"] == "6-4-2"}
    rows = {
        r["comparison"]: r
        for r in verdict_rows(groups, tops, methods, "selective", Options(holm=True))
        if r["topology"] == "6-4-2"
    }
    con, rg = (plain[f"selective vs {m}"]["heldout_p"] for m in ("conventional", "random_growth"))
    assert con < rg  # by hand: k = 2 tested pairs (matched failed, 6-8-2 has no conventional)
    assert rows["selective vs conventional"]["heldout_family_size"] == 2
    assert rows["selective vs conventional"]["heldout_p_holm"] == pytest.approx(min(1, 2 * con))
    assert rows["selective vs random_growth"]["heldout_p_holm"] == pytest.approx(max(min(1, 2 * con), rg))
    assert rows["selective vs conventional"]["heldout_p"] == pytest.approx(con)  # the raw p is kept
    assert "Holm p = " in rows["selective vs conventional"]["reading_heldout"]
    assert "heldout_p_holm" not in plain["selective vs conventional"]


def test_cli_margin_and_holm(sweep, tmp_path, capsys):
    out = tmp_path / "rep"
    assert main([str(sweep), "--out", str(out)]) == 0
    md = capsys.readouterr().out
    assert "Margin m = 5 % of selective's mean final RMS over the paired seeds" in md
    assert "Comparisons per family (one metric across this table): 2 held-out, 2 test-10" in md
    assert "not adjusted for multiplicity" in md
    assert main([str(sweep), "--out", str(out), "--margin", "0.01", "--holm"]) == 0
    md = capsys.readouterr().out
    assert "Margin m = 0.01 Nm (fixed with --margin)" in md and "Holm-adjusted within each family" in md
    verdict = {r["comparison"]: r for r in csv.DictReader((out / "verdict.csv").open()) if r["topology"] == "6-4-2"}
    assert float(verdict["selective vs random_growth"]["heldout_margin"]) == 0.01
    assert verdict["selective vs random_growth"]["heldout_p_holm"] != ""
    for bad in ("abc", "0", "-1%", "150%"):
        assert main([str(sweep), "--out", str(tmp_path / "bad"), f"--margin={bad}"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: --margin=") and repr(bad) in err and "5%" in err
    assert not (tmp_path / "bad").exists()


def test_pairs_only_seeds_complete_in_both(tmp_path):
    s = tmp_path / "sw"
    write_job(s, "selective", "6-4-2", results("selective", "6-4-2", SEL, diverged=(0, 3)))
    write_job(s, "conventional", "6-4-2", results("conventional", "6-4-2", CON[:4] + [0.2], diverged=(4,)))
    groups, tops, methods = aggregate(load_jobs(s), ORDER)
    (v,) = verdict_rows(groups, tops, methods, "selective")
    d = [SEL[i] - CON[i] for i in (1, 2)]
    assert v["heldout_pairs"] == 2
    assert v["heldout_diff_mean"] == pytest.approx(sum(d) / 2)
    t1 = {r["method"]: r for r in table1_rows(groups, tops, methods)}
    assert t1["selective"]["replicas"] == "3/5 (2 diverged)"
    assert t1["selective"]["heldout_nm_n"] == 3
    assert t1["selective"]["heldout_nm_mean"] == pytest.approx((SEL[1] + SEL[2] + SEL[4]) / 3)
    assert t1["selective"]["heldout_scaled_mean"] == pytest.approx((SEL[1] + SEL[2] + SEL[4]) / 6)


def test_time_to_target_on_known_curve(tmp_path):
    s = tmp_path / "sw"
    con_curve = [(30060, [0.30, 0.32]), (90180, [0.20, 0.22]), (150300, [0.10, 0.12])]  # target 0.11
    sel_curve = [(1500, [0.5, 0.5]), (16500, [0.2, None]), (40560, [0.12, 0.11]), (70560, [0.10, 0.11])]
    rg_curve = [(40560, [0.3, 0.3]), (70560, [0.2, 0.2])]
    write_job(s, "conventional", "6-4-2", results("conventional", "6-4-2", [0.1, 0.12], curves=con_curve))
    write_job(s, "selective", "6-4-2", results("selective", "6-4-2", [0.1, 0.11], curves=sel_curve))
    write_job(s, "random_growth", "6-4-2", results("random_growth", "6-4-2", [0.2, 0.2], curves=rg_curve))
    groups, tops, methods = aggregate(load_jobs(s), ORDER)
    all_rows = time_to_target_rows(groups, tops, methods)
    rows = {r["method"]: r for r in all_rows if r["target_method"] == "conventional"}
    assert rows["conventional"]["target_heldout_curve_rms_nm"] == pytest.approx(0.11)
    assert rows["conventional"]["presentations_to_target"] == 150300
    sel = rows["selective"]
    hit = (sel["reached"], sel["presentations_to_target"], sel["previous_curve_point"])
    assert hit == ("yes", 70560, 40560)
    assert sel["fraction_of_conventional_cost"] == pytest.approx(70560 / 150300)
    assert rows["random_growth"]["reached"] == "not reached"
    # second target: selective's final curve value (0.105), which conventional's curve (ending at 0.11)
    # never reaches
    vs_sel = {r["method"]: r for r in all_rows if r["target_method"] == "selective"}
    assert vs_sel["conventional"]["target_heldout_curve_rms_nm"] == pytest.approx(0.105)
    assert vs_sel["conventional"]["reached"] == "not reached"
    own = vs_sel["selective"]
    assert (own["presentations_to_target"], own["previous_curve_point"]) == (70560, 40560)
    assert vs_sel["random_growth"]["reached"] == "not reached"


def test_runs_lists_failed_missing_diverged_and_files_written(sweep, tmp_path, capsys):
    out = tmp_path / "rep"
    assert main([str(sweep), "--out", str(out)]) == 0
    md = capsys.readouterr().out
    for f in ("report.md", "table1.csv", "verdict.csv", "time_to_target.csv", "runs.csv", "curves.png", "cost.png"):
        assert (out / f).stat().st_size > 0, f
    assert (out / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert md == (out / "report.md").read_text()
    runs = {(r["schedule"], r["topology"], r["job"]): r for r in csv.DictReader((out / "runs.csv").open())}
    assert runs[("matched", "6-4-2", "schedule=matched,topology=6-4-2")]["status"] == "failed"
    assert "boom" in runs[("matched", "6-4-2", "schedule=matched,topology=6-4-2")]["error"]
    assert runs[("conventional", "6-8-2", "schedule=conventional,topology=6-8-2")]["status"] == "missing"
    sel = runs[("selective", "6-8-2", "schedule=selective,topology=6-8-2")]
    assert sel["replicas"] == "4/5 (1 diverged)" and "seed 1 diverged" in sel["error"]
    # grid cells with no folder at all are listed too
    assert runs[("random_growth", "6-8-2", "(no folder)")]["status"] == "missing"
    assert "| failed |" in md and "| missing |" in md and "4/5 (1 diverged)" in md
    assert "0.0554" in md and "150,300t (printed 1,50,000t)" in md and "70,560t" in md
    t1 = list(csv.DictReader((out / "table1.csv").open()))
    assert {(r["method"], r["topology"]) for r in t1} >= {("selective", "6-4-2"), ("matched", "6-8-2")}
    assert "curves.png" in md


@pytest.mark.parametrize(
    "swept, listed",
    [
        ({"schedule": "selective,conventional,matched,random_growth", "topology": "6-4-2,6-8-2"}, True),
        ({"design/arm": "puma560,two_link", "data.n": "1000,10000", "schedule": "conventional,selective"}, True),
        ({"design": "a,b,c"}, False),  # design points: each its own topology and schedule, no grid
        ({"design/modern": "glob(*)", "seed": "0,1000"}, False),  # design points in seed blocks (experiment=modern)
        ({"schedule": "selective,matched", "topology": "6-4-2,6-8-2", "seed": "0,1000"}, True),
    ],
)
def test_cells_with_no_folder_are_listed_only_for_a_sweep_that_crossed_them(sweep, swept, listed):
    """The sweep's multirun.yaml says whether topology x schedule is a grid (as Hydra writes it: the sweeper's
    params; command-line lists count too)."""
    from omegaconf import OmegaConf

    from selpres.report.sections.runs import runs_rows

    OmegaConf.save({"hydra": {"sweeper": {"params": swept}, "overrides": {"task": []}}}, sweep / "multirun.yaml")
    ctx = Context.load(sweep)
    rows = runs_rows(ctx.jobs, ctx.groups, ctx.topologies, ctx.methods, sweep)
    assert any(r["job"] == "(no folder)" for r in rows) == listed
    OmegaConf.save({"hydra": {"overrides": {"task": ["schedule=selective,matched", "topology=6-4-2,6-8-2", "seed=0"]}}},
                   sweep / "multirun.yaml")  # fmt: skip
    rows = runs_rows(ctx.jobs, ctx.groups, ctx.topologies, ctx.methods, sweep)
    assert any(r["job"] == "(no folder)" for r in rows)


def test_default_out_dir(sweep, capsys):
    assert main([str(sweep)]) == 0
    assert (sweep / "report" / "report.md").exists()
    assert sweep / "report" not in job_folders(sweep)  # a second report does not take it for a job


def test_cli_missing_or_empty_dir_exits_2(tmp_path, capsys):
    assert main([str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and err.count("\n") == 1 and "Traceback" not in err
    (tmp_path / "empty").mkdir()
    assert main([str(tmp_path / "empty")]) == 2
    assert "no job folders" in capsys.readouterr().err


def test_cli_as_module_exit_code(tmp_path):
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    p = subprocess.run(
        [sys.executable, "-m", "selpres.report", str(tmp_path / "nope")], cwd=root, capture_output=True, text=True
    )
    assert p.returncode == 2 and "Traceback" not in p.stderr and p.stderr.startswith("error:")


def test_jobs_of_one_schedule_name_that_differ_become_separate_methods(tmp_path):
    s = tmp_path / "sw"
    for topology in ("6-4-2", "6-8-2"):
        for sizes in ([50, 1002], [100, 1002]):
            res = results("selective", topology, [0.1, 0.2])
            res["config"] = {
                "schedule": {"name": "selective", "sizes": sizes},
                "topology": {"layers": topology},
                "optim": {"lr": 0.15},
                "seed": 0,
                "replicas": 2,
            }
            d = write_job(s, "selective", topology, res)
            d.rename(d.with_name(d.name + f",sizes={sizes[0]}"))
    groups, tops, methods = aggregate(load_jobs(s), ORDER)
    assert methods == ["selective schedule.sizes=[100,1002]", "selective schedule.sizes=[50,1002]"]
    assert tops == ["6-4-2", "6-8-2"]  # topology alone never splits a method
    assert all(len(g.by_seed) == 2 for g in groups.values())  # nothing pooled across the two size lists
    rows = verdict_rows(groups, tops, methods, "selective")  # only selective variants: each compared with the first
    expected = "selective schedule.sizes=[50,1002] vs selective schedule.sizes=[100,1002]"
    assert {r["comparison"] for r in rows} == {expected}


def test_an_optimizers_own_parameters_are_left_out_of_other_optimizers_labels(tmp_path):
    """optim.mu exists only in QuickProp's config: SGD's label must not say "optim.mu=None"."""
    s = tmp_path / "sw"
    sgd = {"name": "paper", "lr": 0.15, "momentum": 0.9}
    for optim in (sgd, {"name": "quickprop", "lr": 0.001, "mu": 1.75}):
        res = results("conventional", "6-4-2", [0.1, 0.2])
        res["config"] = {"schedule": {"name": "conventional"}, "optim": optim}
        d = write_job(s, "conventional", "6-4-2", res)
        d.rename(d.with_name(d.name + f",optim={optim['name']}"))
    _, _, methods = aggregate(load_jobs(s), ORDER)
    assert methods == [  # results written before optim._target_ named the optimizer optim.name
        "conventional optim._target_=paper optim.lr=0.15 optim.momentum=0.9",
        "conventional optim._target_=quickprop optim.lr=0.001 optim.mu=1.75",
    ]


def test_jobs_pool_by_seed_union(tmp_path):
    """replicas=2 then replicas=4 of the same method: seeds 0..3 once each, the shared seeds agreeing."""
    s = tmp_path / "sw"
    d = write_job(s, "selective", "6-4-2", results("selective", "6-4-2", [0.1, 0.2]))
    d.rename(d.with_name("a_" + d.name))
    d = write_job(s, "selective", "6-4-2", results("selective", "6-4-2", [0.1, 0.2, 0.3, 0.4]))
    d.rename(d.with_name("b_" + d.name))
    groups, _, _ = aggregate(load_jobs(s), ORDER)
    g = groups[("6-4-2", "selective")]
    assert sorted(g.values("heldout").items()) == [(0, 0.1), (1, 0.2), (2, 0.3), (3, 0.4)]
    assert g.warnings == []
    d = write_job(s, "selective", "6-4-2", results("selective", "6-4-2", [0.9]))  # seed 0, other numbers
    d.rename(d.with_name("c_" + d.name))
    g = aggregate(load_jobs(s), ORDER)[0][("6-4-2", "selective")]
    assert g.values("heldout")[0] == 0.1 and any("seed 0 disagrees" in w for w in g.warnings)


def test_flatten_joins_nested_keys_and_keeps_leaves():
    """The one flattening helper serves the report's method labels (".") and TensorBoard hparams ("/")."""
    from selpres.storage import flatten

    cfg = {
        "schedule": {"sizes": [50, 1002], "budget": None},
        "optim": {"lr": 0.15, "inner": {"x": 1}},
        "seed": 0,
        "empty": {},
    }
    assert flatten(cfg) == {
        "schedule.sizes": [50, 1002],
        "schedule.budget": None,
        "optim.lr": 0.15,
        "optim.inner.x": 1,
        "seed": 0,
    }
    assert flatten(cfg, "/")["optim/inner/x"] == 1


def test_paper_setting_names_what_matched_and_random_growth_borrow(sweep):
    """Matched and random growth are not in the paper: the row says whose setting they borrow, never "yes"."""
    s = sweep.parent / "sw2"
    write_job(s, "matched", "6-4-2", results("matched", "6-4-2", CON))
    groups, tops, methods = aggregate(load_jobs(sweep) + load_jobs(s), ORDER)
    t1 = {(r["method"], r["topology"]): r for r in table1_rows(groups, tops, methods)}
    assert t1[("conventional", "6-4-2")]["paper_setting"] == "yes"
    assert t1[("selective", "6-4-2")]["paper_setting"] == "yes"
    rg_setting = t1[("random_growth", "6-4-2")]["paper_setting"]
    assert rg_setting == "not in paper (selective's stages, random order)"
    assert t1[("matched", "6-4-2")]["paper_setting"] == "not in paper (selective's budget)"
    other = results("matched", "6-4-2", CON)
    other["schedule"]["presentations"] = 50_000
    assert paper_setting("matched", other["schedule"]) == "not in paper (budget 50,000t, not selective's)"
    rg = results("random_growth", "6-4-2", RG)["schedule"]
    rg["sizes"] = [100, 1002]
    assert paper_setting("random_growth", rg) == "not in paper (random order, other stages than selective's)"


def test_timing_names_the_engine_that_ran_and_the_fallback(tmp_path, capsys):
    """A run that asked for "fast" and fell back to torch is timed as torch, with the reason; results
    written before the fallback was recorded carry only "engine", which then stands for both."""
    s = tmp_path / "sw"
    fell = results("selective", "6-4-2", SEL)
    fell.update(engine="torch", engine_requested="fast", engine_fallback="no AVX2 on this CPU")
    write_job(s, "selective", "6-4-2", fell)
    native = results("conventional", "6-4-2", CON)
    native.update(engine="native", engine_requested="fast", engine_fallback=None)
    write_job(s, "conventional", "6-4-2", native)
    write_job(s, "conventional", "6-8-2", results("conventional", "6-8-2", CON))  # old format: "fast" only
    out = tmp_path / "rep"
    assert main([str(s), "--out", str(out)]) == 0
    md = capsys.readouterr().out
    runs = {
        (r["schedule"], r["topology"]): [r[k] for k in ("engine", "engine_requested", "engine_fallback")]
        for r in csv.DictReader((out / "runs.csv").open())
    }
    assert runs[("selective", "6-4-2")] == ["torch", "fast", "no AVX2 on this CPU"]
    assert runs[("conventional", "6-4-2")] == ["native", "fast", ""]
    assert runs[("conventional", "6-8-2")] == ["fast", "fast", ""]
    t1 = {(r["method"], r["topology"]): r for r in csv.DictReader((out / "table1.csv").open())}
    assert t1[("selective", "6-4-2")]["engine"] == "torch"
    assert t1[("selective", "6-4-2")]["engine_fallback"] == "no AVX2 on this CPU"
    (wall,) = [line for line in md.splitlines() if line.startswith("| wall s per replica-run")]
    assert "engine that ran" in wall
    cells = wall.split(" | ")
    assert cells[1].endswith(" native") and cells[2].endswith(" fast")  # conventional 6-4-2, 6-8-2
    assert cells[3].endswith(" torch (fast requested: no AVX2 on this CPU)")  # selective 6-4-2
    assert "engine fallback: no AVX2 on this CPU" in md  # the runs table's notes


README_TEXT = """# A project

Some text the generator must keep.

<!-- table1:begin -->
stale numbers: 0.9999
<!-- table1:end -->

## Tour
kept too
"""


def test_readme_block_is_generated_from_the_report(sweep, tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text(README_TEXT)
    out = tmp_path / "rep"
    assert main([str(sweep), "--out", str(out), "--readme", str(readme)]) == 0
    text = readme.read_text()
    before, rest = text.split("<!-- table1:begin -->\n")
    block, after = rest.split("<!-- table1:end -->")
    assert before == README_TEXT.split("<!-- table1:begin -->")[0]  # outside the markers: untouched
    assert after == README_TEXT.split("<!-- table1:end -->")[1]
    assert "0.9999" not in block
    # the numbers table: mean [95 % interval] of the final held-out RMS, as in the report's table1.csv
    t1 = {(r["method"], r["topology"]): r for r in csv.DictReader((out / "table1.csv").open())}
    sel = t1[("selective", "6-4-2")]
    assert float(sel["heldout_nm_mean"]) == pytest.approx(sum(SEL) / 5)
    cell = (
        f"{float(sel['heldout_nm_mean']):.4f} [{float(sel['heldout_nm_ci_lo']):.4f}, "
        f"{float(sel['heldout_nm_ci_hi']):.4f}]"
    )
    (row,) = [line for line in block.splitlines() if line.startswith("| 6-4-2 |")]
    assert cell in row and "0.0554 / 0.0581" in row  # ours, and the paper's conv. / sel.
    assert "| topology | conventional, 150,300 t | selective, 70,560 t |" in block
    assert "seeds 0–4" in block
    # the findings are the verdicts' own readings
    verdict = {(r["topology"], r["comparison"]): r for r in csv.DictReader((out / "verdict.csv").open())}
    reading_con = verdict[("6-4-2", "selective vs conventional")]["reading_heldout"]
    assert reading_con.startswith("selective better by 0.0440 Nm")
    assert f"6-4-2: {reading_con}" in block
    assert "ratio 0.469" in block
    # a second run with the same results leaves the file exactly as it is
    capsys.readouterr()
    assert main([str(sweep), "--out", str(out), "--readme", str(readme)]) == 0
    assert readme.read_text() == text
    assert "already up to date" in capsys.readouterr().err


@pytest.mark.parametrize(
    "content",
    [
        "# no markers at all\n",
        "<!-- table1:begin -->\nonly the first marker\n",
        "<!-- table1:end -->\nreversed\n<!-- table1:begin -->\n",
        "<!-- table1:begin -->\n<!-- table1:end -->\n<!-- table1:begin -->\n<!-- table1:end -->\n",
    ],
)
def test_readme_without_one_marker_pair_is_refused_untouched(sweep, tmp_path, capsys, content):
    readme = tmp_path / "README.md"
    readme.write_bytes(content.encode())
    out = tmp_path / "rep"
    assert main([str(sweep), "--out", str(out), "--readme", str(readme)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and str(readme) in err and "<!-- table1:begin -->" in err
    assert "Traceback" not in err
    assert readme.read_bytes() == content.encode()
    assert not out.exists()  # refused before anything was written
    assert main([str(sweep), "--out", str(out), "--readme", str(tmp_path / "nope.md")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_engine_text_keeps_the_first_line_of_a_compiler_message():
    from selpres.report.markdown import engine_text

    msg = "cc: error: unrecognized option '-mavx2' " + "x" * 80 + "\nsecond line"
    r = {"engine": "torch", "engine_requested": "fast", "engine_fallback": msg}
    assert engine_text(r, 20) == "torch (fast requested: cc: error: unrecogni…)"
    assert engine_text(r, 0) == "torch (fast requested)"
    assert engine_text({"engine": "native", "engine_requested": "fast", "engine_fallback": None}) == "native"
