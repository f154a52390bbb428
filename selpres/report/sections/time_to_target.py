"""Time to target: the presentations each method needs to reach conventional's and selective's final
held-out error (the speed-up, measured on the cost axis)."""

from __future__ import annotations

from selpres.report.compare import time_to_target_rows
from selpres.report.context import Context, Section
from selpres.report.families import families
from selpres.report.groups import BASELINE, REFERENCE
from selpres.report.markdown import fmt, table

NOTE = (
    "The held-out curve is scored every `eval.every` epochs and at stage ends, on the first "
    "`eval.heldout_curve` held-out patterns; the first curve point at or below the target is reported, with "
    "the previous curve point (the true crossing lies in between). Fraction = presentations ÷ the "
    f"{BASELINE} run's total presentations."
)


def time_to_target_markdown(rows: list[dict]) -> str:
    head = [
        "target",
        "topology",
        "method",
        "target (Nm)",
        "presentations to target",
        "(previous curve point)",
        f"fraction of {BASELINE} cost",
        "final curve RMS (Nm)",
    ]
    body = []
    for r in rows:
        if r.get("reached") == "yes":
            hit = [
                f"{r['presentations_to_target']:,}",
                f"{r['previous_curve_point']:,}",
                fmt(r["fraction_of_conventional_cost"], 3),
            ]
        else:
            hit = [r.get("reached", ""), "", ""]
        body.append(
            [
                f"{r['target_method']}'s final",
                r["topology"],
                r["method"],
                fmt(r.get("target_heldout_curve_rms_nm")),
                *hit,
                fmt(r.get("final_curve_rms_nm")),
            ]
        )
    return table(head, body)


def reached_markdown(rows: list[dict], ctx: Context) -> str:
    """A study's version: per target, only the settings that reach it, fastest first, named by family and
    setting; how many never do (every row is in time_to_target.csv)."""
    names = {
        (f.topology, g.schedule): (f.name, f.label(g)) for f in families(ctx.groups, ctx.topologies) for g in f.members
    }
    blocks = []
    for key in dict.fromkeys((r["target_method"], r["topology"]) for r in rows):
        mine = [r for r in rows if (r["target_method"], r["topology"]) == key]
        hits = sorted((r for r in mine if r.get("reached") == "yes"), key=lambda r: r["presentations_to_target"])
        missed = [r for r in mine if r.get("reached") != "yes"]
        target = next((r["target_heldout_curve_rms_nm"] for r in mine if "target_heldout_curve_rms_nm" in r), None)
        family, setting = names.get((key[1], key[0]), (key[0], ""))
        run = f"{family} ({setting})" if setting else family
        title = f"**Target: the final held-out curve RMS of {run}**, {key[1]}: {fmt(target)} Nm"
        body = [
            [
                *names.get((r["topology"], r["method"]), (r["method"], "")),
                f"{r['presentations_to_target']:,}",
                f"{r['previous_curve_point']:,}",
                fmt(r["fraction_of_conventional_cost"], 3),
                f"{r['method_presentations']:,}",
                fmt(r.get("final_curve_rms_nm")),
            ]
            for r in hits
        ]
        head = [
            "family",
            "setting",
            "presentations to target",
            "(previous curve point)",
            f"fraction of {BASELINE} cost",
            "its own cost",
            "final curve RMS (Nm)",
        ]
        text = table(head, body) if body else ""
        blocks.append(
            "\n\n".join(
                filter(
                    None,
                    [
                        title,
                        text,
                        f"{len(hits)} of {len(mine)} settings reach it; {len(missed)} never do "
                        "(`time_to_target.csv` lists every one).",
                    ],
                )
            )
        )
    return "\n\n".join(blocks)


def section(ctx: Context) -> Section:
    rows = time_to_target_rows(ctx.groups, ctx.topologies, ctx.methods)
    if ctx.table1_like:
        title = f"Time to target (targets: {BASELINE}'s and {REFERENCE}'s final held-out curve RMS, mean over seeds)"
        return Section(title, [time_to_target_markdown(rows), NOTE], csv={"time_to_target.csv": rows})
    title = (
        "Time to target (targets: the final held-out curve RMS of the paper's conventional run and of "
        f"{REFERENCE} presentation, mean over seeds)"
    )
    none = f"No target: neither the paper's conventional run nor a {REFERENCE} run of the paper's is in this sweep."
    return Section(title, [reached_markdown(rows, ctx) or none, NOTE], csv={"time_to_target.csv": rows})
