"""Figures: held-out error against cost (the fair axis), the paper's Table 1 as unit-free ratios beside ours,
and the cost of each method in presentations."""

from __future__ import annotations

import math
from pathlib import Path

from selpres.report.compare import mean_curve
from selpres.report.context import Context, Section
from selpres.report.families import families, paper_run
from selpres.report.groups import REFERENCE
from selpres.report.paper import PAPER, paper_setting
from selpres.run.stats import summarize
from selpres.storage import atomic_write


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig, path: Path) -> None:
    plt = pyplot()
    atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=110))
    plt.close(fig)


# 12 colours (the default cycle and two more) against 11 markers: the first 12 families differ in colour, and
# no two of the first 132 share both colour and marker
EXTRA_COLOURS = ["black", "gold"]
MARKERS = "osD^vP*XhH<"


def family_styles(names: list[str]) -> dict[str, tuple[str, str]]:
    """Colour and marker per family (or curve), from two cycles of coprime lengths, so each is told apart by
    the pair (and neighbours by both)."""
    cycle = pyplot().rcParams["axes.prop_cycle"].by_key()["color"] + EXTRA_COLOURS
    return {n: (cycle[i % len(cycle)], MARKERS[i % len(MARKERS)]) for i, n in enumerate(names)}


def nm_log_axis(ax) -> None:
    """A log axis of errors with plain decimal tick labels (0.02, 0.03, ...), not 2 × 10⁻²."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    ax.set_yscale("log")
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    ax.yaxis.set_major_formatter(plain)
    ax.yaxis.set_minor_locator(LogLocator(subs=(2, 3, 5)))
    ax.yaxis.set_minor_formatter(plain)


def thousands(ax) -> None:
    from matplotlib.ticker import FuncFormatter

    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}k"))


RATIO_SET = "test10"  # the paper's RMS is over its 10 test patterns


def _paper_group(groups, topology: str, method: str):
    """The paper's run of ``method``: found by its setting (:func:`paper_run`), else the group of that name
    when it has the paper's n_i and N_i (as Table 1 sets the paper's value beside it)."""
    g = paper_run(groups, topology, method) or groups.get((topology, method))
    return g if g is not None and paper_setting(method, g.sched) == "yes" else None


def paper_ratio_rows(groups, topologies) -> list[dict]:
    """Per topology with the paper's two runs: selective ÷ conventional final test-10 RMS, ours and the
    paper's. A ratio of two errors in the same units has none, so the paper's Table 1 (units unstated) can
    be set beside ours. Ours: the geometric mean over paired seeds of each seed's ratio, with the 95 %
    t-interval of the mean log ratio taken back (None below two paired seeds)."""
    rows = []
    for t in topologies:
        con, sel = (_paper_group(groups, t, m) for m in ("conventional", REFERENCE))
        paper = [PAPER[m]["rms"].get(t) for m in ("conventional", REFERENCE)]
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
            label="paper's Table 1: its selective ÷ its conventional",
        )[0]
    )
    handles.append(ax.axhline(1.0, color="0.5", lw=0.8, ls="--", label="ratio 1: equal error"))
    ax.set_xticks(x, [r["topology"] for r in rows])
    ax.set_xlim(-0.5, len(rows) - 0.5)
    ax.set_xlabel("topology")
    ax.set_ylabel(f"{REFERENCE} ÷ conventional, final test-10 RMS\n(ratio of errors, no unit)")
    ax.set_title("against the paper: ratios", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    return handles


def draw_curves(groups, topologies, methods, labels: dict[str, str] | None = None):
    """Held-out curve RMS (Nm) against cumulative presentations, one panel per topology, and (a Table-1
    sweep) a panel of selective ÷ conventional ratios beside the paper's: its RMS values have no stated unit,
    so they are never drawn on the Nm axis. One legend for all, outside the panels. ``labels``: legend text
    per method (a study's)."""
    plt = pyplot()
    ratios = [] if labels else paper_ratio_rows(groups, topologies)
    widths = [5.0] * len(topologies) + ([1.2 + 0.9 * len(ratios)] if ratios else [])
    width = sum(widths) + 5.5 if labels else max(sum(widths) + 0.6, 11.0)  # room for the legend's columns
    fig, axes = plt.subplots(
        1,
        len(widths),
        figsize=(width, 5.4 if labels else 5.8),
        squeeze=False,
        layout="constrained",
        gridspec_kw={"width_ratios": widths},
    )
    colors = [c for c, _ in family_styles(methods).values()]
    legend: dict[str, object] = {}
    for ax, t in zip(axes[0], topologies):
        for i, m in enumerate(methods):
            g = groups.get((t, m))
            curve = mean_curve(g) if g else []
            if not curve:
                continue
            c = colors[i % len(colors)]
            x = [p for p, _, _ in curve]
            (line,) = ax.plot(x, [v for _, v, _ in curve], color=c)
            legend.setdefault(labels[m] if labels else m, line)
            lo = [st["ci95"][0] if st["ci95"][0] is not None else v for _, v, st in curve]
            hi = [st["ci95"][1] if st["ci95"][1] is not None else v for _, v, st in curve]
            ax.fill_between(x, [max(v, 1e-12) for v in lo], hi, color=c, alpha=0.2, lw=0)
            if m == REFERENCE and g.sched and not labels:
                per_stage = g.sched["presentations_per_stage"]
                for k in range(len(g.sched["sizes"]) - 1):
                    stage = ax.axvline(sum(per_stage[: k + 1]), color=c, ls=":", lw=0.8)
                legend.setdefault(f"{REFERENCE}: stage boundaries", stage)
        nm_log_axis(ax)
        thousands(ax)
        seeds = sorted({len(g.complete_seeds) for (tt, _), g in groups.items() if tt == t and g.curves})
        ax.set_title(f"{t}  (seeds per curve: {'/'.join(map(str, seeds)) or '0'})", fontsize=10)
        ax.set_xlabel("cumulative presentations (units of t)")
        ax.set_ylabel("held-out curve RMS (Nm)")
        ax.grid(True, which="both", alpha=0.3)
    if ratios:
        for h in draw_ratios(axes[0][-1], ratios, colors[methods.index(REFERENCE)] if REFERENCE in methods else "k"):
            legend.setdefault(h.get_label(), h)
    fig.suptitle(
        "Held-out RMS against cost: mean over seeds,\nband = 95 % t-interval of the mean"
        + ("; right: the paper's values as unit-free ratios" if ratios else ""),
        fontsize=10,
    )
    where = {"loc": "outside right center"} if labels else {"loc": "outside lower center", "ncols": 2 + (width >= 15)}
    fig.legend(list(legend.values()), list(legend), fontsize=8, **where)
    return fig


def plot_curves(groups, topologies, methods, path: Path, labels: dict[str, str] | None = None) -> None:
    save_png(draw_curves(groups, topologies, methods, labels), path)


def draw_cost(groups, topologies, methods):
    """Presentations charged per method (training, and the forward passes spent choosing subsets at their
    charge), the paper's printed cost as a marker. Wall time is not drawn: a job trains its replicas
    together, so each (topology, method) has one measurement and no spread (Table 1 lists it; speed
    ratios come from ``selpres-bench``)."""
    plt = pyplot()
    from matplotlib.ticker import FuncFormatter

    train, charged = {}, {}
    for m in methods:
        for t in topologies:
            g = groups.get((t, m))
            if g and g.sched and m not in train:
                train[m] = g.sched["presentations"]
                charged[m] = (g.cost or 0) - g.sched["presentations"]
    fig, ax = plt.subplots(figsize=(1.6 * max(1, len(train)) + 4.2, 4.4), layout="constrained")
    x = list(range(len(train)))
    ax.bar(x, list(train.values()), color="tab:blue", label="training presentations")
    if any(charged.values()):
        ax.bar(
            x,
            list(charged.values()),
            bottom=list(train.values()),
            color="tab:blue",
            alpha=0.45,
            hatch="//",
            label="selection forward passes, at their charge",
        )
    for k, m in enumerate(train):
        total = train[m] + charged[m]
        ax.annotate(f"{total:,}", (k, total / 2), ha="center", va="center", fontsize=8, color="w")
    paper = [(k, PAPER[m]["presentations"]) for k, m in enumerate(train) if m in PAPER]
    if paper:
        ax.plot(
            [k for k, _ in paper],
            [v for _, v in paper],
            "D",
            ms=7,
            mfc="none",
            mec="k",
            mew=1.4,
            ls="none",
            label="paper's Table 1 (1,50,000t printed\nfor 1002 × 150 = 150,300t)",
        )
    ax.set_xticks(x, list(train))
    ax.set_xlabel("method")
    ax.set_ylabel("presentations T/t (units of t)")
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:,.0f}"))
    ax.set_ylim(0, 1.12 * max([*(train[m] + charged[m] for m in train), *(v for _, v in paper)], default=1))
    ax.set_title("cost in presentations", fontsize=10)
    fig.legend(loc="outside right center", fontsize=8)
    return fig


def plot_cost(groups, topologies, methods, path: Path) -> None:
    save_png(draw_cost(groups, topologies, methods), path)


def study_methods(ctx: Context) -> dict[str, str]:
    """A study's curves worth drawing, with their legend text: the paper's two runs and each family's best
    setting (a curve per setting of a study of parameters would be unreadable)."""
    out: dict[str, str] = {}
    fams = families(ctx.groups, ctx.topologies)
    for t in ctx.topologies:
        for method in ("conventional", REFERENCE):
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

    def ours(r: dict) -> str:
        if r["ours"] is None:
            return "—"
        iv = f" [{r['ours_ci_lo']:.3f}, {r['ours_ci_hi']:.3f}]" if r["ours_ci_lo"] is not None else ""
        return f"{r['ours']:.3f}{iv} (n={r['n']})"

    table = [
        f"| topology | {REFERENCE} ÷ conventional, ours (95 % interval) | paper's Table 1 |",
        "|---|---|---|",
        *(f"| {r['topology']} | {ours(r)} | {r['paper']:.3f} |" for r in rows),
    ]
    note = (
        "The paper's RMS values have no stated unit, so `curves.png` does not draw them on the Nm axis: its "
        f"right panel and this table set the paper's ratio {REFERENCE} ÷ conventional (final error over the 10 "
        "test patterns; the units cancel) beside ours, the geometric mean over paired seeds of each seed's "
        "ratio with the 95 % t-interval of the mean log ratio. `cost.png` draws presentations only: a job "
        "trains its replicas together, so its wall time is one measurement with no spread (Table 1 lists it; "
        "`selpres-bench` measures speed ratios side by side)."
    )
    return ["\n".join(table), note]


def section(ctx: Context) -> Section | None:
    """Every method's curve and cost for a Table-1-like sweep; for a study, those of :func:`study_methods`
    (None when it has none)."""
    if ctx.table1_like:
        args = (ctx.groups, ctx.topologies, ctx.methods)
        figures = {
            "curves.png": ("held-out RMS vs presentations", lambda p: plot_curves(*args, p)),
            "cost.png": ("cost", lambda p: plot_cost(*args, p)),
        }
        images = "\n\n".join(f"![{caption}]({name})" for name, (caption, _) in figures.items())
        return Section("Plots", [images, *ratio_text(paper_ratio_rows(ctx.groups, ctx.topologies))], figures=figures)
    labels = study_methods(ctx)
    if not labels:
        return None
    figures = {
        "curves.png": (
            "held-out RMS vs presentations: the paper's runs and each family's best",
            lambda p: plot_curves(ctx.groups, ctx.topologies, list(labels), p, labels),
        )
    }
    images = "\n\n".join(f"![{caption}]({name})" for name, (caption, _) in figures.items())
    note = (
        "The paper's two runs and the best setting of each family with two or more settings; every "
        "setting's final error is on the error–cost plane."
    )
    return Section("Plots", [images, note], figures=figures)
