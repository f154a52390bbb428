"""The sensitivity section on synthetic sweeps whose statistics are worked out by hand: families, best /
median / worst, worst ÷ best, within 10 %, worst − best paired, time to target, and the verdict's reading."""

from __future__ import annotations

import math

import pytest
from test_report import PAPER_SGD, results, write_job, write_setting

from selpres.report import aggregate, load_jobs
from selpres.report.build import Report
from selpres_studies._error_cost import grid, plane_rows
from selpres_studies._families import families, family_name, paper_conventional
from selpres_studies._sensitivity import sensitivity_rows
from selpres_studies.sensitivity import verdict_text

T = "6-4-2"
# selective presentation, three stage-size lists (n_1 = 50, 100, 200; N_i = 30): 31,560 / 33,060 / 36,060 t
S1, S2, S3 = [0.10, 0.12, 0.11, 0.11], [0.12, 0.12, 0.13, 0.11], [0.13, 0.14, 0.12, 0.13]  # means .11 .12 .13
# conventional SGD at 150,300 t over lr × momentum; lr 0.3 with momentum 0.8 diverges on every seed
C_PAPER, C_M8, C_LR3 = [0.09, 0.10, 0.10, 0.11], [0.10, 0.11, 0.10, 0.11], [0.12] * 4  # .10 .105 .12
CON_CURVE = [(30060, [0.3] * 4), (90180, [0.2] * 4), (150300, [0.1] * 4)]  # target: 0.1


def sgd(lr, momentum):
    return {**PAPER_SGD, "lr": lr, "momentum": momentum}


@pytest.fixture
def sweep(tmp_path):
    s = tmp_path / "sens"
    curves = {
        50: [(1500, [0.5] * 4), (31560, [0.1] * 4)],  # reaches 0.1 at its last point
        100: [(3000, [0.5] * 4), (33060, [0.2] * 4)],  # never
        200: [(6000, [0.3] * 4), (20000, [0.099] * 4), (36060, [0.08] * 4)],
    }  # at 20,000
    for n1, vals in ((50, S1), (100, S2), (200, S3)):
        write_setting(s, f"sel{n1}", "selective", T, vals, [n1, 1002], [30, 30], curves=curves[n1])
    grid = {(0.15, 0.9): C_PAPER, (0.15, 0.8): C_M8, (0.3, 0.9): C_LR3, (0.3, 0.8): C_LR3}
    for (lr, m), vals in grid.items():
        write_setting(
            s,
            f"con{lr}_{m}",
            "conventional",
            T,
            vals,
            [1002],
            [150],
            optim=sgd(lr, m),
            curves=CON_CURVE,
            diverged=(0, 1, 2, 3) if (lr, m) == (0.3, 0.8) else (),
        )
    return s


def rows_of(sweep):
    groups, tops, _ = aggregate(load_jobs(sweep))
    return {r["family"]: r for r in sensitivity_rows(groups, tops)}


def test_family_statistics_by_hand(sweep):
    rows = rows_of(sweep)
    assert set(rows) == {"selective presentation", "conventional SGD at 150,300 t"}
    sel = rows["selective presentation"]
    assert sel["settings"] == 3 and sel["swept"] == "schedule.sizes ∈ {[50,1002], [100,1002], [200,1002]}"
    assert (sel["presentations_min"], sel["presentations_max"]) == (31560, 36060)
    assert sel["best_heldout_nm"] == pytest.approx(0.11) and sel["best_setting"] == "schedule.sizes=[50,1002]"
    assert sel["median_heldout_nm"] == pytest.approx(0.12)
    assert sel["worst_heldout_nm"] == pytest.approx(0.13)
    assert sel["worst_setting"] == "schedule.sizes=[200,1002]"
    assert sel["worst_over_best"] == pytest.approx(13 / 11)
    assert (sel["within_10pct"], sel["within_10pct_fraction"]) == (2, pytest.approx(2 / 3))  # .11, .12 ≤ .121
    # worst − best by seed: .03 .02 .01 .02 → mean .02, sd √(2e-4 / 3), t(0.975, 3) = 3.182446
    half = 3.182446 * math.sqrt(2e-4 / 3) / 2
    assert sel["worst_minus_best_nm"] == pytest.approx(0.02)
    assert [sel["worst_minus_best_ci_lo"], sel["worst_minus_best_ci_hi"]] == pytest.approx(
        [0.02 - half, 0.02 + half], abs=1e-6
    )
    # time to conventional's final curve RMS 0.1: 31,560 / never / 20,000 → fastest 20,000, median 31,560
    assert sel["target_heldout_curve_rms_nm"] == pytest.approx(0.1)
    assert sel["target_method"] == "conventional optim.lr=0.15 optim.momentum=0.9"
    assert (sel["reach_settings"], sel["presentations_to_target_fastest"], sel["presentations_to_target_median"]) == (
        2,
        20000,
        31560,
    )


def test_a_setting_that_never_finished_is_infinitely_bad(sweep):
    con = rows_of(sweep)["conventional SGD at 150,300 t"]
    assert con["swept"] == "optim.lr ∈ {0.15, 0.3}; optim.momentum ∈ {0.8, 0.9}"
    assert con["best_heldout_nm"] == pytest.approx(0.10)
    assert con["best_setting"] == "optim.lr=0.15 optim.momentum=0.9"
    assert con["worst_heldout_nm"] == math.inf and con["worst_setting"] == "optim.lr=0.3 optim.momentum=0.8"
    assert con["worst_over_best"] == math.inf
    assert con["median_heldout_nm"] == pytest.approx((0.105 + 0.12) / 2)  # of .10, .105, .12, ∞
    assert (con["within_10pct"], con["within_10pct_fraction"]) == (2, 0.5)  # .10 and .105 ≤ .11
    assert (con["diverged_settings"], con["diverged_replicas"]) == (1, 4)
    assert con["worst_minus_best_pairs"] == 0 and con["worst_minus_best_ci_lo"] is None
    # each finished conventional curve ends at 0.1 = the target, reached at 150,300; the diverged has none
    assert (con["reach_settings"], con["presentations_to_target_fastest"]) == (3, 150300)
    assert con["presentations_to_target_median"] == 150300  # of 150,300 ×3 and never


def test_verdict_reads_consistent_mixed_and_not_supported(sweep, tmp_path):
    rows = list(rows_of(sweep).values())
    text = verdict_text(rows, T)
    assert (
        "compared with the rival that reaches the best level at its cost, the sentence holds: selective "
        "presentation is at least as insensitive by both measures"
    ) in text
    assert "Selective presentation varies by worst ÷ best 1.182, with 2/3 (67 %) of its settings" in text
    assert "against conventional SGD at 150,300 t ∞ with 2/4 (50 %)." in text
    assert "1 of 2 families (selective presentation)" in text  # conventional's pair count is 0
    # a rival with a flatter response: QuickProp over lr × mu, means .100 .101 .102 .103 (ratio 1.03, 100 %)
    for k, (lr, mu) in enumerate([(0.001, 1.5), (0.001, 1.75), (0.002, 1.5), (0.002, 1.75)]):
        write_setting(
            sweep,
            f"qp{k}",
            "conventional",
            T,
            [0.1 + k / 1000] * 4,
            [1002],
            [150],
            optim={"name": "quickprop", "lr": lr, "mu": mu},
        )
    rows = list(rows_of(sweep).values())
    qp = next(r for r in rows if r["family"] == "quickprop at 150,300 t")
    assert qp["worst_over_best"] == pytest.approx(0.103 / 0.100) and qp["within_10pct_fraction"] == 1.0
    assert qp["swept"] == "optim.lr ∈ {0.001, 0.002}; optim.mu ∈ {1.5, 1.75}"
    assert "the sentence does not hold: by each measure of spread some rival" in verdict_text(rows, T)
    # only the within-10 % measure lost: a quickprop with a wide but mostly flat response (ratio 2, 3/4)
    (sweep / "qp3" / "results.json").unlink()
    (sweep / "qp3").rmdir()
    write_setting(
        sweep, "qp3", "conventional", T, [0.2] * 4, [1002], [150], optim={"name": "quickprop", "lr": 0.002, "mu": 1.75}
    )
    text = verdict_text(list(rows_of(sweep).values()), T)
    assert (
        "the sentence holds only in part: selective presentation is at least as insensitive by worst ÷ "
        "best, not by the share within 10 %"
    ) in text


def test_schedule_alone_rows_hold_the_learning_rate_fixed(tmp_path):
    """sizes × lr: the family spans both; 'at optim.lr=…' rows spread over the sizes alone."""
    s = tmp_path / "sw"
    vals = {(50, 0.1): [0.20] * 2, (100, 0.1): [0.21] * 2, (50, 0.3): [0.10] * 2, (100, 0.3): [0.12] * 2}
    for (n1, lr), v in vals.items():
        write_setting(s, f"s{n1}_{lr}", "selective", T, v, [n1, 1002], [30, 30], optim=sgd(lr, 0.9))
    groups, tops, _ = aggregate(load_jobs(s))
    rows = sensitivity_rows(groups, tops)
    assert [(r["family"], r["kind"]) for r in rows] == [
        ("selective presentation", "family"),
        ("selective presentation at optim.lr=0.1", "at fixed other parameters"),
        ("selective presentation at optim.lr=0.3", "at fixed other parameters"),
    ]
    assert [r["worst_over_best"] for r in rows] == pytest.approx([0.21 / 0.10, 0.21 / 0.20, 0.12 / 0.10])
    assert rows[1]["swept"] == "schedule.sizes ∈ {[50,1002], [100,1002]}"
    text = verdict_text(rows, T)
    assert (
        "With optim.lr held fixed (2 values), selective presentation's spread over the schedule alone "
        "is worst ÷ best 1.050–1.200, with 50–100 % of settings within 10 % of the best."
    ) in text
    assert "no rival family (one-stage training, an optimizer swept over its parameters) has more" in text
    assert "target_heldout_curve_rms_nm" in rows[0] and rows[0]["target_heldout_curve_rms_nm"] is None
    assert "no conventional run" in Report.build(s).markdown  # time to target without a target says so
    # growing the set in another order is an ablation of selective presentation, not a rival speed-up method
    for n1 in (50, 100):
        write_setting(s, f"r{n1}", "random_growth", T, [0.3] * 2, [n1, 1002], [30, 30], order="random")
    groups, tops, _ = aggregate(load_jobs(s))
    rows = sensitivity_rows(groups, tops)
    assert [r["family"] for r in rows if r["kind"] == "family"] == ["selective presentation", "staged, random order"]
    assert "no rival family" in verdict_text(rows, T)


def test_family_names_and_the_paper_conventional_target(tmp_path):
    s = tmp_path / "sw"
    write_setting(s, "a", "random_growth", T, [0.1], [50, 1002], [30, 30], order="random")
    write_setting(s, "b", "matched", T, [0.1], [1002], [70], extra=420)
    write_setting(s, "c", "conventional", T, [0.1], [1002], [150], optim={"name": "adam", "lr": 0.01})
    write_setting(s, "d", "selective", T, [0.1], [50, 1002], [30, 30], optim={"name": "rprop", "lr": 0.1})
    write_setting(s, "e", "conventional", T, [0.1], [1002], [150], optim=sgd(0.3, 0.9))
    groups, tops, _ = aggregate(load_jobs(s))
    names = {g.used[0].path.name: family_name(g) for g in groups.values()}
    assert names == {
        "a": "staged, random order",
        "b": "conventional SGD at 70,560 t",
        "c": "adam at 150,300 t",
        "d": "selective presentation with rprop",
        "e": "conventional SGD at 150,300 t",
    }
    assert all(len(f.members) == 1 for f in families(groups, tops))
    # no run with the paper's lr: the one SGD run of 150 epochs is the target; a second makes it ambiguous
    assert paper_conventional(groups, T).used[0].path.name == "e"
    write_setting(s, "f", "conventional", T, [0.1], [1002], [150], optim=sgd(0.1, 0.9))
    groups, _, _ = aggregate(load_jobs(s))
    assert paper_conventional(groups, T) is None
    write_setting(s, "g", "conventional", T, [0.1], [1002], [150])  # the paper's own: chosen again
    groups, _, _ = aggregate(load_jobs(s))
    assert paper_conventional(groups, T).used[0].path.name == "g"


def test_no_family_with_two_settings_no_section(tmp_path):
    """A Table-1-shaped sweep (one setting per method): no sensitivity section, so its report is as before."""
    s = tmp_path / "t1"
    for name in ("selective", "conventional", "matched", "random_growth"):
        res = results(name, T, [0.1, 0.2])
        res["schedule"]["order"] = "random" if name == "random_growth" else "stratified"
        write_job(s, name, T, res)
    report = Report.build(s)
    assert "Sensitivity" not in report.markdown and "Error–cost" not in report.markdown
    assert all(not ({"sensitivity.csv", "error_cost.csv"} & set(sec.csv)) for sec in report.sections)


def test_sensitivity_csv_written(sweep, tmp_path):
    files = Report.build(sweep).write(tmp_path / "out")
    assert "sensitivity.csv" in files
    text = (tmp_path / "out" / "sensitivity.csv").read_text()
    assert text.splitlines()[0].startswith("kind,family,topology,staged,settings,swept,")
    assert "## Sensitivity" in (tmp_path / "out" / "report.md").read_text()


def test_error_cost_rows_and_figures(sweep, tmp_path):
    groups, tops, _ = aggregate(load_jobs(sweep))
    rows = {r["setting"]: r for r in plane_rows(groups, tops)}
    r = rows["schedule.sizes=[50,1002]"]  # S1 = .10 .12 .11 .11: sd √(2e-4 / 3), t(0.975, 3) = 3.182446
    half = 3.182446 * math.sqrt(2e-4 / 3) / 2
    assert (r["family"], r["presentations"], r["n"]) == ("selective presentation", 31560, 4)
    assert [r["heldout_nm_mean"], r["heldout_nm_ci_lo"], r["heldout_nm_ci_hi"]] == pytest.approx(
        [0.11, 0.11 - half, 0.11 + half], abs=1e-6
    )
    dead = rows["optim.lr=0.3 optim.momentum=0.8"]
    assert (dead["n"], dead["diverged"], dead["heldout_nm_mean"]) == (0, 4, None)
    files = Report.build(sweep).write(tmp_path / "out")
    assert {"error_cost.csv", "error_cost.png", "heatmap_conventional_SGD_at_150_300_t_6-4-2.png"} <= set(files)
    assert "heatmap_selective_presentation_6-4-2.png" not in files  # one swept parameter: no grid
    assert (tmp_path / "out" / "error_cost.png").read_bytes()[:4] == b"\x89PNG"


def test_heat_map_grid_of_three_parameters_by_hand(tmp_path):
    """Delta-bar-delta over κ (3 values) × φ (2) × θ (2), one setting not run: κ and φ are the axes (most
    values; φ before θ by name), θ makes the panels; the cell values are the settings' means."""
    s = tmp_path / "dbd"
    done = {}
    for kappa in (0.001, 0.002, 0.003):
        for phi in (0.5, 0.7):
            for theta in (0.6, 0.7):
                if (kappa, phi, theta) == (0.003, 0.7, 0.7):
                    continue
                v = 0.1 + 10 * kappa + phi / 100 + theta / 1000
                done[(kappa, phi, theta)] = v
                write_setting(
                    s,
                    f"k{kappa}p{phi}t{theta}",
                    "conventional",
                    T,
                    [v - 0.001, v + 0.001],
                    [1002],
                    [150],
                    optim={"name": "delta_bar_delta", "kappa": kappa, "phi": phi, "theta": theta},
                )
    groups, tops, _ = aggregate(load_jobs(s))
    (fam,) = families(groups, tops)
    gr = grid(fam)
    assert (gr.x, gr.y) == ("optim.kappa", "optim.phi")
    assert (gr.xs, gr.ys) == (["0.001", "0.002", "0.003"], ["0.5", "0.7"])
    assert list(gr.panels) == ["optim.theta=0.6", "optim.theta=0.7"]
    for (kappa, phi, theta), v in done.items():
        assert gr.panels[f"optim.theta={theta}"][(str(kappa), str(phi))] == pytest.approx(v)
    assert ("0.003", "0.7") not in gr.panels["optim.theta=0.7"]  # not run: a blank cell


def test_a_loss_based_familys_level_is_taken_at_its_cost_with_the_choosing_charged(tmp_path):
    """loss_high pays forward passes to choose its patterns (selection_presentations); its level must compare it
    with what else ran at that whole cost. Two loss_high settings trained 31,560 / 63,120 t and charged 900 each
    (32,460 / 64,020 in all); conventional runs stopped at exactly those costs (32 epochs + 396, 63 + 894) reach
    0.1 Nm where loss_high reaches 0.4 at best: level 0.4 / 0.1 = 4 (at training presentations alone, nothing else
    ran there and the level read 1)."""
    import json

    s = tmp_path / "sw"

    def charged(folder, charge):
        p = folder / "results.json"
        r = json.loads(p.read_text())
        r["selection_presentations"] = charge
        p.write_text(json.dumps(r))

    charged(write_setting(s, "lh1", "lossy", T, [0.5] * 5, [50, 1002], [30, 30], order="loss_high"), 900)
    charged(write_setting(s, "lh2", "lossy", T, [0.4] * 5, [50, 1002], [60, 60], order="loss_high"), 900)
    write_setting(s, "m1", "matched", T, [0.1] * 5, [1002], [32], extra=396)
    write_setting(s, "m2", "matched", T, [0.1] * 5, [1002], [63], extra=894)
    groups, tops, _ = aggregate(load_jobs(s))
    (lossy,) = [r for r in sensitivity_rows(groups, tops) if "loss_high" in r["family"]]
    assert lossy["level_presentations"] == 64_020 and lossy["level"] == pytest.approx(4.0)
    assert "budget-matched" in lossy["level_reference_family"]
