"""Comparisons and their statistics: paired differences by seed and their readings (the verdicts), mean
curves over seeds, and the cost at which each method first reaches a target error (time to target).

Rows are plain dicts, one CSV row each; the sections render them.
"""

from __future__ import annotations

from selpres.report.groups import BASELINE, REFERENCE, SETS, Group, base
from selpres.stats import summarize


def reading(s: dict, ref_mean: float | None, unit: str = "Nm", name: str = REFERENCE) -> str:
    """Plain words for a paired difference name − other (negative = ``name`` has the lower error)."""
    if s["n"] < 2 or s["ci95"][0] is None:
        return f"too few pairs ({s['n']}) for an interval"
    lo, hi = s["ci95"]
    if lo <= 0 <= hi:
        return "no detectable difference"
    d = s["mean"]
    pct = f" ({abs(d) / ref_mean * 100:.1f} %)" if ref_mean else ""
    return f"{name} {'better' if d < 0 else 'worse'} by {abs(d):.4f} {unit}{pct}"


def paired(a: dict[int, float], b: dict[int, float]) -> tuple[dict, float | None]:
    """Summary of a[s] − b[s] over the seeds in both, and the mean of b over those seeds."""
    seeds = sorted(set(a) & set(b))
    st = summarize(a[s] - b[s] for s in seeds)
    return st, (sum(b[s] for s in seeds) / len(seeds) if seeds else None)


def comparisons(methods: list[str]) -> list[tuple[str, str]]:
    """(a, b) pairs to compare as a − b: every selective variant against every other method; a sweep of
    selective variants alone compares each variant with the first."""
    refs = [m for m in methods if base(m) == REFERENCE]
    others = [m for m in methods if base(m) != REFERENCE]
    if others:
        return [(r, o) for r in refs for o in others]
    return [(r, refs[0]) for r in refs[1:]]


def verdict_rows(groups, topologies, methods) -> list[dict]:
    """Selective against every other method, per topology, paired by seed, held-out and test-10 (Nm)."""
    rows = []
    for t in topologies:
        for a, b in comparisons(methods):
            ga, gb = groups.get((t, a)), groups.get((t, b))
            row = {"topology": t, "comparison": f"{a} vs {b}"}
            if ga is None or gb is None or ga.sched is None or gb.sched is None:
                missing = a if ga is None or ga.sched is None else b
                row["reading_heldout"] = f"no results for {missing}"
                rows.append(row)
                continue
            row["cost_ratio"] = ga.sched["presentations"] / gb.sched["presentations"]
            for set_, _ in SETS:
                st, ref = paired(ga.values(set_), gb.values(set_))
                row.update({f"{set_}_pairs": st["n"], f"{set_}_diff_mean": st["mean"],
                            f"{set_}_diff_std": st["std"], f"{set_}_ci_lo": st["ci95"][0],
                            f"{set_}_ci_hi": st["ci95"][1], f"{set_}_other_mean": ref,
                            f"reading_{set_}": reading(st, ref, name=base(a))})
            rows.append(row)
    return rows


def mean_curve(g: Group) -> list[tuple[int, float, dict]]:
    """[(cumulative presentations, mean held-out curve RMS Nm, summarize(...))] over complete seeds, by
    epoch."""
    pts: dict[int, tuple[int, list[float]]] = {}
    for s in g.complete_seeds:
        for ep, pres, v in g.curves.get(s, []):
            pts.setdefault(ep, (pres, []))[1].append(v)
    out = []
    for ep in sorted(pts):
        pres, vals = pts[ep]
        st = summarize(vals)
        out.append((pres, st["mean"], st))
    return out


def _reach_row(curve: list, target: float, base_cost: float | None) -> dict:
    """Where a mean curve first gets to ``target``: the curve point at or below it and the one before."""
    hit = next((i for i, (_, v, _) in enumerate(curve) if v <= target), None)
    if not curve:
        return {"reached": "no curve"}
    if hit is None:
        return {"reached": "not reached"}
    pres = curve[hit][0]
    return {"reached": "yes", "presentations_to_target": pres,
            "previous_curve_point": curve[hit - 1][0] if hit else 0,
            "fraction_of_conventional_cost": pres / base_cost if base_cost else None}


def time_to_target_rows(groups, topologies, methods) -> list[dict]:
    """Presentations each method needs until its mean held-out curve first reaches a target: the
    conventional run's final value (the issue's question), and each selective variant's final value (how
    long the other methods take to get as far as selective presentation does: the speed-up in honest form)."""
    rows = []
    targets = ([BASELINE] if BASELINE in methods else []) + [m for m in methods if base(m) == REFERENCE]
    for target_method in targets:
        for t in topologies:
            tgt = groups.get((t, target_method))
            tgt_curve = mean_curve(tgt) if tgt else []
            base_group = groups.get((t, BASELINE))
            base_curve = mean_curve(base_group) if base_group else []
            if not tgt_curve:
                rows.append({"target_method": target_method, "topology": t, "method": "all",
                             "reached": f"no {target_method} held-out curve: no target"})
                continue
            base_cost, target = (base_curve[-1][0] if base_curve else None), tgt_curve[-1][1]
            for m in methods:
                g = groups.get((t, m))
                curve = mean_curve(g) if g else []
                row = {"target_method": target_method, "topology": t, "method": m,
                       "target_heldout_curve_rms_nm": target, f"{BASELINE}_presentations": base_cost,
                       "final_curve_rms_nm": curve[-1][1] if curve else None,
                       "method_presentations": g.sched["presentations"] if g and g.sched else None}
                row.update(_reach_row(curve, target, base_cost))
                rows.append(row)
    return rows
