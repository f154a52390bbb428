"""Table 1 of the paper (``experiment=table1``): its grid of methods × topologies in the paper's layout, the
paper's numbers beside ours; the verdicts of the reference method against every other; time to target; the curves
against cost with the paper's values as unit-free ratios (``_table1_plots``); and the README's Table 1 block
(``--readme``).

What it compares is what the jobs recorded (results.json: schedule.name); the roles (the *reference*, compared
with every other method, and the *baseline*, whose cost the others' are fractions of), the rows' order and the
paper's numbers are the design's (``table1.yaml``, read by ``_paper``). The paper's runs are found by their
settings (``_families.paper_run``), whatever their labels. On a sweep that is not its grid (a study of parameters,
whose methods are labelled by the settings they sweep) the same blocks come compact, after the sections the study
is about: time to target against the paper's runs, their curves and each family's best, Table 1's columns in
table1.csv only, and a note saying where the comparisons are.

``experiment=large`` has nothing of its own: one n's folder is Table 1's grid on its arms (the paper's numbers
only where a topology is the paper's), the whole sweep is the selection study's (more than one budget).
"""

from __future__ import annotations

from selpres.report import (
    SETS,
    UNITS,
    Context,
    Group,
    Report,
    Section,
    built,
    ci,
    comparisons,
    engine_text,
    fmt,
    mean_std,
    summarize,
    table,
    time_to_target,
    verdict,
)
from selpres.report import time_to_target_rows as rows_to_targets
from selpres_studies import _table1_plots
from selpres_studies._families import SELECTIVE, families, paper_conventional, paper_run
from selpres_studies._paper import DESIGN, paper_setting

PAPER = DESIGN.published
ORDER = DESIGN.order  # the order of the methods' rows, in every section of a sweep this study leads
HEADING = "Table 1 reproduction"


def is_grid(ctx: Context) -> bool:
    """Whether the sweep is Table 1's grid: the paper's methods (with those that borrow from them), one setting
    each per topology. A sweep that labels its methods by swept settings (a study of parameters) is not, and its
    report leads with the sections it is about."""
    return any(m in PAPER for m in ctx.methods) and all(" " not in m for m in ctx.methods)


def _methods(ctx: Context) -> list[str]:
    return DESIGN.methods(ctx.methods)


FOOTNOTE = (
    "¹ The paper's RMS error is over 10 test patterns with units unstated; it is shown next to both of our "
    "metrics (Nm and scaled). Ours: mean ± sample std over complete seeds, and the Student-t 95 % interval "
    "of the mean. *test-10* = the paper's 10-pattern metric, *held-out* = all held-out patterns. Wall time "
    "per replica-run = the job's training seconds ÷ its replicas (replicas are trained together, batched), "
    "measured with the engine named after it (and the one requested, when the run fell back). "
    "Diverged replicas (and any whose final score is not finite) are excluded from means and counted under "
    "*replicas complete*.\n\n"
    "² nMSE = held-out MSE ÷ the variance of the held-out torques, the mean over joints (the inverse-dynamics "
    "literature's metric; 1 = no better than a constant); the mean predictor's RMS is the error of always "
    "predicting the exemplar set's mean torque, the task's floor."
)


def replicas_text(g: Group) -> str:
    """complete/all, and why the others are not: diverged, or a final score that is not finite (report.validate)."""
    n, bad = len(g.by_seed), [r["status"] for r in g.by_seed.values() if r["status"] != "complete"]
    why = ", ".join(f"{bad.count(k)} {k}" for k in dict.fromkeys(bad))
    return f"{n - len(bad)}/{n}" + (f" ({why})" if bad else "")


def table1_rows(groups, topologies, methods) -> list[dict]:
    """One row per (method, topology): schedule, cost, wall time, paper RMS and our RMS statistics."""
    rows = []
    for m in methods:
        for t in topologies:
            g = groups.get((t, m))
            row = {"method": m, "topology": t}
            if g is None or g.sched is None:
                row["replicas"] = "no results"
                rows.append(row)
                continue
            s, w = g.sched, g.wall()
            row.update(
                p=s["p"],
                sizes=" ".join(map(str, s["sizes"])),
                epochs=" ".join(map(str, s["epochs"])),
                extra_presentations=sum(s.get("extra_presentations") or [0]),
                presentations=s["presentations"],
                paper_presentations=PAPER.get(m, {}).get("presentations"),
                cost_ratio_vs_equal_epochs=s["cost_ratio"],
                paper_setting=paper_setting(g.schedule, s),
                replicas=replicas_text(g),
                n_complete=len(g.complete_seeds),
                n_diverged=g.n_diverged,
                **g.engines(),
                wall_train_per_replica_s=w["per_replica"],
                wall_train_job_s=w["train"],
                wall_total_job_s=w["total"],
                paper_rms=PAPER.get(m, {}).get("rms", {}).get(t),
            )
            for set_, _ in SETS:
                for unit, _ in UNITS:
                    st = summarize(g.values(set_, unit).values())
                    k = f"{set_}_{unit}"
                    row.update(
                        {
                            f"{k}_n": st["n"],
                            f"{k}_mean": st["mean"],
                            f"{k}_std": st["std"],
                            f"{k}_ci_lo": st["ci95"][0],
                            f"{k}_ci_hi": st["ci95"][1],
                        }
                    )
            st = summarize(g.values("heldout", "nmse").values())  # selpres.run.floor: MSE ÷ target variance
            floor = (g.used[0].results.get("floor") or {}).get("heldout", {}).get("nm", {}).get("overall")
            row.update(heldout_nmse_mean=st["mean"], heldout_nmse_std=st["std"], heldout_floor_nm=floor)
            rows.append(row)
    return rows


def stat_of(row: dict, k: str) -> dict:
    """The summarize()-shaped statistics of column group ``k`` (e.g. "heldout_nm") of a Table 1 row."""
    return {
        "mean": row.get(f"{k}_mean"),
        "std": row.get(f"{k}_std"),
        "ci95": [row.get(f"{k}_ci_lo"), row.get(f"{k}_ci_hi")],
    }


def _paper_time(r: dict) -> str:
    """The paper's total time T for the column's method, and how it printed it where that differs."""
    paper = PAPER.get(r["method"])
    if not paper:
        return "not in paper"
    ours = f"{paper['presentations']:,}t"
    return ours + (f" (printed {paper['printed']})" if paper["printed"] != ours else "")


def _epochs(r: dict) -> str:
    return r["epochs"] + (f" (+{r['extra_presentations']} presentations)" if r["extra_presentations"] else "")


def _wall(r: dict) -> str:
    job = f"{r['wall_train_job_s']:.3g} / {r['wall_total_job_s']:.3g}"
    return f"{r['wall_train_per_replica_s']:.3g} ({job}) {engine_text(r)}"


def _rms_cells() -> list[tuple]:
    """(label, cell) for our RMS rows: each set and unit, mean ± std then the 95 % interval."""
    return [
        (f"{sname} RMS {uname}, {what}", lambda r, k=f"{set_}_{unit}", show=show: show(stat_of(r, k)))
        for set_, sname in SETS
        for unit, uname in UNITS
        for what, show in (("mean ± std", mean_std), ("95 % CI", ci))
    ]


def _cells() -> list[tuple]:
    """(label, cell(row) -> text) for every line of the table, top to bottom."""
    return [
        ("p", lambda r: str(r["p"]) if r["p"] else "-"),
        ("size of the set n_i", lambda r: r["sizes"]),
        ("no. of epochs N_i", _epochs),
        ("total time T (ours)", lambda r: f"{r['presentations']:,}t"),
        ("total time T (paper)", _paper_time),
        ("paper's n_i, N_i (or budget)?", lambda r: r["paper_setting"]),
        ("wall s per replica-run (job train / total), engine that ran", _wall),
        ("replicas complete", lambda r: r["replicas"]),
        ("rms error, paper¹", lambda r: fmt(r["paper_rms"]) if r["paper_rms"] is not None else "—"),
        *_rms_cells(),
        ("held-out nMSE², mean ± std", lambda r: mean_std(stat_of(r, "heldout_nmse"))),
        ("held-out RMS of the mean predictor² Nm", lambda r: fmt(r["heldout_floor_nm"])),
    ]


def table1_markdown(rows: list[dict]) -> str:
    """The paper's layout: attributes down the side, one column per (method, topology)."""

    def cell(r, label, show):
        if r.get("presentations") is None:  # no results for this column
            return r.get("replicas", "") if label == "replicas complete" else "—"
        return show(r)

    header = ["Table 1"] + [f"{r['method']} {r['topology']}" for r in rows]
    return table(header, [[label] + [cell(r, label, show) for r in rows] for label, show in _cells()])


def grid_section(ctx: Context) -> Section:
    """Table 1 in the paper's layout for its grid (the report's title, and the README block); for a study of
    parameters, whose methods would make one column each, a pointer to the same numbers in table1.csv."""
    rows = table1_rows(ctx.groups, ctx.topologies, _methods(ctx))
    title = "Table 1 (paper's layout, with the paper's numbers)"
    if is_grid(ctx):
        return Section(
            title, [table1_markdown(rows), FOOTNOTE], csv={"table1.csv": rows}, heading=HEADING, readme=readme_block
        )
    tops = f"{len(ctx.topologies)} topolog{'ies' if len(ctx.topologies) > 1 else 'y'}"
    note = (
        f"Not laid out: this sweep is a study of parameters, not Table 1's grid of the paper's methods "
        f"({len(ctx.methods)} methods × {tops}, labelled by the settings they sweep), so Table 1's "
        "layout would have one column each. `table1.csv` holds every column (schedule, cost, wall time, "
        "replicas, mean / std / 95 % interval of each metric); the sections above read them."
    )
    return Section(title, [note], csv={"table1.csv": rows})


def verdict_section(ctx: Context) -> Section:
    """Every variant of the reference against every other method, for Table 1's grid; for a study of parameters
    that product (thousands of rows, most across different costs) is not computed, and the note says where the
    comparisons the study is about are."""
    ref = DESIGN.reference
    if is_grid(ctx):
        return verdict.section(ctx, ref)
    n = len(comparisons(ctx.methods, ref)) * len(ctx.topologies)
    return Section(
        verdict.title(ref),
        [
            f"Not computed: this sweep is a study of parameters, where {ref} against every other "
            f"method would be {n:,} comparisons across different settings and costs. The comparisons a study "
            f"is about are each staged setting against {DESIGN.baseline} training at the same cost (the selection "
            "verdict, shown when the sweep has more than one budget) and each family's spread and level (the "
            "sensitivity section, shown when a family has more than one setting)."
        ],
    )


def time_to_target_rows(groups, topologies, methods) -> list[dict]:
    """Presentations each method needs until its mean held-out curve first reaches a target: the final value of
    the paper's baseline run (:func:`paper_conventional`, found by its settings whatever its label), and that of
    the paper's reference run, else of the run named as the reference (how long the other methods take to get as
    far as the reference does: the speed-up in honest form). Costs are fractions of the baseline run's."""
    base = {t: paper_conventional(groups, t) for t in topologies}
    ref = {t: paper_run(groups, t, DESIGN.reference) or groups.get((t, DESIGN.reference)) for t in topologies}
    targets = [(DESIGN.baseline, base), (DESIGN.reference, ref)]
    return rows_to_targets(groups, topologies, methods, targets, base, DESIGN.baseline)


def time_to_target_section(ctx: Context) -> Section:
    """Every method against both targets for Table 1's grid; for a study, the settings that reach them, by family."""
    rows = time_to_target_rows(ctx.groups, ctx.topologies, _methods(ctx))
    b, r = DESIGN.baseline, DESIGN.reference
    note, csv = time_to_target.note(b), {"time_to_target.csv": rows}
    if is_grid(ctx):
        title = f"Time to target (targets: {b}'s and {r}'s final held-out curve RMS, mean over seeds)"
        return Section(title, [time_to_target.time_to_target_markdown(rows, b), note], csv=csv)
    title = (
        f"Time to target (targets: the final held-out curve RMS of the paper's {b} run and of {SELECTIVE}, mean "
        "over seeds)"
    )
    names = {
        (f.topology, g.schedule): (f.name, f.label(g)) for f in families(ctx.groups, ctx.topologies) for g in f.members
    }
    none = f"No target: neither the paper's {b} run nor a {r} run of the paper's is in this sweep."
    return Section(title, [time_to_target.reached_markdown(rows, names, b) or none, note], csv=csv)


def plots_section(ctx: Context) -> Section | None:
    return _table1_plots.section(ctx, is_grid(ctx), _methods(ctx))


def _seeds_text(report: Report) -> str:
    seeds = sorted({s for g in report.ctx.groups.values() for s in g.by_seed})
    if seeds and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"seeds {seeds[0]}–{seeds[-1]}"
    return f"{len(seeds)} seeds"


def _heldout_patterns(report: Report) -> str:
    ns = {((j.results or {}).get("tests") or {}).get("heldout", {}).get("n") for j in report.ctx.jobs if j.results}
    return f", {ns.pop():,} held-out patterns" if len(ns) == 1 and None not in ns else ""


def numbers_table(report: Report) -> str:
    """Final held-out RMS (Nm), mean [95 % interval], one row per topology, one column per method, and the
    paper's baseline / reference."""
    t1 = {(r["method"], r["topology"]): r for r in report.rows("table1.csv")}
    methods, topologies = DESIGN.methods(report.ctx.methods), report.ctx.topologies
    cost = {
        m: next((t1[(m, t)]["presentations"] for t in topologies if t1[(m, t)].get("presentations")), None)
        for m in methods
    }
    pair = (DESIGN.baseline, DESIGN.reference)
    head = ["topology"] + [f"{m}, {cost[m]:,} t" if cost[m] else m for m in methods]
    head.append(f"paper, {' / '.join(DESIGN.short.get(m, m) for m in pair)} (units unstated)")
    body = []
    for t in topologies:
        st = [stat_of(t1[(m, t)], "heldout_nm") for m in methods]
        cells = [f"{s['mean']:.4f} {ci(s)}" if s["mean"] is not None else "no results" for s in st]
        paper = " / ".join(f"{PAPER[m]['rms'][t]:.4f}" if t in PAPER[m]["rms"] else "—" for m in pair)
        body.append([t, *cells, paper])
    return table(head, body)


def findings(report: Report) -> list[str]:
    """One bullet per comparison, in the verdicts' own words, and the time to target."""
    out = []
    b, r_ = DESIGN.baseline, DESIGN.reference
    t1 = report.rows("table1.csv")
    cost = {r["method"]: r["presentations"] for r in t1 if r.get("presentations")}
    if b in cost and r_ in cost:
        out.append(
            f"**Cost.** {r_}: T = {cost[r_]:,}·t against {b}: T_con = {cost[b]:,}·t (ratio {cost[r_] / cost[b]:.3f})."
        )
    by_comparison: dict[str, list[dict]] = {}
    for r in report.rows("verdict.csv"):
        by_comparison.setdefault(r["comparison"], []).append(r)
    for comparison, rows in by_comparison.items():
        ratio = next((f"; cost ratio {r['cost_ratio']:.3f}" for r in rows if r.get("cost_ratio")), "")
        readings = "; ".join(f"{r['topology']}: {r.get('reading_heldout', '')}" for r in rows)
        out.append(f"**{comparison}** (paired by seed, final held-out RMS{ratio}): {readings}.")
    reached = [
        r
        for r in report.rows("time_to_target.csv")
        if r["target_method"] == r_ and r["method"] == b and r.get("reached") == "yes"
    ]
    if reached:
        where = "; ".join(
            f"{r['presentations_to_target']:,} presentations for {r['topology']} (previous "
            f"curve point {r['previous_curve_point']:,})"
            for r in reached
        )
        out.append(f"**Time to target.** {b}'s mean held-out curve first reaches {r_}'s final value at {where}.")
    return [f"* {line}" for line in out]


def readme_block(report: Report, command: str) -> str:
    """The README's Table 1 block (``--readme``): the numbers table and the findings, each from the report."""
    return "\n\n".join(
        [
            f"<!-- generated by `{command}`: edit the generator (studies/selpres_studies/table1.py), not this "
            "block -->",
            f"Final held-out RMS in Nm, mean over {_seeds_text(report)} [95 % t-interval]{_heldout_patterns(report)}:",
            numbers_table(report),
            "What the report's statistics say:",
            "\n".join(findings(report)),
            verdict.method_note(report.rows("verdict.csv"), report.ctx.options, DESIGN.reference),
        ]
    )


# each section built on its own (one that fails is named, the rest kept): Table 1's grid leads with its table; a
# study of parameters leads with time to target and the curves, after the study's own sections
GRID_SECTIONS = [
    ("table1", grid_section),
    ("verdict", verdict_section),
    ("time_to_target", time_to_target_section),
    ("plots", plots_section),
]
STUDY_SECTIONS = [
    ("time_to_target", time_to_target_section),
    ("plots", plots_section),
    ("table1", grid_section),
    ("verdict", verdict_section),
]


def section(ctx: Context) -> list[Section]:
    makers = GRID_SECTIONS if is_grid(ctx) else STUDY_SECTIONS
    return [s for name, make in makers if (s := built(make, ctx, name)) is not None]


SECTION = section
