"""Time to target: the presentations each method needs to reach conventional's and selective's final
held-out error (the speed-up, measured on the cost axis)."""

from __future__ import annotations

from selpres.report.compare import time_to_target_rows
from selpres.report.context import Context, Section
from selpres.report.groups import BASELINE, REFERENCE
from selpres.report.markdown import fmt, table

NOTE = (
    "The held-out curve is scored every `eval.every` epochs and at stage ends, on the first "
    "`eval.heldout_curve` held-out patterns; the first curve point at or below the target is reported, with "
    "the previous curve point (the true crossing lies in between). Fraction = presentations ÷ the "
    f"{BASELINE} run's total presentations."
)


def time_to_target_markdown(rows: list[dict]) -> str:
    head = ["target", "topology", "method", "target (Nm)", "presentations to target",
            "(previous curve point)", f"fraction of {BASELINE} cost", "final curve RMS (Nm)"]
    body = []
    for r in rows:
        if r.get("reached") == "yes":
            hit = [f"{r['presentations_to_target']:,}", f"{r['previous_curve_point']:,}",
                   fmt(r["fraction_of_conventional_cost"], 3)]
        else:
            hit = [r.get("reached", ""), "", ""]
        body.append([f"{r['target_method']}'s final", r["topology"], r["method"],
                     fmt(r.get("target_heldout_curve_rms_nm")), *hit, fmt(r.get("final_curve_rms_nm"))])
    return table(head, body)


def section(ctx: Context) -> Section:
    rows = time_to_target_rows(ctx.groups, ctx.topologies, ctx.methods)
    title = (f"Time to target (targets: {BASELINE}'s and {REFERENCE}'s final held-out curve RMS, "
             "mean over seeds)")
    return Section(title, [time_to_target_markdown(rows), NOTE], csv={"time_to_target.csv": rows})
