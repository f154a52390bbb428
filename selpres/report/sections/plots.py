"""Figures: held-out error against cost (the fair axis), and the cost of each method in presentations and
in measured seconds."""

from __future__ import annotations

from pathlib import Path

from selpres.report.compare import mean_curve
from selpres.report.context import Context, Section
from selpres.report.families import families, paper_run
from selpres.report.groups import REFERENCE
from selpres.report.paper import PAPER, PAPER_UNITS_NOTE
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


def plot_curves(groups, topologies, methods, path: Path, labels: dict[str, str] | None = None) -> None:
    """Held-out curve RMS (Nm) against cumulative presentations; one panel per topology. ``labels``: legend
    text per method (a study's), then drawn outside the panels."""
    plt = pyplot()
    from matplotlib.ticker import FuncFormatter

    if labels:
        fig, axes = plt.subplots(
            1, len(topologies), figsize=(5.2 * len(topologies) + 5, 4.6), squeeze=False, layout="constrained"
        )
        colors = [c for c, _ in family_styles(methods).values()]
    else:
        fig, axes = plt.subplots(1, len(topologies), figsize=(5.2 * len(topologies), 4.2), squeeze=False)
        colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, t in zip(axes[0], topologies):
        for i, m in enumerate(methods):
            g = groups.get((t, m))
            curve = mean_curve(g) if g else []
            if not curve:
                continue
            c = colors[i % len(colors)]
            x = [p for p, _, _ in curve]
            ax.plot(
                x, [v for _, v, _ in curve], color=c, label=f"{labels[m] if labels else m} (n={len(g.complete_seeds)})"
            )
            lo = [st["ci95"][0] if st["ci95"][0] is not None else v for _, v, st in curve]
            hi = [st["ci95"][1] if st["ci95"][1] is not None else v for _, v, st in curve]
            ax.fill_between(x, [max(v, 1e-12) for v in lo], hi, color=c, alpha=0.2, lw=0)
            if m == REFERENCE and g.sched:
                per_stage = g.sched["presentations_per_stage"]
                for k in range(len(g.sched["sizes"]) - 1):
                    ax.axvline(sum(per_stage[: k + 1]), color=c, ls=":", lw=0.8)
            paper = PAPER.get(m, {})
            if t in paper.get("rms", {}):
                ax.plot(
                    [paper["presentations"]],
                    [paper["rms"][t]],
                    marker="_",
                    ms=18,
                    mew=2.5,
                    color=c,
                    ls="none",
                    label=f"{PAPER_UNITS_NOTE}: {m}",
                )
        ax.set_yscale("log")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}k"))
        ax.set_title(f"{t}")
        ax.set_xlabel("cumulative presentations (units of t)")
        ax.set_ylabel("held-out curve RMS (Nm)")
        ax.grid(True, which="both", alpha=0.3)
        if not labels:
            ax.legend(fontsize=7)
    fig.suptitle(
        "Held-out RMS vs cost: mean over seeds, band = 95 % t-interval of the mean"
        + ("" if labels else f"; dotted = {REFERENCE} stage boundaries"),
        fontsize=9,
    )
    if labels:  # one legend for all panels, outside them
        handles = {h.get_label(): h for ax in axes[0] for h in ax.get_legend_handles_labels()[0]}
        fig.legend(list(handles.values()), list(handles), loc="outside right center", fontsize=7)
    else:
        fig.tight_layout()
    save_png(fig, path)


def plot_cost(groups, topologies, methods, path: Path) -> None:
    """Presentations per method, and measured wall seconds per replica-run per (topology, method)."""
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    pres = {}
    for m in methods:
        for t in topologies:
            g = groups.get((t, m))
            if g and g.sched:
                pres.setdefault(m, g.sched["presentations"])
    a1.bar(list(pres), list(pres.values()), color="tab:blue", label="ours")
    for k, m in enumerate(pres):
        if m in PAPER:
            a1.plot(
                [k],
                [PAPER[m]["presentations"]],
                marker="_",
                ms=30,
                mew=2,
                color="k",
                label="paper" if k == 0 or "paper" not in a1.get_legend_handles_labels()[1] else None,
            )
    a1.set_ylabel("presentations T/t")
    a1.set_title("cost in presentations")
    a1.legend(fontsize=8)
    width = 0.8 / max(1, len(methods))
    ran = {key: g.engines()["engine"] for key, g in groups.items() if g.used}
    for i, m in enumerate(methods):
        ys = [(groups[(t, m)].wall()["per_replica"] or 0) if (t, m) in ran else 0 for t in topologies]
        engines = sorted({e for (_, mm), e in ran.items() if mm == m})
        label = m if len(set(ran.values())) <= 1 else f"{m} ({', '.join(engines)})"
        a2.bar([k + i * width for k in range(len(topologies))], ys, width, label=label)
    a2.set_xticks([k + width * (len(methods) - 1) / 2 for k in range(len(topologies))], topologies)
    a2.set_ylabel("train seconds / replica (job train time ÷ replicas)")
    a2.set_title(f"measured wall time per replica-run, engine: {', '.join(sorted(set(ran.values())))}")
    a2.legend(fontsize=8)
    fig.tight_layout()
    save_png(fig, path)


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
        return Section("Plots", [images], figures=figures)
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
