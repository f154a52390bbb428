"""The modern study's judgements (:mod:`selpres_studies.modern`): each method on its own published claim against
the reference at full cost, and Holm's correction over the whole family (the compute-matched comparisons too).

Every comparison is of the **converged error** (issue 40), chosen before the run (``modern.yaml``): paired by seed
over the seeds where neither run stalled, the ``design.trim`` trimmed mean of the differences with its
Tukey–McLaughlin test (:func:`selpres.run.stats.trimmed`); the plain mean over every pair, stalls included, beside
it. Stalls are their own outcome (:mod:`selpres_studies._modern_stalls`)."""

from __future__ import annotations

import math

from selpres.report import (
    ALPHA,
    Options,
    adjust_family,
    median,
    outcome,
    paired_columns,
    reading,
    signed_interval,
    summarize,
    table,
    trimmed,
)
from selpres_studies._modern_cells import DESIGN, METRICS, Cell, Design, _arm_regimes


def converged_paired(c: Cell, other: Cell, metric: str, options: Options, design: Design, of: str = "self") -> dict:
    """c − other over the seeds where neither stalled: the ``design.trim`` trimmed mean of the differences, its
    95 % interval and two-sided p, and TOST against the margin, a share (``options.margin``) of the converged
    trimmed mean of ``c`` (``of="self"``: a compute-matched comparison) or of ``other`` (``of="other"``: a claim is
    about matching the reference). The keys of :func:`selpres.report.compare.paired`, plus the plain mean over every
    pair (``plain_*``, stalls included) and how many pairs a stall left out (``stalled_pairs``)."""
    a, b = c.values(metric), other.values(metric)
    seeds = sorted(set(a) & set(b))
    ok = [s for s in seeds if c.stalled.get(s) is False and other.stalled.get(s) is False]
    loc = trimmed([(a if of == "self" else b)[s] for s in ok], design.trim)["mean"]
    m = options.margin.of(loc)
    t = trimmed([a[s] - b[s] for s in ok], design.trim, margin=m)
    plain = summarize(a[s] - b[s] for s in seeds)
    return {
        "n": t["n"],
        "mean": t["mean"],
        "std": None,
        "se": t["se"],
        "ci95": t["ci95"],
        "other_mean": trimmed([b[s] for s in ok], design.trim)["mean"],
        "margin": m,
        "p": t["p"],
        "p_tost": t["p_tost"],
        "p_upper": t.get("p_upper"),
        "ci90": t["ci90"],
        "plain_n": plain["n"],
        "plain_mean": plain["mean"],
        "plain_ci95": plain["ci95"],
        "stalled_pairs": len(seeds) - len(ok),
    }


def converged_columns(prefix: str, v: dict) -> dict:
    """:func:`converged_paired` as CSV columns: :func:`selpres.report.compare.paired_columns` and the plain mean's."""
    return {
        **paired_columns(prefix, v),
        f"{prefix}_stalled_pairs": v["stalled_pairs"],
        f"{prefix}_plain_pairs": v["plain_n"],
        f"{prefix}_plain_diff_mean": v["plain_mean"],
        f"{prefix}_plain_ci_lo": v["plain_ci95"][0],
        f"{prefix}_plain_ci_hi": v["plain_ci95"][1],
    }


def _against_reference(c: Cell, ref: Cell, metric: str, options: Options, one_sided: bool, design: Design) -> dict:
    """c − ref, converged (:func:`converged_paired`), the margin a share of the *reference's* converged error (a claim
    is about matching it); ``one_sided``: the equivalence test is the non-inferiority half (H0: Δ ≥ +m), for
    "comparable or better"."""
    v = converged_paired(c, ref, metric, options, design, of="other")
    if one_sided and v["p_tost"] is not None:
        v["p_tost"] = v["p_upper"]
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
                    m: _against_reference(c, ref, m, options, kind == "comparable", design) for m, _, _ in METRICS
                }
                for metric, v in row["_tests"].items():
                    row.update(converged_columns(metric, v))
            rows.append(row)
    return rows


def speedup(c: Cell, ref: Cell) -> dict:
    """Seed by seed, where the method's held-out curve first reaches the reference's final held-out curve value
    (the same seed's), as shares of the reference's final cost and seconds: medians over the seeds that reach it.
    Seeds where either stalled are left out (a stalled reference's final error is no target)."""
    cost, secs, seeds = [], [], 0
    for seed, ref_curve in ref.curves.items():
        curve = c.curves.get(seed)
        if not curve or not ref_curve or c.stalled.get(seed) or ref.stalled.get(seed):
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
