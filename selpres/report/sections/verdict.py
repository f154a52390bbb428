"""The verdicts: a reference method − every other, paired by seed, with intervals, p-values against zero
and against the equivalence margin, and a reading in plain words. The reference is a study's (its design)."""

from __future__ import annotations

from selpres.report.compare import ALPHA, Options, verdict_rows
from selpres.report.context import Context, Section
from selpres.report.groups import SETS
from selpres.report.markdown import diff_text, fmt, pvalues_text, table


def method_note(rows: list[dict], options: Options, reference: str) -> str:
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
        f"Margin m = {options.margin.describe(reference)}. Comparisons per family (one metric across this table): "
        f"{sizes}; p-values {adjusted}."
    )


def note(reference: str) -> str:
    return (
        f"Δ < 0: {reference} has the lower error. Pairs = seeds complete in both jobs. The percentage is "
        f"relative to the other method's mean over the paired seeds. Cost ratio = {reference} presentations ÷ "
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


def title(reference: str) -> str:
    return f"Verdict: {reference} − other, paired by seed (final RMS, Nm)"


def section(ctx: Context, reference: str) -> Section:
    """Every variant of the ``reference`` method against every other method of the sweep."""
    rows = verdict_rows(ctx.groups, ctx.topologies, ctx.methods, reference, ctx.options)
    blocks = [verdict_markdown(rows, ctx.options), method_note(rows, ctx.options, reference), note(reference)]
    return Section(title(reference), blocks, csv={"verdict.csv": rows})
