"""The error–cost plane and heat maps (issue 10, item 3).

The plane puts every configuration at (presentations, mean final held-out RMS) with its 95 % interval,
coloured by family, over conventional training's mean learning curve: the frontier, i.e. what plain
training reaches at each cost. A point above the frontier is beaten by conventional training stopped at
the same cost. Heat maps show a family's two-parameter grids (lr × momentum, ε × μ, κ × φ, ...).

Shown with the sensitivity section (:mod:`selpres_studies.sensitivity`): when some family has more than one
setting.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from selpres.report import (
    Context,
    Group,
    Section,
    family_styles,
    mean_curve,
    nm_log_axis,
    pyplot,
    save_png,
    summarize,
    thousands,
)
from selpres_studies._families import Family, families, paper_conventional

NOTE = (
    "Points: mean final held-out RMS over complete seeds (all held-out patterns), bars: its 95 % t-interval; "
    "one point per configuration, colour and marker by family (one legend entry per family). Line: the mean "
    "held-out curve of the paper's "
    "conventional run (scored every `eval.every` epochs on the first `eval.heldout_curve` held-out "
    "patterns), the frontier a method must get below to beat plain training stopped at the same cost. "
    "Heat maps: mean final held-out RMS (Nm) of each setting of a family swept over a grid of two or more "
    "parameters (at least half its cells run); the two with the most values are the axes, any others make "
    "one panel per value; "
    "a red box marks the family's best, a blank cell a setting not run (or with no complete seed)."
)


def plane_rows(groups, topologies, fams: list[Family] | None = None) -> list[dict]:
    """One row per configuration: its family, setting, cost and mean final held-out RMS with interval."""
    rows = []
    for fam in fams if fams is not None else families(groups, topologies):
        for g in fam.members:
            st = summarize(g.values("heldout").values())
            rows.append(
                {
                    "topology": fam.topology,
                    "family": fam.name,
                    "method": g.schedule,
                    "setting": fam.label(g),
                    "presentations": g.cost,
                    "n": st["n"],
                    "diverged": g.n_diverged,
                    "heldout_nm_mean": st["mean"],
                    "heldout_nm_ci_lo": st["ci95"][0],
                    "heldout_nm_ci_hi": st["ci95"][1],
                }
            )
    return rows


@dataclass
class Grid:
    """A family's settings laid out on two swept parameters (x, y), one panel per value of the others."""

    family: Family
    x: str
    y: str
    xs: list[str]
    ys: list[str]
    panels: dict[str, dict[tuple[str, str], float | None]]  # panel label -> (x value, y value) -> mean


GRID_FILL = 0.5  # a family's settings must fill at least half the cells to be drawn as a heat map


def grid(fam: Family) -> Grid | None:
    """The family's heat-map layout, or None when fewer than two parameters take two or more values, or when
    its settings fill less than half the cells (a design of one factor at a time, such as selective
    presentation's, is a line through the grid: a mostly blank map; its settings are tabulated instead).
    Axes: the two parameters with the most values (ties by name); a mean is None without complete seeds."""
    keys = sorted(fam.keys, key=lambda k: (-len(fam.values(k)), k))
    if len(keys) < 2 or len(fam.members) < GRID_FILL * math.prod(len(fam.values(k)) for k in keys):
        return None
    x, y, rest = keys[0], keys[1], keys[2:]
    panels: dict[str, dict[tuple[str, str], float | None]] = {}
    for g in fam.members:
        f = fam.settings[g.schedule]
        panel = " ".join(f"{k}={f.get(k, 'absent')}".replace('"', "") for k in rest)
        panels.setdefault(panel, {})[(f.get(x, "absent"), f.get(y, "absent"))] = summarize(
            g.values("heldout").values()
        )["mean"]
    return Grid(fam, x, y, fam.values(x), fam.values(y), dict(sorted(panels.items())))


def frontier_label(ref: Group, fam: Family | None) -> str:
    what = f"{fam.name},\n{fam.label(ref)}" if fam and len(fam.members) > 1 else ref.schedule
    n = len(ref.complete_seeds)
    return f"frontier: the paper's conventional run,\nits mean learning curve (n={n}):\n{what}"


def draw_plane(rows: list[dict], groups, topologies: list[str], fams: list[Family]):
    """The figure: one panel per topology, each family's configurations with 95 % bars in its own colour and
    marker, the paper's conventional mean curve as the frontier, one legend for all outside the panels."""
    plt = pyplot()
    styles = family_styles(list(dict.fromkeys(r["family"] for r in rows)))
    fig, axes = plt.subplots(
        1, len(topologies), figsize=(6 * len(topologies) + 4, 5.2), squeeze=False, layout="constrained"
    )
    legend: dict[str, object] = {}
    for ax, t in zip(axes[0], topologies):
        ref = paper_conventional(groups, t)
        curve = mean_curve(ref) if ref else []
        if curve:
            home = next((f for f in fams if any(m is ref for m in f.members)), None)
            (line,) = ax.plot([p for p, _, _ in curve], [v for _, v, _ in curve], color="0.3", lw=1.2)
            legend.setdefault(frontier_label(ref, home), line)
        for fam in dict.fromkeys(r["family"] for r in rows if r["topology"] == t):
            pts = [r for r in rows if r["topology"] == t and r["family"] == fam and r["heldout_nm_mean"]]
            if not pts:
                continue
            x = [r["presentations"] for r in pts]
            y = [r["heldout_nm_mean"] for r in pts]
            lo = [r["heldout_nm_mean"] - (r["heldout_nm_ci_lo"] or r["heldout_nm_mean"]) for r in pts]
            hi = [(r["heldout_nm_ci_hi"] or r["heldout_nm_mean"]) - r["heldout_nm_mean"] for r in pts]
            color, marker = styles[fam]
            handle = ax.errorbar(
                x,
                y,
                yerr=[lo, hi],
                fmt=marker,
                ms=5,
                capsize=2,
                color=color,
                mec="k",
                mew=0.4,
                elinewidth=0.8,
                alpha=0.9,
            )
            legend.setdefault(f"{fam} ({len(pts)})", handle)
        nm_log_axis(ax)
        thousands(ax)
        ax.set_title(t)
        ax.set_xlabel("presentations (units of t)")
        ax.set_ylabel("held-out RMS (Nm)")
        ax.grid(True, which="both", alpha=0.3)
    fig.legend(
        list(legend.values()),
        list(legend),
        loc="outside right center",
        fontsize=7,
        title="family (configurations)",
        title_fontsize=7,
    )
    fig.suptitle(
        "Error–cost plane: every configuration (mean final held-out RMS, 95 % interval)\n"
        "over conventional training's mean learning curve",
        fontsize=9,
    )
    return fig


def plot_plane(rows: list[dict], groups, topologies: list[str], fams: list[Family], path: Path) -> None:
    save_png(draw_plane(rows, groups, topologies, fams), path)


def plot_grid(gr: Grid, path: Path) -> None:
    """One heat map per panel, cells annotated with the mean, the family's best boxed."""
    plt = pyplot()
    import numpy as np

    n = len(gr.panels)
    fig, axes = plt.subplots(1, n, figsize=(1.2 * len(gr.xs) + 3.2 * n, 0.7 * len(gr.ys) + 2.4), squeeze=False)
    finite = [v for cells in gr.panels.values() for v in cells.values() if v is not None]
    best = min(finite) if finite else None
    vmin, vmax = (min(finite), max(finite)) if finite else (0.0, 1.0)
    for ax, (panel, cells) in zip(axes[0], gr.panels.items()):
        z = np.array(
            [[cells.get((xv, yv)) if cells.get((xv, yv)) is not None else math.nan for xv in gr.xs] for yv in gr.ys],
            dtype=float,
        )
        im = ax.imshow(z, cmap="viridis", vmin=vmin, vmax=vmax, aspect="auto", origin="lower")
        for i in range(len(gr.ys)):
            for j in range(len(gr.xs)):
                if not math.isnan(z[i, j]):
                    light = (z[i, j] - vmin) > 0.6 * (vmax - vmin)  # viridis is light at the top
                    ax.text(j, i, f"{z[i, j]:.4f}", ha="center", va="center", fontsize=7, color="k" if light else "w")
                    if z[i, j] == best:
                        ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec="r", lw=2))
        ax.set_xticks(range(len(gr.xs)), [v.replace('"', "") for v in gr.xs], fontsize=7, rotation=20)
        ax.set_yticks(range(len(gr.ys)), [v.replace('"', "") for v in gr.ys], fontsize=7)
        ax.set_xlabel(gr.x)
        ax.set_ylabel(gr.y)
        if panel:
            ax.set_title(panel, fontsize=8)
        fig.colorbar(im, ax=ax, label="mean final held-out RMS (Nm)")
    fig.suptitle(f"{gr.family.name}, {gr.family.topology}", fontsize=9)
    fig.tight_layout()
    save_png(fig, path)


def slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_")


def section(ctx: Context) -> Section | None:
    fams = families(ctx.groups, ctx.topologies)
    if not any(len(f.members) > 1 for f in fams):
        return None
    rows = plane_rows(ctx.groups, ctx.topologies, fams)
    figures = {"error_cost.png": ("error–cost plane", lambda p: plot_plane(rows, ctx.groups, ctx.topologies, fams, p))}
    for gr in filter(None, (grid(f) for f in fams)):
        name = f"heatmap_{slug(gr.family.name)}_{gr.family.topology}.png"
        figures[name] = (f"{gr.family.name}, {gr.family.topology}: {gr.x} × {gr.y}", lambda p, gr=gr: plot_grid(gr, p))
    images = "\n\n".join(f"![{caption}]({name})" for name, (caption, _) in figures.items())
    return Section("Error–cost plane and heat maps", [images, NOTE], csv={"error_cost.csv": rows}, figures=figures)
