"""Time to target: the presentations each method needs to reach a target error (the speed-up, measured on the
cost axis), rendered from :func:`selpres.report.compare.time_to_target_rows`. The targets, and the run whose cost
the others' are fractions of (its name: ``base``), are a study's."""

from __future__ import annotations

from selpres.report.markdown import fmt, table


def note(base: str) -> str:
    return (
        "The held-out curve is scored every `eval.every` epochs and at stage ends, on the first "
        "`eval.heldout_curve` held-out patterns; the first curve point at or below the target is reported, with "
        "the previous curve point (the true crossing lies in between). Fraction = presentations ÷ the "
        f"{base} run's total presentations."
    )


def time_to_target_markdown(rows: list[dict], base: str) -> str:
    """Every row: per target and topology, every method."""
    head = [
        "target",
        "topology",
        "method",
        "target (Nm)",
        "presentations to target",
        "(previous curve point)",
        f"fraction of {base} cost",
        "final curve RMS (Nm)",
    ]
    body = []
    for r in rows:
        if r.get("reached") == "yes":
            hit = [
                f"{r['presentations_to_target']:,}",
                f"{r['previous_curve_point']:,}",
                fmt(r[f"fraction_of_{base}_cost"], 3),
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


def reached_markdown(rows: list[dict], names: dict[tuple[str, str], tuple[str, str]], base: str) -> str:
    """A study of parameters' version: per target, only the settings that reach it, fastest first, named by
    ``names`` ((topology, method) -> (family, setting)); how many never do (every row is in time_to_target.csv)."""
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
                fmt(r[f"fraction_of_{base}_cost"], 3),
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
            f"fraction of {base} cost",
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
