"""The sensitivity study's numbers: per family, its spread over its settings and its level against the best
method at the same cost; per selective setting, its budget-matched partner. The words around them are
``selpres_studies.sensitivity``."""

from __future__ import annotations

import math

from selpres.report import Group, mean_curve, median, paired, reach, summarize
from selpres_studies._families import (
    Family,
    at_fixed_other_parameters,
    at_paper_total_epochs,
    families,
    matched_partner,
    paper_conventional,
    same_cost,
    schedule_terms,
    stages,
)

TOLERANCE = 0.10  # "within 10 % of its own best" (issue 10, item 3); a level within it is "the best level"
FAMILY, PAPER_TOTAL, FIXED = "family", "at the paper's total epochs", "at fixed other parameters"


def setting_summary(g: Group, target: float | None, base_cost: float | None) -> dict:
    """One setting: mean final held-out RMS over complete seeds (∞ if none), the relative 95 % half-width,
    diverged replicas, and presentations to the target (∞ if its mean curve never gets there)."""
    st = summarize(g.values("heldout").values())
    mean = st["mean"] if st["n"] else math.inf
    rel = (st["ci95"][1] - st["mean"]) / st["mean"] if st["ci95"][1] is not None and st["mean"] else None
    out = {"mean": mean, "n": st["n"], "rel_half": rel, "diverged": g.n_diverged, "to_target": None}
    if target is not None:
        out["to_target"] = reach(mean_curve(g), target, base_cost).get("presentations_to_target", math.inf)
    return out


def cost_points(fams: list[Family]) -> list[tuple[int, float, str, str]]:
    """Every setting of the given families as (cost: presentations with selection's charge, mean final held-out
    RMS, family, setting): what a family's level is measured against. A setting with no complete seed is left out."""
    out = []
    for fam in fams:
        for g in fam.members:
            st = summarize(g.values("heldout").values())
            if st["n"]:
                out.append((g.cost, st["mean"], fam.name, fam.label(g)))
    return out


def level(best: float, cost: int, points: list[tuple[int, float, str, str]]) -> dict:
    """A family's level: its best ÷ the lowest mean of any setting at the same cost (within 1 %), and which
    setting that is. ∞ when the family never finished; None when nothing else ran at that cost."""
    at = [p for p in points if same_cost(p[0], cost)]
    if not math.isfinite(best) or not at:
        return {"level": math.inf if not math.isfinite(best) else None, "level_presentations": cost}
    ref = min(at, key=lambda p: p[1])
    return {
        "level": best / ref[1],
        "level_presentations": cost,
        "level_reference_family": ref[2],
        "level_reference_setting": ref[3],
        "level_reference_heldout_nm": ref[1],
    }


def family_row(
    fam: Family, reference: Group | None, kind: str = FAMILY, points: list[tuple[int, float, str, str]] | None = None
) -> dict:
    """Best / median / worst over a family's settings, worst ÷ best, the fraction within 10 % of its best,
    its level against ``points`` (every setting of the topology), and time to the conventional run's final
    error."""
    ref_curve = mean_curve(reference) if reference else []
    target = ref_curve[-1][1] if ref_curve else None
    base_cost = ref_curve[-1][0] if ref_curve else None
    per = [(g, setting_summary(g, target, base_cost)) for g in fam.members]
    best_g, best = min(per, key=lambda p: p[1]["mean"])
    worst_g, worst = max(per, key=lambda p: p[1]["mean"])
    means = [s["mean"] for _, s in per]
    within = sum(m <= (1 + TOLERANCE) * best["mean"] for m in means) if math.isfinite(best["mean"]) else 0
    lo, hi = fam.presentations()
    rel = median(s["rel_half"] for _, s in per)
    spread = paired(worst_g.values("heldout"), best_g.values("heldout"))
    row = {
        "kind": kind,
        "family": fam.name,
        "topology": fam.topology,
        "staged": stages(fam.members[0]) > 1,
        "settings": len(per),
        "swept": fam.ranges_text(),
        "swept_terms": fam.swept_text(),
        "swept_keys": " ".join(fam.keys),
        "presentations_min": lo,
        "presentations_max": hi,
        "seeds_min": min(s["n"] for _, s in per),
        "seeds_max": max(s["n"] for _, s in per),
        "best_heldout_nm": best["mean"],
        "best_setting": fam.label(best_g),
        "median_heldout_nm": median(means),
        "worst_heldout_nm": worst["mean"],
        "worst_setting": fam.label(worst_g),
        "worst_over_best": worst["mean"] / best["mean"] if math.isfinite(best["mean"]) else None,
        "within_10pct": within,
        "within_10pct_fraction": within / len(per),
        **level(best["mean"], best_g.cost, points or []),
        "ci95_half_width_pct": None if rel is None else 100 * rel,
        "worst_minus_best_pairs": spread["n"],
        "worst_minus_best_nm": spread["mean"],
        "worst_minus_best_ci_lo": spread["ci95"][0],
        "worst_minus_best_ci_hi": spread["ci95"][1],
        "diverged_settings": sum(s["diverged"] > 0 for _, s in per),
        "diverged_replicas": sum(s["diverged"] for _, s in per),
        "target_method": reference.schedule if reference else None,
        "target_heldout_curve_rms_nm": target,
    }
    if target is not None:
        hits = [s["to_target"] for _, s in per]
        row.update(
            reach_settings=sum(math.isfinite(h) for h in hits),
            presentations_to_target_fastest=min(hits),
            presentations_to_target_median=median(hits),
        )
    return row


def sensitivity_rows(groups, topologies) -> list[dict]:
    """One row per family with two or more settings, per topology; after a staged family whose total epochs
    vary, its row at the paper's total; after one swept over other keys too, one row per fixed value of
    those keys (its spread over the schedule alone)."""
    rows = []
    fams = families(groups, topologies)
    for t in topologies:
        here = [f for f in fams if f.topology == t]
        ref, points = paper_conventional(groups, t), cost_points(here)
        for fam in here:
            if len(fam.members) < 2:
                continue
            rows.append(family_row(fam, ref, FAMILY, points))
            if (total := at_paper_total_epochs(fam)) is not None:
                rows.append(family_row(total, ref, PAPER_TOTAL, points))
            rows += [family_row(part, ref, FIXED, points) for part in at_fixed_other_parameters(fam)]
    return rows


def versus_matched_rows(groups, topologies) -> list[dict]:
    """Each setting of a staged family (two or more settings) beside its budget-matched partner: conventional
    training stopped at the same presentations, with the same other settings. Sorted by N, p, n_1, cost."""
    rows = []
    for fam in families(groups, topologies):
        if stages(fam.members[0]) == 1 or len(fam.members) < 2:
            continue
        stats = {g.schedule: summarize(g.values("heldout").values()) for g in fam.members}
        best = min((st["mean"] for st in stats.values() if st["n"]), default=None)
        for g in sorted(
            fam.members,
            key=lambda g: (sum(g.sched["epochs"]), g.sched["p"], g.sched["sizes"], g.sched["presentations"]),
        ):
            st, partner, terms = stats[g.schedule], matched_partner(groups, g), schedule_terms(g.sched)
            pst = summarize(partner.values("heldout").values()) if partner else {"n": 0, "mean": None}
            row = {
                "topology": fam.topology,
                "family": fam.name,
                "setting": fam.label(g),
                "p": terms["p"],
                "n1": terms["n_1"],
                "growth": terms["n_i growth"],
                "profile": terms["N_i profile"],
                "total_epochs": terms["N = ΣN_i"],
                "sizes": " ".join(map(str, g.sched["sizes"])),
                "epochs": " ".join(map(str, g.sched["epochs"])),
                "presentations": g.cost,
                "n": st["n"],
                "heldout_nm_mean": st["mean"],
                "heldout_nm_ci_lo": st["ci95"][0],
                "heldout_nm_ci_hi": st["ci95"][1],
                "within_10pct_of_family_best": None
                if best is None or st["mean"] is None
                else st["mean"] <= (1 + TOLERANCE) * best,
                "matched": partner.schedule if partner else None,
                "matched_presentations": partner.cost if partner else None,
                "matched_n": pst["n"],
                "matched_heldout_nm_mean": pst["mean"],
                "over_matched": st["mean"] / pst["mean"] if st["mean"] and pst["mean"] else None,
            }
            rows.append(row)
    return rows
