"""Sensitivity: how much each family's final error depends on where in its range its parameters are set,
and a verdict on the paper's sentence "the proposed method is not very sensitive to actual values of
parameters like p, N_i and n_i" (as compared with speed-up techniques that rely on exact values).

Shown when some family has more than one setting (:mod:`selpres.report.families`).
"""

from __future__ import annotations

import math

from selpres.report.compare import mean_curve, paired, reach
from selpres.report.context import Context, Section
from selpres.report.families import (SCHEDULE, SELECTIVE, Family, at_fixed_other_parameters, families,
                                     paper_conventional, stages)
from selpres.report.groups import Group
from selpres.report.markdown import fmt, signed_interval, table
from selpres.stats import median, summarize

TOLERANCE = 0.10  # "within 10 % of its own best" (issue 10, item 3)

NOTE = (
    "A *family* is one method with its parameters swept (see `selpres/report/families.py`): the schedule's "
    "kind (one stage = conventional; several stages in the stratified order = selective presentation) and "
    "the optimizer (`optim.name`); one-stage families are split by their cost. A *setting* is one swept "
    "point; its error is the mean final held-out RMS (Nm) over its complete seeds. Best, median and worst "
    "are over the family's settings; *within 10 %* counts the settings whose mean is at most 1.1 × the "
    "family's best; *±95 %* is the median over settings of the half-width of a setting mean's 95 % "
    "t-interval (as a percentage of the mean; unpaired). *Worst − best, paired*: the worst setting minus the "
    "best, seed by seed, with its 95 % t-interval: above 0, the spread exceeds the seeds' noise. A setting "
    "with no complete seed counts as infinitely bad (∞); one that lost "
    "some seeds to divergence is counted under *diverged* and its mean covers the rest. *Time to target*: "
    "the presentations at which a setting's mean held-out curve first reaches the final curve RMS of the "
    "paper's conventional run (150,300 t, lr 0.15, momentum 0.9; else the only SGD run of 150 epochs) of "
    "the same topology; the fastest "
    "setting, and the median over all settings (a setting that never reaches it counts as never). Rows "
    "*at …* hold a staged family's non-schedule parameters fixed, so their spread is over p, N_i, n_i "
    "alone."
)


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


def family_row(fam: Family, reference: Group | None, kind: str = "family") -> dict:
    """Best / median / worst over a family's settings, worst ÷ best, the fraction within 10 % of its best,
    and time to the conventional run's final error."""
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
        "kind": kind, "family": fam.name, "topology": fam.topology, "staged": stages(fam.members[0]) > 1,
        "settings": len(per),
        "swept": fam.ranges_text(), "swept_keys": " ".join(fam.keys),
        "presentations_min": lo, "presentations_max": hi,
        "seeds_min": min(s["n"] for _, s in per), "seeds_max": max(s["n"] for _, s in per),
        "best_heldout_nm": best["mean"], "best_setting": fam.label(best_g),
        "median_heldout_nm": median(means),
        "worst_heldout_nm": worst["mean"], "worst_setting": fam.label(worst_g),
        "worst_over_best": worst["mean"] / best["mean"] if math.isfinite(best["mean"]) else None,
        "within_10pct": within, "within_10pct_fraction": within / len(per),
        "ci95_half_width_pct": None if rel is None else 100 * rel,
        "worst_minus_best_pairs": spread["n"], "worst_minus_best_nm": spread["mean"],
        "worst_minus_best_ci_lo": spread["ci95"][0], "worst_minus_best_ci_hi": spread["ci95"][1],
        "diverged_settings": sum(s["diverged"] > 0 for _, s in per),
        "diverged_replicas": sum(s["diverged"] for _, s in per),
        "target_method": reference.schedule if reference else None, "target_heldout_curve_rms_nm": target,
    }
    if target is not None:
        hits = [s["to_target"] for _, s in per]
        row.update(reach_settings=sum(math.isfinite(h) for h in hits),
                   presentations_to_target_fastest=min(hits), presentations_to_target_median=median(hits))
    return row


def sensitivity_rows(groups, topologies) -> list[dict]:
    """One row per family with two or more settings, per topology; after a staged family swept over other
    keys too, one row per fixed value of those keys (its spread over the schedule alone)."""
    rows = []
    for fam in families(groups, topologies):
        if len(fam.members) < 2:
            continue
        ref = paper_conventional(groups, fam.topology)
        rows.append(family_row(fam, ref))
        rows += [family_row(part, ref, kind="at fixed other parameters")
                 for part in at_fixed_other_parameters(fam)]
    return rows


def _ratio(x: float | None) -> str:
    return "n/a" if x is None else ("∞" if x == math.inf else f"{x:.3f}")


def _nm(x: float) -> str:
    return "∞ (no seed finished)" if x == math.inf else fmt(x)


def _to_target(r: dict) -> str:
    if r["target_heldout_curve_rms_nm"] is None:
        return "no target (no conventional run of the paper's in this topology)"
    fastest, med = r["presentations_to_target_fastest"], r["presentations_to_target_median"]
    if fastest == math.inf:
        return f"0/{r['settings']} reach"
    return (f"{r['reach_settings']}/{r['settings']} reach; fastest {fastest:,.0f}; median "
            + ("never" if med == math.inf else f"{med:,.0f}"))


def _resolved(r: dict) -> bool:
    """Whether the worst setting is worse than the best beyond the seeds' noise (paired interval above 0)."""
    return r["worst_minus_best_ci_lo"] is not None and r["worst_minus_best_ci_lo"] > 0


def _spread(r: dict) -> str:
    if r["worst_minus_best_ci_lo"] is None:
        return f"n/a ({r['worst_minus_best_pairs']} pairs)"
    lo, hi = r["worst_minus_best_ci_lo"], r["worst_minus_best_ci_hi"]
    return f"{r['worst_minus_best_nm']:+.4f} {signed_interval(lo, hi)}"


def sensitivity_markdown(rows: list[dict]) -> str:
    head = ["family", "topology", "settings", "swept (ranges)", "presentations", "best (setting)", "median",
            "worst (setting)", "worst ÷ best", "worst − best, paired [95 % CI]", "within 10 % of best",
            "±95 %", "time to conventional's final",
            "diverged settings (replicas)"]
    body = []
    for r in rows:
        lo, hi = r["presentations_min"], r["presentations_max"]
        cost = f"{lo:,}" if lo == hi else f"{lo:,}–{hi:,}"
        body.append([
            r["family"], r["topology"], str(r["settings"]), r["swept"] or "—", cost,
            f"{_nm(r['best_heldout_nm'])} ({r['best_setting']})", _nm(r["median_heldout_nm"]),
            f"{_nm(r['worst_heldout_nm'])} ({r['worst_setting']})", _ratio(r["worst_over_best"]), _spread(r),
            f"{r['within_10pct']}/{r['settings']} ({100 * r['within_10pct_fraction']:.0f} %)",
            "n/a" if r["ci95_half_width_pct"] is None else f"{r['ci95_half_width_pct']:.1f} %",
            _to_target(r), f"{r['diverged_settings']} ({r['diverged_replicas']})"])
    return table(head, body)


def _quote(r: dict) -> str:
    return (f"{r['family']}: worst ÷ best {_ratio(r['worst_over_best'])}, "
            f"{100 * r['within_10pct_fraction']:.0f} % within 10 % (over {r['swept']})")


def _inf(x: float | None) -> float:
    """A ratio, None (a setting that never finished) standing for ∞."""
    return math.inf if x is None else x


def _span(values: list[float], show) -> str:
    lo, hi = min(values), max(values)
    return show(lo) if lo == hi else f"{show(lo)}–{show(hi)}"


def _schedule_alone(rows: list[dict], sel: dict) -> str:
    """Selective presentation's spread over p, N_i, n_i alone, from its rows at fixed other parameters."""
    parts = [r for r in rows if r["topology"] == sel["topology"] and r["kind"] != "family"
             and r["family"].startswith(SELECTIVE + " at ")]
    if not parts:
        return ""
    fixed = ", ".join(k for k in sel["swept_keys"].split() if not k.startswith(SCHEDULE))
    ratios = _span([_inf(r["worst_over_best"]) for r in parts], _ratio)
    within = _span([100 * r["within_10pct_fraction"] for r in parts], lambda x: f"{x:.0f}") + " %"
    return (f"With {fixed} held fixed ({len(parts)} values), selective presentation's spread over the "
            f"schedule alone is worst ÷ best {ratios}, with {within} of settings within 10 % of the best. ")


def _reading(sel: dict, rivals: list[dict]) -> str:
    ratio_ok = all(_inf(sel["worst_over_best"]) <= _inf(r["worst_over_best"]) for r in rivals)
    within_ok = all(sel["within_10pct_fraction"] >= r["within_10pct_fraction"] for r in rivals)
    if ratio_ok and within_ok:
        return ("consistent with the sentence over these ranges: selective presentation is at least as "
                "insensitive as every rival by both measures")
    if not ratio_ok and not within_ok:
        return ("not supported over these ranges: by each measure some rival is less sensitive than "
                "selective presentation")
    better, worse = ("worst ÷ best", "within 10 %") if ratio_ok else ("within 10 %", "worst ÷ best")
    return (f"mixed over these ranges: selective presentation is at least as insensitive as every rival by "
            f"{better}, not by {worse}")


def verdict_text(rows: list[dict], topology: str) -> str:
    """The paper's sentence read against one topology's families, in plain words, with the ranges."""
    main = [r for r in rows if r["topology"] == topology and r["kind"] == "family"]
    if not main:
        return f"**{topology}.** No family with more than one setting."
    sel = next((r for r in main if r["family"] == SELECTIVE), None)
    rivals = [r for r in main if not r["staged"]]  # the one-stage speed-up techniques, not other orders
    by_ratio = min(main, key=lambda r: _inf(r["worst_over_best"]))
    by_within = max(main, key=lambda r: r["within_10pct_fraction"])
    text = (f"**{topology}.** Least sensitive by worst ÷ best: **{by_ratio['family']}** "
            f"({_ratio(by_ratio['worst_over_best'])}); by the fraction of settings within 10 % of the "
            f"family's own best: **{by_within['family']}** "
            f"({100 * by_within['within_10pct_fraction']:.0f} %). "
            + "; ".join(_quote(r) for r in main) + ". ")
    if sel is None:
        return text + ("No selective presentation family with more than one setting: the sentence is not "
                       "tested.")
    if not any(k.startswith(SCHEDULE) for k in sel["swept_keys"].split()):
        return text + ("Selective presentation's swept keys include none of p, N_i, n_i (schedule.*): the "
                       "sentence is not tested.")
    text += _schedule_alone(rows, sel)
    if not rivals:
        return text + ("No rival family (one-stage training, an optimizer swept over its parameters) "
                       "with more than one setting: the comparison the sentence makes cannot be made here.")
    resolved = [r["family"] for r in main if _resolved(r)]
    return text + (
        f"Reading: {_reading(sel, rivals)}. The verdict depends on the ranges: widening a family's range can "
        "only raise its worst ÷ best, so a rival swept over a narrower range looks less sensitive. Worst − "
        f"best, paired by seed, has a 95 % interval above 0 for {len(resolved)} of {len(main)} families"
        + (f" ({', '.join(resolved)})" if resolved else "")
        + "; where it does not, the family's spread is within the seeds' noise.")


def section(ctx: Context) -> Section | None:
    rows = sensitivity_rows(ctx.groups, ctx.topologies)
    if not rows:
        return None
    verdicts = [verdict_text(rows, t) for t in ctx.topologies if any(r["topology"] == t for r in rows)]
    title = ("Sensitivity: is selective presentation \"not very sensitive to p, N_i and n_i\"? "
             "(final held-out RMS, Nm)")
    return Section(title, [sensitivity_markdown(rows), NOTE, "\n\n".join(verdicts)],
                   csv={"sensitivity.csv": rows})
