"""Figures: held-out error against cost (the fair axis), with room for a study's panel beside it (Table 1's: the
paper's values as unit-free ratios), and the cost of each method in presentations, with a study's marks on it (the
costs the paper printed). Drawing only: which methods, marks and panels is the study's."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from selpres.report.compare import mean_curve
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


@dataclass(frozen=True)
class Side:
    """A study's panel right of the curves: how many entries its x axis has (its width), what the title says of
    it, and ``draw(ax, colours)`` -> its legend handles (``colours``: each method's colour in the curves)."""

    entries: int
    caption: str
    draw: Callable


def draw_curves(
    groups,
    topologies,
    methods,
    labels: dict[str, str] | None = None,
    staged: str | None = None,
    side: Side | None = None,
):
    """Held-out curve RMS (Nm) against cumulative presentations, one panel per topology, and a study's ``side``
    panel right of them. One legend for all, outside the panels. ``labels``: legend text per method (a study's;
    then the legend sits right of the panels); ``staged``: the method whose stage boundaries are drawn."""
    plt = pyplot()
    widths = [5.0] * len(topologies) + ([1.2 + 0.9 * side.entries] if side else [])
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
            if m == staged and g.sched:
                per_stage = g.sched["presentations_per_stage"]
                for k in range(len(g.sched["sizes"]) - 1):
                    stage = ax.axvline(sum(per_stage[: k + 1]), color=c, ls=":", lw=0.8)
                legend.setdefault(f"{staged}: stage boundaries", stage)
        nm_log_axis(ax)
        thousands(ax)
        seeds = sorted({len(g.complete_seeds) for (tt, _), g in groups.items() if tt == t and g.curves})
        ax.set_title(f"{t}  (seeds per curve: {'/'.join(map(str, seeds)) or '0'})", fontsize=10)
        ax.set_xlabel("cumulative presentations (units of t)")
        ax.set_ylabel("held-out curve RMS (Nm)")
        ax.grid(True, which="both", alpha=0.3)
    if side:
        for h in side.draw(axes[0][-1], dict(zip(methods, colors))):
            legend.setdefault(h.get_label(), h)
    fig.suptitle(
        "Held-out RMS against cost: mean over seeds,\nband = 95 % t-interval of the mean"
        + (f"; right: {side.caption}" if side else ""),
        fontsize=10,
    )
    where = {"loc": "outside right center"} if labels else {"loc": "outside lower center", "ncols": 2 + (width >= 15)}
    fig.legend(list(legend.values()), list(legend), fontsize=8, **where)
    return fig


def plot_curves(groups, topologies, methods, path: Path, **how) -> None:
    save_png(draw_curves(groups, topologies, methods, **how), path)


def draw_cost(groups, topologies, methods, marks: dict[str, int] | None = None, marks_label: str = ""):
    """Presentations charged per method (training, and the forward passes spent choosing subsets at their
    charge), a study's ``marks`` (method -> presentations, e.g. what a paper printed; ``marks_label`` in the
    legend) as hollow markers. Wall time is not drawn: a job trains its replicas together, so each (topology,
    method) has one measurement and no spread (a study's table lists it; speed ratios come from
    ``selpres-bench``)."""
    marks = marks or {}
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
    marked = [(k, marks[m]) for k, m in enumerate(train) if m in marks]
    if marked:
        ax.plot(
            [k for k, _ in marked],
            [v for _, v in marked],
            "D",
            ms=7,
            mfc="none",
            mec="k",
            mew=1.4,
            ls="none",
            label=marks_label,
        )
    ax.set_xticks(x, list(train))
    ax.set_xlabel("method")
    ax.set_ylabel("presentations T/t (units of t)")
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:,.0f}"))
    ax.set_ylim(0, 1.12 * max([*(train[m] + charged[m] for m in train), *(v for _, v in marked)], default=1))
    ax.set_title("cost in presentations", fontsize=10)
    fig.legend(loc="outside right center", fontsize=8)
    return fig


def plot_cost(groups, topologies, methods, path: Path, **how) -> None:
    save_png(draw_cost(groups, topologies, methods, **how), path)
