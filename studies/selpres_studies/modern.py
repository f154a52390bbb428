"""Modern training and data pruning (issues 22, 28, 31): every method's final held-out error against its total cost
and its wall seconds, per arm and training regime; each against conventional training scheduled for the same cost,
and each that makes a published claim judged on it (``_modern_claims``).

A cell is (arm, regime, method): the arm from ``robot`` (its name, else its file's or its kind), the regime from the
optimizer, its mini-batch and the hidden units (the paper's: sigmoid, online SGD), the method from the schedule's
name the job recorded: a pruning policy no code here knows or a new arm gets its rows as it is. The study's design
(``modern.yaml`` beside this module) names the roles: the *reference* (training at full cost, compared with nothing)
and the *partner*, one-stage conventional training *scheduled* for the same total cost (its cosine learning rate,
where there is one, decays to zero at that budget), against which every other method of the same arm and regime and
of the partner's cost is compared, paired by seed. The family for Holm's correction is every such comparison and
every tested claim of one metric in the sweep; the readings are the report's three (compare.reading), at the
report's margin (``--margin``, by default 5 % of the method's own mean). nMSE = mean over joints of MSE ÷ the held-
out targets' variance (1 = predicting the mean).
"""

from __future__ import annotations

from pathlib import Path

from selpres.report import (
    Context,
    Options,
    Section,
    clopper_pearson,
    median,
    outcome,
    summarize,
    table,
    trimmed,
)
from selpres_studies._families import pruned_job
from selpres_studies._modern_cells import (  # noqa: F401  (the study's API, read here by the tests)
    DESIGN,
    METRICS,
    Cell,
    Design,
    _arm_regimes,
    _order,
    arm_of,
    cells,
    heldout_nmse,
    job_cost,
    job_curves,
    job_work,
    regime_of,
)
from selpres_studies._modern_claims import (  # noqa: F401
    claim_rows,
    claims_markdown,
    converged_columns,
    converged_paired,
    judge,
    speedup,
)
from selpres_studies._modern_stalls import remedy_markdown, remedy_rows, stall_markdown, stall_rows  # noqa: F401

DODGE = 0.07  # methods of one cost are drawn side by side within ±7 % of their cost


def applies(ctx: Context) -> bool:
    """A sweep with a pruning rival or a modern regime beside the paper's."""
    return any(job.results and pruned_job(job.results) for job in ctx.jobs)


def summary_rows(cs: dict, design: Design = DESIGN) -> list[dict]:
    rows = []
    for key in sorted(cs, key=_order(design.methods(m for _, _, m in cs))):
        c = cs[key]
        row = {
            "arm": c.arm,
            "regime": c.regime,
            "method": c.method,
            "cost": c.cost,
            "wall_s": c.wall,
            "wall_min_s": min(c.work) if c.work else None,
            "wall_max_s": max(c.work) if c.work else None,
            "jobs": len(c.costs),
            "lr": ",".join(f"{v:g}" for v in sorted(c.lrs)),
            "engine": ",".join(sorted(c.engines)),
        }
        k, n = sum(c.stalled.values()), len(c.stalled)
        row.update(stalls=k, stall_seeds=n, stall_rate=k / n if n else None)
        row["stall_lo"], row["stall_hi"] = clopper_pearson(k, n)
        for metric, _, _ in METRICS:
            s = summarize(c.values(metric).values())
            row.update({f"{metric}_n": s["n"], f"{metric}_mean": s["mean"], f"{metric}_lo": s["ci95"][0]})
            row[f"{metric}_hi"] = s["ci95"][1]
            ok = list(c.converged(metric).values())
            t = trimmed(ok, design.trim)
            row.update({f"{metric}_converged_n": t["n"], f"{metric}_trimmed": t["mean"]})
            row.update({f"{metric}_trimmed_lo": t["ci95"][0], f"{metric}_trimmed_hi": t["ci95"][1]})
            row[f"{metric}_converged_median"] = median(ok)
        rows.append(row)
    return rows


def verdict_rows(cs: dict, options: Options, design: Design = DESIGN) -> list[dict]:
    """Every rival of the partner's cost (within ``design.matched_within``) against the partner, both metrics, on the
    converged error (:func:`converged_paired`: paired by seed where neither stalled, the trimmed mean); the p-values
    are Holm-adjusted by :func:`judge` over the whole family."""
    rows = []
    methods = design.methods(m for _, _, m in cs)
    for arm, regime in _arm_regimes(cs, design):
        partner = cs.get((arm, regime, design.partner))
        for method in design.rivals(methods):
            c = cs.get((arm, regime, method))
            if c is None or partner is None or not partner.cost:
                continue
            if abs(c.cost / partner.cost - 1) > design.matched_within:
                continue  # not of the partner's cost: judged on its own claim, if it makes one
            row = {"arm": arm, "regime": regime, "comparison": f"{method} − {design.partner}"}
            row["cost_ratio"] = c.cost / partner.cost
            row["_tests"] = {m: converged_paired(c, partner, m, options, design) for m, _, _ in METRICS}
            for metric, v in row["_tests"].items():
                row.update(converged_columns(metric, v))
            rows.append(row)
    return rows


def _iv(mean, lo, hi, nd=3) -> str:
    if mean is None:
        return "–"
    if lo is None:
        return f"{mean:.{nd}f}"
    return f"{mean:.{nd}f} [{lo:.{nd}f}, {hi:.{nd}f}]"


def summary_markdown(rows: list[dict]) -> str:
    body = [
        [
            r["arm"],
            r["regime"],
            r["method"],
            r["lr"],
            f"{r['cost']:,.0f}" if r["cost"] is not None else "–",
            _wall(r),
            _stalls(r),
            _iv(r["rms_trimmed"], r["rms_trimmed_lo"], r["rms_trimmed_hi"]),
            "–" if r["rms_converged_median"] is None else f"{r['rms_converged_median']:.3f}",
            _iv(r["rms_mean"], r["rms_lo"], r["rms_hi"]),
            _iv(r["nmse_trimmed"], r["nmse_trimmed_lo"], r["nmse_trimmed_hi"], 4),
            str(r["rms_n"]),
        ]
        for r in rows
    ]
    head = [
        "arm",
        "regime",
        "method",
        "lr",
        "total cost (presentations)",
        "wall s per job [min, max]",
        "stalled [95 %]",
        "converged RMS, Nm: trimmed mean [95 %]",
        "its median",
        "plain mean RMS (all seeds) [95 %]",
        "converged nMSE: trimmed mean [95 %]",
        "seeds",
    ]
    return table(head, body)


def _stalls(r: dict) -> str:
    if not r.get("stall_seeds"):
        return "–"
    return f"{r['stalls']}/{r['stall_seeds']} [{r['stall_lo'] * 100:.0f}, {r['stall_hi'] * 100:.0f} %]"


def _wall(r: dict) -> str:
    if r.get("wall_s") is None:
        return "–"
    if r["jobs"] < 2:
        return f"{r['wall_s']:.2f}"
    return f"{r['wall_s']:.2f} [{r['wall_min_s']:.2f}, {r['wall_max_s']:.2f}]"


def verdict_markdown(rows: list[dict]) -> str:
    body = [
        [
            r["arm"],
            r["regime"],
            r["comparison"],
            f"{r['rms_pairs']} ({r['rms_stalled_pairs']})",
            r["reading_rms"],
            plain_text(r, "rms"),
            r["reading_nmse"],
        ]
        for r in rows
    ]
    head = ["arm", "regime", "Δ (paired by seed)", "pairs (stalled, left out)", "converged held-out RMS (Nm)",
            "plain mean Δ RMS, all pairs [95 %]", "converged held-out nMSE"]  # fmt: skip
    return table(head, body)


def plain_text(r: dict, metric: str) -> str:
    """The plain mean difference over every pair (stalls included) with its t-interval, as the study read it before."""
    d = r.get(f"{metric}_plain_diff_mean")
    if d is None:
        return "–"
    lo, hi = r[f"{metric}_plain_ci_lo"], r[f"{metric}_plain_ci_hi"]
    return f"{d:+.4f}" + ("" if lo is None else f" [{lo:+.4f}, {hi:+.4f}]")


def headline(rows: list[dict], claims: list[dict] = ()) -> str:
    """The counts of each reading after Holm's correction (the adjusted p-values of the rows), and of each claim's
    verdict on held-out RMS."""
    out = []
    for metric, name, _ in METRICS:
        tested = [r for r in rows if r.get(f"{metric}_p_holm") is not None]
        said = [
            outcome(
                {
                    "n": r[f"{metric}_pairs"],
                    "p": r[f"{metric}_p_holm"],
                    "mean": r[f"{metric}_diff_mean"],
                    "p_tost": r.get(f"{metric}_tost_p_holm"),
                }
            )
            for r in tested
        ]
        counts = ", ".join(
            f"{said.count(k)} {k}" for k in ("better", "worse", "equivalent", "no detectable difference")
        )
        out.append(
            f"{name}: of {len(tested)} comparisons with compute-matched training, after Holm's correction {counts}"
        )
    text = "**Against compute-matched training** — " + "; ".join(out) + "."
    tested = [r for r in claims if r.get("claim_rms")]
    if tested:
        verdicts = [r["claim_rms"] for r in tested]
        counts = ", ".join(f"{verdicts.count(k)} {k}" for k in ("holds", "not shown", "contradicted"))
        text += f" **Each on its own claim** (held-out RMS, the same family) — of {len(tested)}: {counts}."
    return text


def note(options: Options, design: Design = DESIGN) -> str:
    return (
        "Total cost: back-propagated presentations plus forward passes charged for choosing at "
        "`schedule.selection_cost` of a presentation (Selective Backprop's; the pruning policies' scores come "
        "from their training passes). Wall: the method's own seconds per job (choosing, k-means and scoring "
        "included; preparing data and evaluating, which all share, left out), for all the job's seeds at once, "
        "the mean over its jobs and [min, max] over them (the seed blocks: repeats of the same method). "
        "Methods named `…_full` train for conventional training's epochs at their own saving; the others of "
        "selective presentation's cost are stopped at it (`schedule.budget`). "
        f"**Stalls** (final held-out RMS ≥ {design.stall_share * 100:g} % of the mean predictor's) are their own "
        "outcome (the stall table); every error comparison is of the **converged error**: paired by seed over the "
        f"seeds where neither run stalled, the {design.trim * 100:g} % trimmed mean of the differences "
        "(Tukey–McLaughlin test), the plain mean over every pair beside it. "
        f"**Compute-matched:** the partner `{design.partner}` is conventional training scheduled for that cost "
        "(its cosine learning rate reaches zero at its own end), not a prefix of the longer run; every method "
        f"within {design.matched_within * 100:g} % of its cost is compared with it. "
        f"Δ = method − {design.partner}, paired by seed; Δ < 0: the method has the lower error. Margin m = "
        f"{options.margin.describe('the method')} (of its converged trimmed mean). Readings: *better/worse* when "
        "the Holm-adjusted test rejects Δ = 0, *equivalent within ±m* when the Holm-adjusted TOST rejects "
        f"|Δ| ≥ m, else *no detectable difference*. **Own claims**, against `{design.reference}` at its full "
        "cost, m a share of its converged trimmed mean: *comparable* holds when the test finds the method better "
        "or a one-sided test rejects Δ ≥ +m (non-inferior); *lossless* holds when TOST rejects |Δ| ≥ m (or the "
        "method is better); *speedup* (no test: read off the held-out curves of the seeds where neither stalled) "
        "holds when every such seed's curve reaches that seed's "
        f"final `{design.reference}` curve value and the median cost to get there is below {design.reference}'s. "
        "Holm's family, per metric: every compute-matched comparison and every tested claim in the sweep."
    )


def plot_error_cost(rows: list[dict], path: Path, design: Design = DESIGN, axis: str = "cost") -> None:
    """The converged final held-out RMS (Nm: the trimmed mean over the seeds that did not stall) with 95 % intervals
    against total cost (``axis="cost"``) or against the method's wall seconds per job (``axis="wall"``, with its
    [min, max] over the jobs): one panel per (regime, arm), the legend outside the panels. A method keeps its colour
    whichever others ran (the design's listed methods hold theirs); the methods other than the reference are drawn
    side by side within ±DODGE of their cost."""
    from matplotlib.ticker import FuncFormatter

    from selpres.report import family_styles, pyplot, save_png

    plt = pyplot()
    panels = sorted({(r["regime"], r["arm"]) for r in rows}, key=lambda k: (not k[0].startswith("paper"), k))
    regimes = sorted({p[0] for p in panels}, key=lambda g: (not g.startswith("paper"), g))
    arms = sorted({p[1] for p in panels})
    fig, axes = plt.subplots(
        len(regimes),
        len(arms),
        figsize=(4.6 * len(arms) + 2.6, 3.6 * len(regimes)),
        squeeze=False,
        layout="constrained",
    )
    methods = design.methods({*design.order, *(r["method"] for r in rows)})
    styles = family_styles(methods)
    side = [m for m in methods if m != design.reference]
    step = 2 * DODGE / max(len(side) - 1, 1)
    for i, regime in enumerate(regimes):
        for j, arm in enumerate(arms):
            ax = axes[i][j]
            for r in rows:
                y = r["rms_trimmed"]  # the converged error: stalls are their own outcome
                if (r["regime"], r["arm"]) != (regime, arm) or y is None:
                    continue
                colour, marker = styles[r["method"]]
                lo, hi = r["rms_trimmed_lo"], r["rms_trimmed_hi"]
                yerr = None if lo is None else [[y - lo], [hi - y]]
                x, xerr = r["cost"], None
                if axis == "wall":
                    if r.get("wall_s") is None:
                        continue
                    x, xerr = r["wall_s"], [[r["wall_s"] - r["wall_min_s"]], [r["wall_max_s"] - r["wall_s"]]]
                k = side.index(r["method"]) if r["method"] in side else None  # the reference at its own cost
                dodge = 1.0 if k is None else 1 + step * (k - (len(side) - 1) / 2)
                ax.errorbar(
                    x * (dodge if axis == "cost" else 1.0),
                    y,
                    yerr=yerr,
                    xerr=xerr,
                    fmt=marker,
                    color=colour,
                    capsize=4,
                    ms=7,
                    label=r["method"],
                )
            ax.set_title(f"{arm}\n{regime}", fontsize=9)
            ax.set_xlabel("total cost (presentations)" if axis == "cost" else "the method's wall seconds per job")
            if axis == "wall":
                ax.set_xscale("log")
            ax.set_ylabel("converged held-out RMS (Nm), trimmed mean [95 %]")
            ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:,.0f}" if axis == "cost" else f"{v:g}"))
            ax.tick_params(axis="x", labelrotation=20)
            ax.grid(alpha=0.3)
    handles = {}
    for ax in axes.flat:
        for h, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, h)
    fig.legend(list(handles.values()), list(handles), loc="outside right center", title="method")
    save_png(fig, path)


def section(ctx: Context, design: Design = DESIGN) -> Section | None:
    if not applies(ctx):
        return None
    cs = cells(ctx, design)
    summary = summary_rows(cs, design)
    verdicts, claims = verdict_rows(cs, ctx.options, design), claim_rows(cs, ctx.options, design)
    judge(verdicts, claims, ctx.options)
    stalls, remedies = stall_rows(cs, design), remedy_rows(cs, design)
    blocks = [headline(verdicts, claims), summary_markdown(summary)]
    if stalls:
        blocks += [
            f"**Stalls** (final held-out RMS ≥ {design.stall_share * 100:g} % of predicting the training mean's), "
            f"per method, against `{design.reference}` paired by seed (McNemar's exact test on the seeds that "
            "stalled in one of the two; Holm over these tests), and the hidden units that ended dead (no gradient "
            "on any held-out input) or linear (the same derivative on every one: ReLU always on):",
            stall_markdown(stalls, design),
        ]
    if remedies:
        blocks += ["**The remedy** against the regime it remedies, method by method, paired by seed:"]
        blocks += [remedy_markdown(remedies)]
    if claims:
        blocks += [
            "**Each method on its own claim**, against conventional training at full cost:",
            claims_markdown(claims, design),
        ]
    blocks += [
        "**Against compute-matched training**:",
        verdict_markdown(verdicts),
        note(ctx.options, design),
        "![final held-out RMS against total cost, per regime and arm](modern_error_cost.png)\n\n"
        "Each point: the converged error (the trimmed mean over the seeds that did not stall) with its 95 % "
        "interval; methods of one cost are drawn "
        "side by side (within ±7 % of their cost; conventional training at its own) so their intervals "
        "can be told apart.",
        "![final held-out RMS against the method's wall seconds per job](modern_error_wall.png)\n\n"
        "The same errors against the method's own wall seconds per job (log scale; [min, max] over its jobs): "
        "cheaper in presentations is not always faster on this machine.",
    ]
    return Section(
        "Modern training and data pruning: error against total cost",
        blocks,
        csv={
            "modern.csv": summary,
            "modern_verdict.csv": verdicts,
            "modern_claims.csv": claims,
            "modern_stalls.csv": stalls,
            "modern_remedy.csv": remedies,
        },
        figures={
            "modern_error_cost.png": ("error against cost", lambda p: plot_error_cost(summary, p, design)),
            "modern_error_wall.png": ("error against wall", lambda p: plot_error_cost(summary, p, design, "wall")),
        },
    )


SECTION = section
ORDER = DESIGN.order  # the runs table of a modern sweep lists its methods in the design's order
