"""The verdicts: selective − every other method, paired by seed, with an interval and a reading."""

from __future__ import annotations

from selpres.report.compare import verdict_rows
from selpres.report.context import Context, Section
from selpres.report.markdown import ci, fmt, table

NOTE = (
    "Δ < 0: selective has the lower error. Pairs = seeds complete in both jobs. The reading says *no "
    "detectable difference* when the 95 % t-interval of the paired mean difference contains 0; the "
    "percentage is relative to the other method's mean over the paired seeds. Cost ratio = selective "
    "presentations ÷ other's."
)


def _diff(r: dict, set_: str) -> str:
    if r.get(f"{set_}_diff_mean") is None:
        return "n/a"
    return f"{r[f'{set_}_diff_mean']:+.4f} " + ci({"ci95": [r[f"{set_}_ci_lo"], r[f"{set_}_ci_hi"]]})


def verdict_markdown(rows: list[dict]) -> str:
    head = ["topology", "comparison", "cost ratio", "pairs", "held-out Δ Nm, mean [95 % CI]",
            "held-out reading", "test-10 Δ Nm, mean [95 % CI]", "test-10 reading"]
    return table(head, [[r["topology"], r["comparison"], fmt(r.get("cost_ratio"), 3),
                         str(r.get("heldout_pairs", 0)), _diff(r, "heldout"), r.get("reading_heldout", ""),
                         _diff(r, "test10"), r.get("reading_test10", "")] for r in rows])


def section(ctx: Context) -> Section:
    rows = verdict_rows(ctx.groups, ctx.topologies, ctx.methods)
    title = "Verdict: selective − other, paired by seed (final RMS, Nm)"
    return Section(title, [verdict_markdown(rows), NOTE], csv={"verdict.csv": rows})
