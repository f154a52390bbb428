"""The verdicts: selective − every other method, paired by seed, with intervals, p-values against zero
and against the equivalence margin, and a reading in plain words."""

from __future__ import annotations

from selpres.report.compare import ALPHA, Options, comparisons, verdict_rows
from selpres.report.context import Context, Section
from selpres.report.groups import REFERENCE, SETS
from selpres.report.markdown import diff_text, fmt, pvalues_text, table


def method_note(rows: list[dict], options: Options) -> str:
    """How the readings were reached: the three readings, the margin used, the families and Holm."""
    sizes = ", ".join(
        f"{max((r.get(f'{s}_family_size', 0) for r in rows), default=0)} {name}" for s, name in SETS[::-1]
    )
    adjusted = (
        "Holm-adjusted within each family (`--holm`)"
        if options.holm
        else "not adjusted for multiplicity (`--holm` applies Holm's step-down correction)"
    )
    return (
        f"Three readings, never merged: *better/worse by …* when the paired t-test rejects Δ = 0 "
        f"(p < {ALPHA:g}: the 95 % t-interval excludes 0); *equivalent within ±m* when two one-sided tests "
        f"(TOST, Schuirmann 1987) reject |Δ| ≥ m (p < {ALPHA:g}: the 90 % interval lies inside ±m); "
        "otherwise *no detectable difference*, which does not rule out a real effect of the size its "
        "interval allows. "
        f"Margin m = {options.margin.describe()}. Comparisons per family (one metric across this table): "
        f"{sizes}; p-values {adjusted}."
    )


NOTE = (
    f"Δ < 0: {REFERENCE} has the lower error. Pairs = seeds complete in both jobs. The percentage is "
    f"relative to the other method's mean over the paired seeds. Cost ratio = {REFERENCE} presentations ÷ "
    "other's."
)


def verdict_markdown(rows: list[dict], options: Options = Options()) -> str:
    head = ["topology", "comparison", "cost ratio", "pairs"]
    for _, name in SETS[::-1]:  # held-out first: the paper's claim is about generalisation
        head += [
            f"{name} Δ Nm, mean [95 % CI]",
            f"{name} ±m Nm",
            f"{name} p: t / TOST" + (" (Holm)" if options.holm else ""),
            f"{name} reading",
        ]
    body = []
    for r in rows:
        cells = [r["topology"], r["comparison"], fmt(r.get("cost_ratio"), 3), str(r.get("heldout_pairs", 0))]
        for set_, _ in SETS[::-1]:
            cells += [
                diff_text(r, set_),
                fmt(r.get(f"{set_}_margin")),
                pvalues_text(r, set_, options.holm),
                r.get(f"reading_{set_}", ""),
            ]
        body.append(cells)
    return table(head, body)


def section(ctx: Context) -> Section:
    """Every selective variant against every other method, for a Table-1-like sweep; for a study of
    parameters that product (thousands of rows, most across different costs) is not computed, and the note
    says where the comparisons the study is about are."""
    title = f"Verdict: {REFERENCE} − other, paired by seed (final RMS, Nm)"
    if not ctx.table1_like:
        n = len(comparisons(ctx.methods)) * len(ctx.topologies)
        return Section(
            title,
            [
                f"Not computed: this sweep is a study of parameters, where {REFERENCE} against every other "
                f"method would be {n:,} comparisons across different settings and costs. The comparisons a study "
                "is about are each staged setting against conventional training at the same cost (the selection "
                "verdict, shown when the sweep has more than one budget) and each family's spread and level (the "
                "sensitivity section, shown when a family has more than one setting)."
            ],
        )
    rows = verdict_rows(ctx.groups, ctx.topologies, ctx.methods, ctx.options)
    return Section(
        title, [verdict_markdown(rows, ctx.options), method_note(rows, ctx.options), NOTE], csv={"verdict.csv": rows}
    )
