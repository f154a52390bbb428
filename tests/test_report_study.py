"""The report of a study of parameters shaped like ``experiment=sensitivity``, on a synthetic sweep with
hand-worked numbers: optimizer configs as the optimizer group writes them (``optim._target_: sgd``; and as
results written before it did, ``optim.name: sgd`` with every other optimizer's key null), selective
presentation over p, n_i, N_i and N with a budget-matched conventional partner at each cost, SGD over
lr × momentum at 150,300 t and a Delta-Bar-Delta that is flat but bad everywhere. Each test fails on the
report as it was before these cases were handled."""

from __future__ import annotations

import math

import pytest
from test_report import write_setting

from selpres.report import aggregate, load_jobs
from selpres.report.__main__ import main
from selpres.report.build import Report
from selpres_studies._error_cost import plane_rows
from selpres_studies._families import families, paper_conventional
from selpres_studies._sensitivity import sensitivity_rows
from selpres_studies.sensitivity import verdict_text
from selpres_studies.table1 import time_to_target_rows

T = "6-4-2"
# what configs/optim/*.yaml leave unset for an optimizer that does not use the key
UNSET = {
    k: None
    for k in (
        "mu",
        "weight_decay",
        "kappa",
        "phi",
        "theta",
        "eta_minus",
        "eta_plus",
        "step_min",
        "step_max",
        "beta1",
        "beta2",
        "eps",
    )
}


KEY = "_target_"  # the key naming the optimizer; the study fixture also writes the older spelling, "name"


def sgd(lr=0.15, momentum=0.9):
    return {
        KEY: "sgd",
        "lr": lr,
        "batch_size": 1,
        "momentum": momentum,
        **UNSET,
        "sigmoid_prime_offset": 0.0,
        "reduction": "sum",
    }


def dbd(kappa, phi):
    return {
        KEY: "delta_bar_delta",
        "lr": 0.001,
        "batch_size": 0,
        "momentum": None,
        **UNSET,
        "kappa": kappa,
        "phi": phi,
        "theta": 0.7,
        "sigmoid_prime_offset": 0.0,
        "reduction": "sum",
    }


def flat(mean, n=4):
    """Four seeds around ``mean`` (mean − 0.003, − 0.001, + 0.001, + 0.003): the mean is exact."""
    return [mean - 0.003, mean - 0.001, mean + 0.001, mean + 0.003][:n]


# selective presentation: sizes, epochs, cost, mean; each with a budget-matched partner (1002 × k + r = cost)
SELECTIVE = {
    "sA": ([50, 1002], [75, 75], 78_900, 0.20),  # p 1, N = 150
    "sB": ([50, 224, 1002], [50, 50, 50], 63_800, 0.22),  # p 2, geometric, N = 150
    "sC": ([50, 100, 1002], [10, 20, 120], 122_740, 0.25),  # p 2, N_i increasing, N = 150
    "sN75": ([50, 1002], [37, 38], 39_926, 0.40),  # N = 75
    "sN300": ([50, 1002], [150, 150], 157_800, 0.18),  # N = 300
}
MATCHED = {"sA": 0.21, "sB": 0.25, "sC": 0.20, "sN75": 0.44, "sN300": 0.19}  # conventional at the same cost
SGD_GRID = {(0.15, 0.9): 0.17, (0.15, 0.5): 0.30, (0.5, 0.9): 0.19, (0.5, 0.5): 0.51}  # at 150,300 t
DBD_GRID = {(0.01, 0.2): 1.70, (0.01, 0.5): 1.72, (0.03, 0.2): 1.74, (0.03, 0.5): 1.76}  # flat, 10 × SGD
CON_CURVE = [(30060, [0.5] * 4), (90180, [0.3] * 4), (150300, [0.17] * 4)]  # target: 0.17
N300_CURVE = [(7500, [0.6] * 4), (100000, [0.16] * 4), (157800, [0.15] * 4)]  # reaches 0.17 at 100,000


@pytest.fixture(params=["_target_", "name"])
def study(tmp_path, request, monkeypatch):
    monkeypatch.setitem(globals(), "KEY", request.param)
    s = tmp_path / "study"
    for name, (sizes, epochs, cost, mean) in SELECTIVE.items():
        assert sum(n * e for n, e in zip(sizes, epochs)) == cost
        write_setting(
            s,
            name,
            "selective",
            T,
            flat(mean),
            sizes,
            epochs,
            optim=sgd(),
            curves=N300_CURVE if name == "sN300" else None,
        )
        write_setting(
            s, "m" + name, "matched", T, flat(MATCHED[name]), [1002], [cost // 1002], extra=cost % 1002, optim=sgd()
        )
    for (lr, m), mean in SGD_GRID.items():
        write_setting(
            s,
            f"c{lr}_{m}",
            "conventional",
            T,
            flat(mean),
            [1002],
            [150],
            optim=sgd(lr, m),
            curves=CON_CURVE if (lr, m) == (0.15, 0.9) else None,
        )
    for (kappa, phi), mean in DBD_GRID.items():
        write_setting(s, f"d{kappa}_{phi}", "conventional", T, flat(mean), [1002], [150], optim=dbd(kappa, phi))
    return s


def grouped(study):
    groups, tops, methods = aggregate(load_jobs(study))
    return groups, tops, methods


def by_folder(groups):
    return {g.used[0].path.name: g for g in groups.values()}


def test_the_papers_conventional_run_is_found_under_optim_target_sgd(study):
    groups, _, _ = grouped(study)
    assert paper_conventional(groups, T) is by_folder(groups)["c0.15_0.9"]


def test_labels_name_only_the_keys_that_are_set_and_differ(study):
    _, _, methods = grouped(study)
    assert "conventional optim._target_=sgd optim.batch_size=1 optim.lr=0.15 optim.momentum=0.9" in methods
    assert (
        "conventional optim._target_=delta_bar_delta optim.batch_size=0 optim.kappa=0.01 optim.lr=0.001 "
        "optim.phi=0.2 optim.theta=0.7"
    ) in methods
    assert not [m for m in methods if "null" in m]


def test_budget_matched_runs_are_one_family(study):
    groups, tops, _ = grouped(study)
    sizes = {f.name: len(f.members) for f in families(groups, tops)}
    assert sizes == {
        "selective presentation": 5,
        "conventional SGD, budget-matched": 5,
        "conventional SGD at 150,300 t": 4,
        "delta_bar_delta at 150,300 t": 4,
    }
    fam = next(f for f in families(groups, tops) if f.name.endswith("budget-matched"))
    assert fam.label(by_folder(groups)["msA"]) == "schedule.epochs=[78]"


def test_spread_level_and_the_papers_total_by_hand(study):
    groups, tops, _ = grouped(study)
    rows = {r["family"]: r for r in sensitivity_rows(groups, tops)}
    sel = rows["selective presentation"]
    assert sel["worst_over_best"] == pytest.approx(0.40 / 0.18) and sel["within_10pct"] == 1  # ≤ .198: .18
    # the level: its best (sN300, .18 at 157,800 t) ÷ the best of anything at that cost (itself; m .19)
    assert sel["level"] == pytest.approx(1.0) and sel["level_presentations"] == 157_800
    assert sel["swept_terms"] == (
        "p ∈ {1, 2}; n_i growth ∈ {geometric, one step, other}; N_i profile ∈ "
        "{equal, increasing}; N = ΣN_i ∈ {75, 150, 300}"
    )
    # at the paper's N = 150: sA .20, sB .22, sC .25 → 1.25, with .20 and .22 ≤ .22 within 10 %
    total = rows["selective presentation at ΣN_i = 150"]
    assert (total["kind"], total["settings"]) == ("at the paper's total epochs", 3)
    assert total["worst_over_best"] == pytest.approx(1.25) and total["within_10pct"] == 2
    assert (total["presentations_min"], total["presentations_max"]) == (63_800, 122_740)
    assert total["level"] == pytest.approx(1.0)  # sA .20 against its partner's .21 at 78,900 t
    # budget-matched: .21 .25 .20 .44 .19 → 0.44 / 0.19; level .19 ÷ sN300's .18 at 157,800 t
    matched = rows["conventional SGD, budget-matched"]
    assert matched["worst_over_best"] == pytest.approx(0.44 / 0.19) and matched["within_10pct"] == 2
    assert matched["level"] == pytest.approx(0.19 / 0.18)
    # Delta-Bar-Delta: flat (1.76 / 1.70, all within 10 %) but 10 × the best at 150,300 t
    d = rows["delta_bar_delta at 150,300 t"]
    assert d["worst_over_best"] == pytest.approx(1.76 / 1.70) and d["within_10pct_fraction"] == 1.0
    assert d["level"] == pytest.approx(10.0)
    assert (d["level_reference_family"], d["level_reference_setting"]) == (
        "conventional SGD at 150,300 t",
        "optim.lr=0.15 optim.momentum=0.9",
    )
    con = rows["conventional SGD at 150,300 t"]
    assert con["worst_over_best"] == pytest.approx(3.0) and con["level"] == pytest.approx(1.0)
    # time to the paper's conventional final (0.17): only sN300's curve gets there, at 100,000
    assert sel["target_heldout_curve_rms_nm"] == pytest.approx(0.17)
    assert (sel["reach_settings"], sel["presentations_to_target_fastest"]) == (1, 100000)


def test_each_selective_setting_beside_its_budget_matched_partner(study):
    from selpres_studies._sensitivity import versus_matched_rows

    groups, tops, _ = grouped(study)
    rows = {r["sizes"] + "/" + r["epochs"]: r for r in versus_matched_rows(groups, tops)}
    assert len(rows) == 5
    b = rows["50 224 1002/50 50 50"]
    assert (b["p"], b["growth"], b["profile"], b["total_epochs"], b["presentations"]) == (
        2,
        "geometric",
        "equal",
        150,
        63_800,
    )
    assert b["matched_presentations"] == 63_800 and b["over_matched"] == pytest.approx(0.22 / 0.25)
    assert rows["50 100 1002/10 20 120"]["over_matched"] == pytest.approx(0.25 / 0.20)
    assert [r["total_epochs"] for r in versus_matched_rows(groups, tops)] == [75, 150, 150, 150, 300]


def test_verdict_separates_spread_from_level_and_answers_with_numbers(study):
    from selpres_studies._sensitivity import versus_matched_rows

    groups, tops, _ = grouped(study)
    rows = sensitivity_rows(groups, tops)
    text = verdict_text(rows, T, versus_matched_rows(groups, tops))
    assert "not tested" not in text and "Least sensitive" not in text
    assert (
        "compared with the rival that reaches the best level at its cost, the sentence holds: selective "
        "presentation is at least as insensitive by both measures"
    ) in text
    assert (
        "Selective presentation at the paper's N = ΣN_i = 150 (over p, n_i and the N_i profile) varies "
        "by worst ÷ best 1.250, with 2/3 (67 %) of its settings within 10 % of its best, against "
        "conventional SGD at 150,300 t 3.000 with 1/4 (25 %)."
    ) in text
    # the flat rival is set aside for its level, with its numbers
    assert "The other 1 rival family never gets within 1.1 × of the best at its cost (best 10.00 × it)" in text
    assert "delta_bar_delta at 150,300 t: 10.00" in text
    assert "delta_bar_delta at 150,300 t has worst ÷ best 1.035, but even its best is 10.00 ×" in text
    # cost: .20/.21 .22/.25 .25/.20 .40/.44 .18/.19 → 0.880–1.250, four of five lower
    assert "each of its settings has 0.880–1.250 × conventional's error (4 of 5 lower" in text
    assert "selective presentation spreads 2.222 against 1.250 at the paper's N" in text


def test_a_studys_report_leads_with_its_sections_and_stays_short(study, tmp_path, capsys):
    # folders gathered by hand name no study: the studies that apply lead, by name (selection, sensitivity with
    # its error-cost plane)
    heads = [line for line in Report.build(study).markdown.splitlines() if line.startswith("## ")]
    assert [h.split(":")[0].split(" ")[1] for h in heads[:3]] == ["Selection", "Sensitivity", "Error–cost"]
    # the sweep as Hydra runs it records its experiment: that study leads
    (study / "multirun.yaml").write_text("hydra:\n  runtime:\n    choices:\n      experiment: sensitivity\n")
    md = Report.build(study).markdown
    heads = [line for line in md.splitlines() if line.startswith("## ")]
    assert md.startswith("# Sweep report:")
    assert heads[0].startswith("## Sensitivity") and heads[1].startswith("## Error–cost plane")
    assert heads[2].startswith("## Selection verdict")
    assert heads[-3:][0].startswith("## Table 1") and heads[-1] == "## Runs"
    assert "| Table 1 |" not in md and "Not computed: this sweep is a study of parameters" in md
    assert "The verdict on 6-4-2 depends on these ranges" in md
    assert len(md.splitlines()) < 120
    # time to target against the paper's conventional run, found by its settings, not by its label
    assert "no target" not in md
    groups, tops, methods = grouped(study)
    rows = [
        r
        for r in time_to_target_rows(groups, tops, methods)
        if r["target_method"] == paper_conventional(groups, T).schedule
    ]
    hit = [r for r in rows if r.get("reached") == "yes" and r["method"].startswith("selective")]
    assert [r["presentations_to_target"] for r in hit] == [100000]
    assert hit[0]["fraction_of_conventional_cost"] == pytest.approx(100000 / 150300)
    # a study has no Table 1 block for the README: refused, nothing written
    readme = tmp_path / "README.md"
    readme.write_text("<!-- table1:begin -->\n<!-- table1:end -->\n")
    assert main([str(study), "--out", str(tmp_path / "out"), "--readme", str(readme)]) == 2
    err = capsys.readouterr().err
    assert "no study of the report" in err and "writes a README block" in err and not (tmp_path / "out").exists()


def test_error_cost_plane_one_entry_per_family_legend_outside_frontier_drawn(study):
    from selpres_studies._error_cost import draw_plane

    groups, tops, _ = grouped(study)
    fams = families(groups, tops)
    fig = draw_plane(plane_rows(groups, tops, fams), groups, tops, fams)
    (ax,) = fig.axes
    assert ax.get_legend() is None and len(fig.legends) == 1
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels[0].startswith("frontier: the paper's conventional run")
    assert labels[1:] == [
        "selective presentation (5)",
        "conventional SGD, budget-matched (5)",
        "conventional SGD at 150,300 t (4)",
        "delta_bar_delta at 150,300 t (4)",
    ]
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    assert fig.legends[0].get_window_extent(renderer).x0 >= ax.get_window_extent(renderer).x1
    (frontier,) = [line for line in ax.get_lines() if list(line.get_xdata()) == [30060, 90180, 150300]]
    assert list(frontier.get_ydata()) == pytest.approx([0.5, 0.3, 0.17])
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_family_styles_are_distinct():
    from selpres.report.sections.plots import family_styles

    names = [f"f{i}" for i in range(132)]
    styles = family_styles(names)
    assert len(set(styles.values())) == 132  # colour and marker together tell every family apart
    assert len({c for c, _ in list(styles.values())[:12]}) == 12  # the first twelve by colour alone
    assert all(
        styles[a] != styles[b] and styles[a][0] != styles[b][0] and styles[a][1] != styles[b][1]
        for a, b in zip(names, names[1:])
    )  # neighbours differ in both


def test_a_family_with_no_finished_setting_has_an_infinite_level(study):
    for k, lr in enumerate((0.1, 1.0)):
        write_setting(
            study,
            f"rp{k}",
            "conventional",
            T,
            [0.1] * 4,
            [1002],
            [150],
            optim={**sgd(), KEY: "rprop", "momentum": None, "lr": lr},
            diverged=(0, 1, 2, 3),
        )
    groups, tops, _ = grouped(study)
    rp = {r["family"]: r for r in sensitivity_rows(groups, tops)}["rprop at 150,300 t"]
    assert rp["level"] == math.inf and rp["best_heldout_nm"] == math.inf
    assert "rprop at 150,300 t: ∞" in verdict_text(sensitivity_rows(groups, tops), T)


def test_a_one_factor_at_a_time_design_gets_no_heat_map(study, tmp_path):
    """Selective presentation's 5 settings over 3 size lists × 5 epoch lists fill 5 of 15 cells: no map; SGD's
    full 2 × 2 grid gets one."""
    from selpres_studies._error_cost import grid

    groups, tops, _ = grouped(study)
    fams = {f.name: f for f in families(groups, tops)}
    assert grid(fams["selective presentation"]) is None
    sgd_grid = grid(fams["conventional SGD at 150,300 t"])
    assert (sgd_grid.x, sgd_grid.y) == ("optim.lr", "optim.momentum")
    assert (sgd_grid.xs, sgd_grid.ys) == (["0.15", "0.5"], ["0.5", "0.9"])
    files = Report.build(study).write(tmp_path / "out")
    assert "heatmap_conventional_SGD_at_150_300_t_6-4-2.png" in files
    assert not [f for f in files if f.startswith("heatmap_selective")]
