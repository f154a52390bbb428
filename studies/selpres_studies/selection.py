"""Selection verdict (issue 12, item 4): does any way of choosing the growing training set beat
conventional training given the same number of presentations?

For each staged configuration (its order = ``schedule.order``, its budget = its total presentations) and
topology: Δ = its final held-out RMS − that of *compute-matched* conventional training (a one-stage run
with the same total presentations, within 1 %, and otherwise the same settings), paired by seed, with its
95 % interval, the three readings of :mod:`selpres.report.compare` (better/worse, equivalent within ±m,
no detectable difference) and presentations to reach conventional's final error.

Shown when the sweep goes beyond Table 1's own comparison, which the verdict section already makes: more
than one budget, or an order other than the stratified and random ones.
"""

from __future__ import annotations

from selpres.report import (
    Context,
    Group,
    Options,
    Section,
    adjust_family,
    diff_text,
    fmt,
    mean_curve,
    outcome,
    paired,
    paired_columns,
    pvalues_text,
    reach,
    reading,
    signed_interval,
    table,
)
from selpres_studies._families import PAPER_ORDER, matched_partner, paper_conventional, stages

TABLE1_ORDERS = (PAPER_ORDER, "random")  # what Table 1's verdicts already compare at one budget


def _order(g: Group) -> str:
    return g.sched.get("order") or PAPER_ORDER


def order_rank(order: str) -> tuple:
    return (order not in TABLE1_ORDERS, TABLE1_ORDERS.index(order) if order in TABLE1_ORDERS else 0, order)


def _time_to(g: Group, target_group: Group | None) -> dict:
    """Presentations until ``g``'s mean held-out curve reaches ``target_group``'s final curve value."""
    target_curve = mean_curve(target_group) if target_group else []
    if not target_curve:
        return {"reached": "no target"}
    pres, target, _ = target_curve[-1]
    return {"target": target, **reach(mean_curve(g), target, pres)}


def selection_rows(
    groups: dict[tuple[str, str], Group], topologies: list[str], options: Options = Options()
) -> list[dict]:
    """One row per staged configuration and topology, against its compute-matched partner; the held-out
    comparisons form one family (its size recorded; Holm-adjusted with ``options.holm``)."""
    staged = sorted(
        (g for g in groups.values() if g.sched is not None and stages(g) > 1),
        key=lambda g: (topologies.index(g.topology), order_rank(_order(g)), g.cost, g.schedule),
    )
    rows, found = [], []
    for g in staged:
        order = _order(g)
        row = {"topology": g.topology, "order": order, "budget": g.cost, "method": g.schedule}
        rows.append(row)
        partner = matched_partner(groups, g)
        if partner is None:
            row["reading_heldout"] = (
                f"no compute-matched one-stage run at {g.cost:,} t (±1 %) with the same other settings"
            )
            continue
        v = paired(g.values("heldout"), partner.values("heldout"), options.margin)
        row.update(matched=partner.schedule, cost_ratio=g.cost / partner.cost, **paired_columns("heldout", v))
        found.append((row, v))
        conv = paper_conventional(groups, g.topology)
        to_conv, to_matched = _time_to(g, conv), _time_to(g, partner)
        row.update(
            conventional=conv.schedule if conv else None,
            to_conventional_target=to_conv.get("target"),
            to_conventional_reached=to_conv["reached"],
            to_conventional_presentations=to_conv.get("presentations_to_target"),
            to_conventional_previous_point=to_conv.get("previous_curve_point"),
            to_matched_target=to_matched.get("target"),
            to_matched_reached=to_matched["reached"],
            to_matched_presentations=to_matched.get("presentations_to_target"),
        )
    adjust_family(found, "heldout", options)
    for row, v in found:
        row["outcome"] = outcome(v)
        row["reading_heldout"] = reading({**v, "holm": options.holm}, name=f"{row['order']} order")
    return rows


def shown(rows: list[dict]) -> bool:
    """Whether the section adds to Table 1's verdicts: compared rows at more than one budget, or an order
    Table 1 does not have."""
    compared = [r for r in rows if "matched" in r]
    return bool(compared) and (
        len({r["budget"] for r in compared}) > 1 or any(r["order"] not in TABLE1_ORDERS for r in compared)
    )


def headline(rows: list[dict], options: Options) -> str:
    """Which order, if any, beats compute-matched training with an interval excluding zero, at what budget
    and by how much; else the null result, with what was tried."""
    compared = [r for r in rows if "outcome" in r]
    if not compared:
        return "**No comparison possible**: no staged run has a compute-matched one-stage partner."
    counts = {
        k: sum(r["outcome"] == k for r in compared)
        for k in ("better", "equivalent", "no detectable difference", "worse", "too few pairs")
    }
    orders = sorted({r["order"] for r in compared}, key=order_rank)
    budgets = ", ".join(f"{b:,}" for b in sorted({r["budget"] for r in compared}))
    tops = ", ".join(dict.fromkeys(r["topology"] for r in compared))
    tried = f"{len(compared)} comparisons: orders {', '.join(orders)}; budgets {budgets} t; topologies {tops}"
    holm = (
        f"p-values Holm-adjusted over the {len(compared)} comparisons"
        if options.holm
        else f"not adjusted for the {len(compared)} comparisons (`--holm` adjusts them)"
    )
    tally = ", ".join(f"{n} {k}" for k, n in counts.items() if n)
    wins = [r for r in compared if r["outcome"] == "better"]
    los = [r["heldout_ci_lo"] for r in compared if r["heldout_ci_lo"] is not None]
    his = [r["heldout_ci_hi"] for r in compared if r["heldout_ci_hi"] is not None]
    bounds = (
        f" The 95 % intervals reach from {min(los):+.4f} to {max(his):+.4f} Nm: effects of that size are not ruled out."
        if los
        else ""
    )
    if not wins:
        return (
            f"**No order beats compute-matched conventional training** with a 95 % interval of Δ below 0 "
            f"({tried}; {holm}). Readings: {tally}.{bounds}"
        )
    best = "; ".join(
        f"{r['order']} order at {r['budget']:,} t on {r['topology']}: lower by {-r['heldout_diff_mean']:.4f} "
        "Nm "
        f"({-r['heldout_diff_mean'] / r['heldout_other_mean'] * 100:.1f} %; 95 % interval "
        f"{signed_interval(r['heldout_ci_lo'], r['heldout_ci_hi'])})"
        for r in sorted(wins, key=lambda r: r["heldout_diff_mean"])
    )
    return (
        f"**Beats compute-matched conventional training** (95 % interval of Δ below 0): {best}. "
        f"Over {tried} ({holm}), readings: {tally}."
    )


def _reach_text(r: dict, key: str) -> str:
    state = r.get(f"{key}_reached")
    if state == "yes":
        return f"{r[f'{key}_presentations']:,}"
    return {"no target": "no target", None: ""}.get(state, state)


def selection_markdown(rows: list[dict], options: Options) -> str:
    head = [
        "topology",
        "order",
        "budget (t)",
        "run",
        "compute-matched",
        "cost ratio",
        "pairs",
        "Δ held-out Nm [95 % CI]",
        "±m Nm",
        "p: t / TOST" + (" (Holm)" if options.holm else ""),
        "reading",
        "presentations to conventional's final",
        "to matched's final",
    ]
    body = []
    for r in rows:
        if "matched" not in r:
            body.append(
                [
                    r["topology"],
                    r["order"],
                    f"{r['budget']:,}",
                    r["method"],
                    "—",
                    "",
                    "",
                    "",
                    "",
                    "",
                    r["reading_heldout"],
                    "",
                    "",
                ]
            )
            continue
        body.append(
            [
                r["topology"],
                r["order"],
                f"{r['budget']:,}",
                r["method"],
                r["matched"],
                fmt(r["cost_ratio"], 3),
                str(r["heldout_pairs"]),
                diff_text(r, "heldout"),
                fmt(r["heldout_margin"]),
                pvalues_text(r, "heldout", options.holm),
                r["reading_heldout"],
                _reach_text(r, "to_conventional"),
                _reach_text(r, "to_matched"),
            ]
        )
    return table(head, body)


def note(options: Options) -> str:
    return (
        "Δ = the staged run − compute-matched conventional training (one stage, the same presentations "
        "within 1 %, the same other settings), final held-out RMS, paired by seed; Δ < 0: the order has the "
        f"lower error. Margin m = {options.margin.describe('the staged run')}. Readings as in the verdict "
        "section: "
        "*better/worse* when the 95 % interval excludes 0, *equivalent* when the 90 % interval lies inside "
        "±m (TOST), otherwise *no detectable difference*. Presentations to a final: where the run's mean "
        "held-out curve first reaches the final curve RMS of the paper's conventional run (150,300 t) or of "
        "its compute-matched partner; the curve is scored every `eval.every` epochs and at stage ends."
    )


def section(ctx: Context) -> Section | None:
    rows = selection_rows(ctx.groups, ctx.topologies, ctx.options)
    if not shown(rows):
        return None
    return Section(
        "Selection verdict: each order against compute-matched conventional training",
        [headline(rows, ctx.options), selection_markdown(rows, ctx.options), note(ctx.options)],
        csv={"selection.csv": rows},
    )


SECTION = section
