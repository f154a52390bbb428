"""The modern study's judgements (:mod:`selpres_studies.modern`): each method on its own published claim against
the reference at full cost, and Holm's correction over the whole family (the compute-matched comparisons too)."""

from __future__ import annotations

import math

from selpres.report import (
    ALPHA,
    Margin,
    Options,
    adjust_family,
    median,
    outcome,
    paired,
    paired_columns,
    reading,
    signed_interval,
    table,
    tost,
)
from selpres_studies._modern_cells import DESIGN, METRICS, Cell, Design, _arm_regimes


def _against_reference(c: Cell, ref: Cell, metric: str, options: Options, one_sided: bool) -> dict:
    """c − ref paired by seed, the margin a share of the *reference's* mean (a claim is about matching it);
    ``one_sided``: the equivalence test is the non-inferiority half (H0: Δ ≥ +m), for "comparable or better"."""
    a, b = c.values(metric), ref.values(metric)
    seeds = sorted(set(a) & set(b))
    ref_mean = sum(b[s] for s in seeds) / len(seeds) if seeds else None
    m = options.margin.of(ref_mean)
    v = paired(a, b, Margin(m, relative=False) if m else options.margin)
    if one_sided and m and len(seeds) > 1:
        t = tost([a[s] - b[s] for s in seeds], m, ALPHA)
        v.update(p_tost=t["p_upper"], ci90=t["ci"])
    return v


def claim_rows(cs: dict, options: Options, design: Design = DESIGN) -> list[dict]:
    """Every method that makes a claim (``design.claims``) judged on it, against the reference at full cost:
    *comparable* (comparable or better: non-inferior within +m), *lossless* (equivalent within ±m, TOST), or
    *speedup* (the cost and the method's seconds to reach the reference's final error, seed by seed)."""
    rows = []
    for arm, regime in _arm_regimes(cs, design):
        ref = cs.get((arm, regime, design.reference))
        for method in design.methods(m for _, _, m in cs):
            kind, c = design.claims.get(method), cs.get((arm, regime, method))
            if kind is None or c is None or ref is None:
                continue
            row = {"arm": arm, "regime": regime, "method": method, "claim": kind}
            row["cost_share"] = c.cost / ref.cost if ref.cost else None
            row["wall_share"] = c.wall / ref.wall if ref.wall and c.wall is not None else None
            if kind == "speedup":
                row.update(speedup(c, ref))
            else:
                row["_tests"] = {
                    m: _against_reference(c, ref, m, options, one_sided=kind == "comparable") for m, _, _ in METRICS
                }
                for metric, v in row["_tests"].items():
                    row.update(paired_columns(metric, v))
            rows.append(row)
    return rows


def speedup(c: Cell, ref: Cell) -> dict:
    """Seed by seed, where the method's held-out curve first reaches the reference's final held-out curve value
    (the same seed's), as shares of the reference's final cost and seconds: medians over the seeds that reach it."""
    cost, secs, seeds = [], [], 0
    for seed, ref_curve in ref.curves.items():
        curve = c.curves.get(seed)
        if not curve or not ref_curve:
            continue
        seeds += 1
        target, ref_cost, ref_secs = ref_curve[-1][2], ref_curve[-1][0], ref_curve[-1][1]
        hit = next((p for p in curve if p[2] <= target), None)
        if hit is not None:
            cost.append(hit[0] / ref_cost)
            secs.append(hit[1] / ref_secs if ref_secs else math.nan)
    return {
        "seeds": seeds,
        "reached": len(cost),
        "cost_to_reach_share": median(cost),
        "wall_to_reach_share": median(s for s in secs if math.isfinite(s)),
    }


def judge(matched: list[dict], claims: list[dict], options: Options) -> None:
    """Holm's correction over the family: every compute-matched comparison and every tested claim, per metric;
    then each row's readings."""
    holm_ = Options(options.margin, holm=True)
    for metric, _, unit in METRICS:
        found = [(r, r["_tests"][metric]) for r in matched + claims if "_tests" in r]
        adjust_family(found, metric, holm_)
        for row in matched:
            v = row["_tests"][metric]
            name = row["comparison"].split(" ")[0]
            row[f"reading_{metric}"] = reading({**v, "holm": True}, name=name, unit=unit or "")
        for row in claims:
            if "_tests" in row:
                row[f"reading_{metric}"], row[f"claim_{metric}"] = claim_reading(row, row["_tests"][metric], unit)
    for row in matched + claims:
        row.pop("_tests", None)


def claim_reading(row: dict, v: dict, unit: str) -> tuple[str, str]:
    """(words, holds | not shown | contradicted) for one claim, from Holm-adjusted p-values."""
    unit = f" {unit}" if unit else ""
    said, m, d = outcome(v), v.get("margin"), v.get("mean")
    if said == "too few pairs":
        return f"too few pairs ({v['n']})", "not shown"
    iv = f"95 % interval {signed_interval(*v['ci95'])}; Holm p = {v['p']:.2g}"
    if said == "better":
        return f"better by {abs(d):.4f}{unit} ({iv})", "holds"
    passed = v.get("p_tost") is not None and v["p_tost"] < ALPHA
    test = "non-inferior within +" if row["claim"] == "comparable" else "equivalent within ±"
    within = f"{test}{m:.4f}{unit} (Holm p = {v['p_tost']:.2g})" if m else ""
    if said == "worse":
        return f"worse by {abs(d):.4f}{unit} ({iv})" + (f"; yet {within}" if passed else ""), (
            "holds" if passed else "contradicted"
        )
    if passed:
        return within + f" (Δ {d:+.4f}{unit}, {iv})", "holds"
    return f"not shown {within.split(' (')[0]} (Δ {d:+.4f}{unit}, {iv})", "not shown"


def _pct(x: float | None) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{x * 100:.0f} %"


CLAIMS = {
    "comparable": "comparable or better error than {ref} at its full cost, for less",
    "lossless": "lossless: {ref}'s error (±m) at its own saving",
    "speedup": "reaches {ref}'s final error sooner",
}


def claims_markdown(rows: list[dict], design: Design = DESIGN) -> str:
    body = []
    for r in rows:
        if r["claim"] == "speedup":
            reached = f"{r['reached']} of {r['seeds']} seeds"
            said = (
                f"reached {design.reference}'s final held-out curve error in {reached}; median cost to reach "
                f"{_pct(r['cost_to_reach_share'])} of {design.reference}'s, median wall "
                f"{_pct(r['wall_to_reach_share'])}"
            )
            cheaper = r["cost_to_reach_share"] is not None and r["cost_to_reach_share"] < 1
            verdict = "holds" if r["reached"] == r["seeds"] and cheaper else "not shown"
            body.append(
                [
                    r["arm"],
                    r["regime"],
                    r["method"],
                    CLAIMS["speedup"].format(ref=design.reference),
                    _pct(r["cost_share"]),
                    _pct(r["wall_share"]),
                    said,
                    "–",
                    verdict,
                ]
            )
            continue
        body.append(
            [
                r["arm"],
                r["regime"],
                r["method"],
                CLAIMS[r["claim"]].format(ref=design.reference),
                _pct(r["cost_share"]),
                _pct(r["wall_share"]),
                r["reading_rms"],
                r["reading_nmse"],
                r["claim_rms"],
            ]
        )
    head = ["arm", "regime", "method", "its claim", "cost", "wall", "held-out RMS (Nm)", "held-out nMSE", "claim (RMS)"]
    return table(head, body)
