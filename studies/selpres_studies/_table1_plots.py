"""Table 1's figures: every method's held-out curve against cost, with the paper's values beside ours as
unit-free ratios (reference ÷ baseline: its RMS values have no stated unit, so they are never drawn on the Nm axis),
and the cost of each method with what the paper printed; for a study of parameters, the paper's runs and each
family's best setting. Drawn by the report's :mod:`selpres.report.sections.plots`."""

from __future__ import annotations

import math

from selpres.report import Context, Section, Side, draw_cost, draw_curves, save_png, summarize
from selpres_studies._families import families, paper_run
from selpres_studies._paper import DESIGN, paper_setting

RATIO_SET = "test10"  # the paper's RMS is over its 10 test patterns
PAPER = DESIGN.published
_B = PAPER[DESIGN.baseline]  # the cost the paper printed beside the one it means (1,50,000t for 1002 × 150)
COST_MARKS = (
    f"paper's Table 1 ({_B['printed']} printed\nfor {_B['sizes'][-1]} × {sum(_B['epochs'])} = {_B['presentations']:,}t)"
)


def _paper_group(groups, topology: str, method: str):
    """The paper's run of ``method``: found by its setting (:func:`paper_run`), else the group of that name
    when it has the paper's n_i and N_i (as Table 1 sets the paper's value beside it)."""
    g = paper_run(groups, topology, method) or groups.get((topology, method))
    return g if g is not None and paper_setting(method, g.sched) == "yes" else None


def paper_ratio_rows(groups, topologies) -> list[dict]:
    """Per topology with the paper's two runs: reference ÷ baseline final test-10 RMS, ours and the paper's. A
    ratio of two errors in the same units has none, so the paper's Table 1 (units unstated) can be set beside
    ours. Ours: the geometric mean over paired seeds of each seed's ratio, with the 95 % t-interval of the mean
    log ratio taken back (None below two paired seeds)."""
    rows = []
    pair = (DESIGN.baseline, DESIGN.reference)
    for t in topologies:
        con, sel = (_paper_group(groups, t, m) for m in pair)
        paper = [PAPER[m]["rms"].get(t) for m in pair]
        if con is None or sel is None or None in paper:
            continue
        a, b = sel.values(RATIO_SET), con.values(RATIO_SET)
        logs = [math.log(a[s] / b[s]) for s in sorted(set(a) & set(b)) if a[s] > 0 and b[s] > 0]
        st = summarize(logs)
        lo, hi = st["ci95"]
        rows.append(
            {
                "topology": t,
                "n": st["n"],
                "ours": math.exp(st["mean"]) if st["mean"] is not None else None,
                "ours_ci_lo": math.exp(lo) if lo is not None else None,
                "ours_ci_hi": math.exp(hi) if hi is not None else None,
                "paper": paper[1] / paper[0],
            }
        )
    return rows


def draw_ratios(ax, rows: list[dict], colour: str) -> list:
    """The ratio panel: ours with its interval, the paper's as a hollow marker, 1 = equal error."""
    ref, baseline = DESIGN.reference, DESIGN.baseline
    x = list(range(len(rows)))
    ours = [(k, r) for k, r in zip(x, rows) if r["ours"] is not None]
    handles = []
    if ours:
        yerr = [
            [r["ours"] - (r["ours_ci_lo"] or r["ours"]) for _, r in ours],
            [(r["ours_ci_hi"] or r["ours"]) - r["ours"] for _, r in ours],
        ]
        n = sorted({r["n"] for _, r in ours})
        handles.append(
            ax.errorbar(
                [k - 0.08 for k, _ in ours],
                [r["ours"] for _, r in ours],
                yerr=yerr,
                fmt="o",
                color=colour,
                capsize=3,
                label=f"ours: geometric mean of paired ratios, 95 % interval (n={'/'.join(map(str, n))})",
            )
        )
    handles.append(
        ax.plot(
            [k + 0.08 for k in x],
            [r["paper"] for r in rows],
            "D",
            mfc="none",
            mec="k",
            mew=1.2,
            ls="none",
            label=f"paper's Table 1: its {ref} ÷ its {baseline}",
        )[0]
    )
    handles.append(ax.axhline(1.0, color="0.5", lw=0.8, ls="--", label="ratio 1: equal error"))
    ax.set_xticks(x, [r["topology"] for r in rows])
    ax.set_xlim(-0.5, len(rows) - 0.5)
    ax.set_xlabel("topology")
    ax.set_ylabel(f"{ref} ÷ {baseline}, final test-10 RMS\n(ratio of errors, no unit)")
    ax.set_title("against the paper: ratios", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    return handles


def draw_table1_curves(groups, topologies, methods):
    """Every method's curve, the reference's stage boundaries, and the ratio panel where the paper's two runs are."""
    ratios = paper_ratio_rows(groups, topologies)
    side = None
    if ratios:
        side = Side(
            len(ratios),
            "the paper's values as unit-free ratios",
            lambda ax, colours: draw_ratios(ax, ratios, colours.get(DESIGN.reference, "k")),
        )
    return draw_curves(groups, topologies, methods, staged=DESIGN.reference, side=side)


def draw_table1_cost(groups, topologies, methods):
    """Every method's cost in presentations, the paper's printed cost marked."""
    marks = {m: p["presentations"] for m, p in PAPER.items()}
    return draw_cost(groups, topologies, methods, marks=marks, marks_label=COST_MARKS)


def study_methods(ctx: Context) -> dict[str, str]:
    """A study's curves worth drawing, with their legend text: the paper's two runs and each family's best
    setting (a curve per setting of a study of parameters would be unreadable)."""
    out: dict[str, str] = {}
    fams = families(ctx.groups, ctx.topologies)
    for t in ctx.topologies:
        for method in (DESIGN.baseline, DESIGN.reference):
            if (g := paper_run(ctx.groups, t, method)) is not None:
                home = next(f for f in fams if any(m is g for m in f.members))
                out.setdefault(g.schedule, f"the paper's {method}: {home.name}")
        for f in fams:
            done = [g for g in f.members if g.values("heldout")]
            if f.topology == t and len(f.members) > 1 and done:
                best = min(done, key=lambda g: summarize(g.values("heldout").values())["mean"])
                out.setdefault(best.schedule, f"best of {f.name}: {f.label(best)}")
    return out


def ratio_text(rows: list[dict]) -> list[str]:
    """The ratio panel's numbers and what they are, for the report's text (nothing without the paper's runs)."""
    if not rows:
        return []
    ref, baseline = DESIGN.reference, DESIGN.baseline

    def ours(r: dict) -> str:
        if r["ours"] is None:
            return "—"
        iv = f" [{r['ours_ci_lo']:.3f}, {r['ours_ci_hi']:.3f}]" if r["ours_ci_lo"] is not None else ""
        return f"{r['ours']:.3f}{iv} (n={r['n']})"

    table = [
        f"| topology | {ref} ÷ {baseline}, ours (95 % interval) | paper's Table 1 |",
        "|---|---|---|",
        *(f"| {r['topology']} | {ours(r)} | {r['paper']:.3f} |" for r in rows),
    ]
    note = (
        "The paper's RMS values have no stated unit, so `curves.png` does not draw them on the Nm axis: its "
        f"right panel and this table set the paper's ratio {ref} ÷ {baseline} (final error over the 10 "
        "test patterns; the units cancel) beside ours, the geometric mean over paired seeds of each seed's "
        "ratio with the 95 % t-interval of the mean log ratio. `cost.png` draws presentations only: a job "
        "trains its replicas together, so its wall time is one measurement with no spread (Table 1 lists it; "
        "`selpres-bench` measures speed ratios side by side)."
    )
    return ["\n".join(table), note]


def section(ctx: Context, grid: bool, methods: list[str]) -> Section | None:
    """Every method's curve and cost for Table 1's grid; for a study of parameters, those of
    :func:`study_methods` (None when it has none)."""
    if grid:
        args = (ctx.groups, ctx.topologies, methods)
        figures = {
            "curves.png": ("held-out RMS vs presentations", lambda p: save_png(draw_table1_curves(*args), p)),
            "cost.png": ("cost", lambda p: save_png(draw_table1_cost(*args), p)),
        }
        images = "\n\n".join(f"![{caption}]({name})" for name, (caption, _) in figures.items())
        return Section("Plots", [images, *ratio_text(paper_ratio_rows(ctx.groups, ctx.topologies))], figures=figures)
    labels = study_methods(ctx)
    if not labels:
        return None
    figures = {
        "curves.png": (
            "held-out RMS vs presentations: the paper's runs and each family's best",
            lambda p: save_png(draw_curves(ctx.groups, ctx.topologies, list(labels), labels), p),
        )
    }
    images = "\n\n".join(f"![{caption}]({name})" for name, (caption, _) in figures.items())
    note = (
        "The paper's two runs and the best setting of each family with two or more settings; every "
        "setting's final error is on the error–cost plane."
    )
    return Section("Plots", [images, note], figures=figures)
