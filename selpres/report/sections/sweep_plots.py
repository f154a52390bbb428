"""The sweep section's figures: the error–cost plane and, for a two-key grid, a heat map of Δ against the partner.

The plane: every setting at (its cost, its mean final held-out RMS) with 95 % intervals (on the cost too where seeds
cost differently), numbered as in the table; conventional training stopped at each cost (the partners' final RMS,
joined: the line to beat) and the full conventional run's learning curve; the Pareto set ringed. The heat map:
Δ = setting − partner on a diverging scale centred at 0 (blue: the setting errs less), a cell whose 95 % interval
contains 0 hatched and marked "n.r."; one panel per schedule name. Legends sit below the panels, so the data has
the width of a README.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from selpres.report.groups import Group, base
from selpres.report.sections.plots import family_styles, nm_log_axis, pyplot, save_png, thousands
from selpres.run.stats import summarize

GRID_FILL = 0.5  # a grid is drawn when its settings fill at least half its cells


@dataclass
class Point:
    """One setting or conventional run: its cost and its final held-out RMS over seeds."""

    group: Group
    number: int = 0  # its row in the table (settings only)
    cost_ci: list = field(default_factory=lambda: [None, None])  # where seeds cost differently (pruning)

    @property
    def stats(self) -> dict:
        return summarize(self.group.values("heldout").values())

    @property
    def cost(self) -> float:
        return self.group.cost


def _bars(mean, lo, hi):
    return [[mean - lo if lo is not None else 0.0], [hi - mean if hi is not None else 0.0]]


LABEL_OFFSETS = [(7, 6), (7, -13), (-16, 6), (-16, -13), (9, 16), (-18, 16), (9, -24), (-18, -24), (0, 26)]


def _label(ax, taken: list, x: float, y: float, text: str) -> None:
    """The point's number where it overlaps no label placed before and no marker (points in display units)."""
    px, py = ax.transData.transform((x, y))
    w, h = 6.5 * len(text) + 2, 11
    for dx, dy in LABEL_OFFSETS:
        box = (px + dx * 1.4, py + dy * 1.4, w, h)  # offsets are in points, the display in pixels at dpi 110
        if not any(abs(box[0] - b[0]) < max(w, b[2]) and abs(box[1] - b[1]) < h for b in taken):
            break
    taken.append(box)
    ax.annotate(text, (x, y), xytext=(dx, dy), textcoords="offset points", fontsize=8)


def _front(points: list[Point]) -> list[tuple[float, float]]:
    """The Pareto front over every point (settings and conventional runs) as a step line, by cost."""
    pts = sorted((p.cost, p.stats["mean"]) for p in points if p.stats["mean"] is not None)
    out, best = [], math.inf
    for c, e in pts:
        if e < best:
            out.append((c, e))
            best = e
    return out


def number(text: str):
    """A swept value as a number where it is one (for ordering rows and axes), else its text."""
    try:
        v = json.loads(text)
    except (TypeError, ValueError):
        return text
    return v if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else text


def draw_plane(rows: list[dict], points: list[Point], conv: list[Point], topologies: list[str], curves: dict):
    plt = pyplot()
    fig, axes = plt.subplots(
        1, len(topologies), figsize=(8.2 * len(topologies), 5.6), squeeze=False, layout="constrained"
    )
    names = list(dict.fromkeys(base(p.group.schedule) for p in points))
    styles = family_styles(names)
    pareto_of = {r["number"]: r["pareto"] for r in rows}
    legend: dict[str, object] = {}
    for ax, t in zip(axes[0], topologies):
        mine = [p for p in points if p.group.topology == t and p.stats["mean"] is not None]
        line = sorted((p for p in conv if p.group.topology == t and p.stats["mean"] is not None), key=lambda p: p.cost)
        if line:
            x = [p.cost for p in line]
            st = [p.stats for p in line]
            (h,) = ax.plot(x, [s["mean"] for s in st], "s-", color="0.35", ms=4, lw=1.2)
            legend["one-stage training stopped at each cost (final RMS): the line to beat"] = h
            lo = [s["ci95"][0] if s["ci95"][0] is not None else s["mean"] for s in st]
            hi = [s["ci95"][1] if s["ci95"][1] is not None else s["mean"] for s in st]
            ax.fill_between(x, lo, hi, color="0.35", alpha=0.15, lw=0)
        shown = mine + line
        lo_x = min(p.cost for p in shown) * 0.9 if shown else 0
        hi_x = max(p.cost for p in shown) * 1.04 if shown else 1
        curve = [(c, v) for c, v, _ in curves.get(t, []) if lo_x <= c <= hi_x]
        if curve:
            (h,) = ax.plot([c for c, _ in curve], [v for _, v in curve], "--", color="0.6", lw=0.9)
            legend["the full one-stage run's learning curve (held-out curve patterns)"] = h
        front = _front(shown)
        if len(front) > 1:
            (h,) = ax.step([c for c, _ in front], [e for _, e in front], where="post", color="k", lw=0.8, ls=":")
            legend["Pareto front (every run)"] = h
        partners = {r["number"]: r.get("partner_cost") for r in rows}
        for p in mine:
            match = next((q for q in line if q.cost == partners.get(p.number)), None)
            if match is not None:
                ax.plot([p.cost, match.cost], [p.stats["mean"], match.stats["mean"]], color="0.5", lw=0.6)
        ax.set_xlim(lo_x, hi_x)
        taken: list = []
        for p in mine:
            st, name = p.stats, base(p.group.schedule)
            color, marker = styles[name]
            xerr = None if p.cost_ci[0] is None else _bars(p.cost, *p.cost_ci)
            h = ax.errorbar(
                p.cost, st["mean"], yerr=_bars(st["mean"], *st["ci95"]), xerr=xerr, fmt=marker, ms=6, color=color,
                mec="k", mew=0.5, capsize=2, elinewidth=0.9,
            )  # fmt: skip
            legend.setdefault(
                f"{name} (numbers: the table's rows)" if len(names) > 1 else "settings (numbered as in the table)", h
            )
            if pareto_of.get(p.number) == "Pareto":
                (ring,) = ax.plot(p.cost, st["mean"], "o", ms=14, mfc="none", mec="k", mew=1.1)
                legend["Pareto set (settings)"] = ring
        nm_log_axis(ax)
        fig.canvas.draw()  # the axes' final limits, so labels are placed where they will be drawn
        for p in mine:  # the markers themselves are taken too
            px, py = ax.transData.transform((p.cost, p.stats["mean"]))
            taken.append((px - 5, py - 5, 10, 10))
        for p in mine:
            _label(ax, taken, p.cost, p.stats["mean"], str(p.number))
        thousands(ax)
        ax.set_xlabel("cost: presentations (units of t)")
        ax.set_ylabel("final held-out RMS (Nm), mean over seeds")
        ax.set_title(t if len(topologies) > 1 else f"{t}: bars = 95 % t-intervals", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
    fig.legend(list(legend.values()), list(legend), loc="outside lower center", ncols=2, fontsize=8, frameon=False)
    return fig


def grids(rows: list[dict], keys: list[str]) -> tuple[list[tuple[str, str, str, dict]], str | None]:
    """[(schedule name, x key, y key, {(x, y): row})] of the names swept over exactly two keys, or why none."""
    inner = [k for k in keys if k != "schedule.name"]
    out, why = [], []
    for name in dict.fromkeys(r.get("schedule.name") or base(r["setting"]) for r in rows):
        mine = [r for r in rows if (r.get("schedule.name") or base(r["setting"])) == name]
        swept = [k for k in inner if len({r[k] for r in mine}) > 1]
        if len(swept) != 2:
            why.append(f"{name}: {len(swept)} swept key{'s' if len(swept) != 1 else ''}")
            continue
        x, y = sorted(swept, key=lambda k: -len({r[k] for r in mine}))
        cells = {(r[x], r[y]): r for r in mine}
        if len(cells) < GRID_FILL * len({r[x] for r in mine}) * len({r[y] for r in mine}):
            why.append(f"{name}: fewer than half the {x} × {y} cells run")
            continue
        out.append((name, x, y, cells))
    return out, None if out else "; ".join(why)


def draw_grids(found: list[tuple[str, str, str, dict]]):
    plt = pyplot()
    import numpy as np
    from matplotlib.colors import TwoSlopeNorm

    n = len(found)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n + 1.4, 4.2), squeeze=False, layout="constrained")
    deltas = [r.get("partner_diff_mean") for _, _, _, cells in found for r in cells.values()]
    span = max([abs(d) for d in deltas if d is not None] or [1e-6])
    norm = TwoSlopeNorm(vcenter=0.0, vmin=-span, vmax=span)
    for ax, (name, x, y, cells) in zip(axes[0], found):
        xs = sorted({k[0] for k in cells}, key=lambda v: (isinstance(number(v), str), number(v)))
        ys = sorted({k[1] for k in cells}, key=lambda v: (isinstance(number(v), str), number(v)))
        z = np.full((len(ys), len(xs)), math.nan)
        for (xv, yv), r in cells.items():
            if r.get("partner_diff_mean") is not None:
                z[ys.index(yv), xs.index(xv)] = r["partner_diff_mean"]
        im = ax.imshow(z, cmap="RdBu_r", norm=norm, aspect="auto", origin="lower")
        for (xv, yv), r in cells.items():
            i, j, d = ys.index(yv), xs.index(xv), r.get("partner_diff_mean")
            if d is None:
                ax.text(j, i, "no partner", ha="center", va="center", fontsize=7, color="0.4")
                continue
            said = r.get("partner_verdict")
            unresolved = said not in ("better", "worse", "equivalent")
            if unresolved:
                ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="///", ec="0.55", lw=0))
            mark = {"equivalent": "\n≈ within ±m", "better": "\nbetter", "worse": "\nworse"}.get(said, "\nn.r.")
            text = f"#{r['number']}\n{d:+.4f}" + mark
            ax.text(j, i, text, ha="center", va="center", fontsize=7, color="w" if abs(d) > 0.6 * span else "k")
        ax.set_xticks(range(len(xs)), xs, fontsize=8)
        ax.set_yticks(range(len(ys)), ys, fontsize=8)
        ax.set_xlabel(x)
        ax.set_ylabel(y)
        ax.set_title(name, fontsize=9)
    fig.colorbar(im, ax=list(axes[0]), label="Δ held-out RMS vs partner (Nm)\n< 0 (blue): the setting errs less")
    fig.suptitle(
        "Δ = setting − compute-matched partner, paired by seed\n"
        "hatched, n.r.: not resolved (no detectable difference, Holm)",
        fontsize=9,
    )
    return fig


def figures(ctx, rows: list[dict], points: list[Point], conv: list[Point], keys: list[str], curves: dict):
    """The section's figures ({file: (caption, draw(path))}) and its Markdown lines (the images, or why none);
    ``curves``: topology -> the full one-stage run's mean held-out curve."""
    figs = {
        "sweep_error_cost.png": (
            "error–cost plane: every setting numbered as in the table, the Pareto set ringed, one-stage training "
            "stopped at each cost as the line to beat",
            lambda path: save_png(draw_plane(rows, points, conv, ctx.topologies, curves), path),
        )
    }
    found, why = grids(rows, keys)
    lines = []
    if found and any(r.get("partner_diff_mean") is not None for _, _, _, c in found for r in c.values()):
        figs["sweep_heatmap.png"] = (
            "Δ against the compute-matched partner over the two swept keys",
            lambda path: save_png(draw_grids(found), path),
        )
    elif found:
        lines.append("No heat map: the settings' compute-matched partners are missing (see above).")
    else:
        lines.append(f"No heat map: it needs a schedule swept over exactly two keys ({why}).")
    return figs, [f"![{caption}]({name})" for name, (caption, _) in figs.items()] + lines
