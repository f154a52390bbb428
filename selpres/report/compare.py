"""Comparisons and their statistics: paired differences by seed and their readings (the verdicts), mean
curves over seeds, and the cost at which each method first reaches a target error (time to target).

A verdict has three readings that are never merged: *better/worse by …* (the paired t-test rejects a
zero difference), *equivalent within ±m* (two one-sided tests reject a difference of m or more) and *no
detectable difference* (neither: an interval that contains 0 cannot rule out a real effect).

Rows are plain dicts, one CSV row each; the sections render them. Which method is the reference of a verdict,
and which runs are the targets of time to target, is the study's to say (its design): nothing here names one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from selpres.errors import ConfigError
from selpres.report.groups import SETS, Group, base
from selpres.report.markdown import signed_interval
from selpres.run.stats import holm, summarize, t_test, tost

ALPHA = 0.05  # every test's level: 95 % intervals for differences, 90 % intervals for TOST


@dataclass(frozen=True)
class Margin:
    """The equivalence margin m: a fraction of the mean final error, over the paired seeds, of the method a
    verdict is about (its reference), or a fixed value in Nm. An equivalence verdict means nothing without it, so the
    report prints the margin used beside every verdict."""

    value: float = 0.05
    relative: bool = True

    @classmethod
    def parse(cls, text: str) -> Margin:
        """ "5%" (of the reference method's mean) or "0.002" (Nm)."""
        t = str(text).strip()
        rel = t.endswith("%")
        try:
            v = float(t[:-1] if rel else t)
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and v > 0 and (v < 100 or not rel)):
            raise ConfigError(
                "--margin",
                text,
                "a percentage of the compared method's mean such as 5% (0 < p < 100) or a value in Nm such as "
                "0.002 (> 0)",
            )
        return cls(v / 100, True) if rel else cls(v, False)

    def of(self, ref_mean: float | None) -> float | None:
        if not self.relative:
            return self.value
        return None if ref_mean is None else self.value * abs(ref_mean)

    def describe(self, of: str) -> str:
        """The margin in words; ``of``: whose mean a relative margin is a fraction of."""
        if self.relative:
            return f"{self.value * 100:g} % of {of}'s mean final RMS over the paired seeds (per row and metric)"
        return f"{self.value:g} Nm (fixed with --margin)"


@dataclass(frozen=True)
class Options:
    """How verdicts are read: the equivalence margin, and whether p-values are Holm-adjusted per family; ``budget``:
    a cost (presentations) within which a sweep's best setting is named (``--budget``; None: the Pareto set only)."""

    margin: Margin = field(default_factory=Margin)
    holm: bool = False
    budget: int | None = None


def outcome(v: dict) -> str:
    """The reading in one word: better / worse (t-test), equivalent (TOST), no detectable difference, or too
    few pairs. ``reading`` puts the same rule in words."""
    if v["n"] < 2 or v.get("p") is None:
        return "too few pairs"
    if v["p"] < ALPHA:
        return "better" if v["mean"] < 0 else "worse"
    return "equivalent" if v.get("p_tost") is not None and v["p_tost"] < ALPHA else "no detectable difference"


def reading(v: dict, name: str, unit: str = "Nm") -> str:
    """Plain words for a paired difference name − other (negative = ``name`` has the lower error).

    ``v``: n, mean, ci95 and other_mean of the differences; margin, p (paired t) and p_tost, already
    Holm-adjusted when ``holm``; ci90 (the TOST interval)."""
    said = outcome(v)
    if said == "too few pairs":
        return f"too few pairs ({v['n']}) for an interval"
    d, m, holm_ = v["mean"], v.get("margin"), v.get("holm", False)
    equivalent = v.get("p_tost") is not None and v["p_tost"] < ALPHA  # also when the t-test already decided
    iv95 = signed_interval(*v["ci95"])
    adj = f"; Holm p = {v['p']:.2g}" if holm_ else ""
    if said in ("better", "worse"):
        pct = f"{abs(d) / v['other_mean'] * 100:.1f} %; " if v.get("other_mean") else ""
        within = f"; yet within the margin: equivalent within ±{m:.4f} {unit}" if equivalent else ""
        return f"{name} {said} by {abs(d):.4f} {unit} ({pct}95 % interval {iv95}{adj}){within}"
    if said == "equivalent":
        tost_adj = f"; Holm TOST p = {v['p_tost']:.2g}" if holm_ else ""
        return f"equivalent within ±{m:.4f} {unit} (90 % interval {signed_interval(*v['ci90'])}{tost_adj})"
    after = " after Holm's correction" if holm_ and not v["ci95"][0] <= 0 <= v["ci95"][1] else ""
    not_eq = f"; not shown equivalent within ±{m:.4f} {unit}" if m else ""
    return f"no detectable difference{after} (95 % interval {iv95}{adj}){not_eq}"


def paired(a: dict[int, float], b: dict[int, float], margin: Margin = Margin()) -> dict:
    """a[s] − b[s] over the seeds in both: summary, paired t-test and TOST against the margin."""
    seeds = sorted(set(a) & set(b))
    diffs = [a[s] - b[s] for s in seeds]
    st = summarize(diffs)

    def mean(values: dict[int, float]) -> float | None:
        return sum(values[s] for s in seeds) / len(seeds) if seeds else None

    m = margin.of(mean(a))
    eq = tost(diffs, m, ALPHA) if m else {"p": None, "ci": [None, None]}
    return {
        "n": st["n"],
        "mean": st["mean"],
        "std": st["std"],
        "ci95": st["ci95"],
        "other_mean": mean(b),
        "margin": m,
        "p": t_test(diffs)["p"],
        "p_tost": eq["p"],
        "ci90": eq["ci"],
    }


def comparisons(methods: list[str], reference: str) -> list[tuple[str, str]]:
    """(a, b) pairs to compare as a − b: every variant of the ``reference`` method (its label starts with its
    name) against every other method; a sweep of the reference's variants alone compares each with the first."""
    refs = [m for m in methods if base(m) == reference]
    others = [m for m in methods if base(m) != reference]
    if others:
        return [(r, o) for r in refs for o in others]
    return [(r, refs[0]) for r in refs[1:]]


def verdict_rows(groups, topologies, methods, reference: str, options: Options = Options()) -> list[dict]:
    """The ``reference`` method against every other (:func:`comparisons`), per topology, paired by seed,
    held-out and test-10 (Nm).

    A family is one metric across the whole table (all topologies and comparisons); its size is recorded,
    and with ``options.holm`` the t-test and TOST p-values are Holm-adjusted within it."""
    rows, found = [], []  # found: (row, set, paired(...)) for every comparison with results on both sides
    for t in topologies:
        for a, b in comparisons(methods, reference):
            ga, gb = groups.get((t, a)), groups.get((t, b))
            row = {"topology": t, "comparison": f"{a} vs {b}"}
            rows.append(row)
            if ga is None or gb is None or ga.sched is None or gb.sched is None:
                missing = a if ga is None or ga.sched is None else b
                row["reading_heldout"] = f"no results for {missing}"
                continue
            row["cost_ratio"] = ga.cost / gb.cost  # measured: presented and charged, each side
            for set_, _ in SETS:
                v = paired(ga.values(set_), gb.values(set_), options.margin)
                row.update(paired_columns(set_, v))
                found.append((row, set_, v, base(a)))
    for set_, _ in SETS:
        adjust_family([(row, v) for row, s, v, _ in found if s == set_], set_, options)
    for row, set_, v, name in found:
        row[f"reading_{set_}"] = reading({**v, "holm": options.holm}, name=name)
    return rows


def paired_columns(prefix: str, v: dict) -> dict:
    """A :func:`paired` result as CSV columns named ``<prefix>_…`` (prefix: the metric, e.g. "heldout")."""
    return {
        f"{prefix}_pairs": v["n"],
        f"{prefix}_diff_mean": v["mean"],
        f"{prefix}_diff_std": v["std"],
        f"{prefix}_ci_lo": v["ci95"][0],
        f"{prefix}_ci_hi": v["ci95"][1],
        f"{prefix}_other_mean": v["other_mean"],
        f"{prefix}_margin": v["margin"],
        f"{prefix}_p": v["p"],
        f"{prefix}_tost_p": v["p_tost"],
        f"{prefix}_ci90_lo": v["ci90"][0],
        f"{prefix}_ci90_hi": v["ci90"][1],
    }


def adjust_family(found: list[tuple[dict, dict]], prefix: str, options: Options) -> None:
    """One family of tests ([(row, paired(...))]; those without a p-value are not tests): its size into
    ``<prefix>_family_size`` of each row and, with ``options.holm``, the t-test and TOST p-values
    Holm-adjusted within it (in ``v`` and as ``<prefix>_p_holm`` / ``<prefix>_tost_p_holm``)."""
    family = [(row, v) for row, v in found if v["p"] is not None]
    for key in ("p", "p_tost"):
        tested = [(row, v) for row, v in family if v[key] is not None]
        adjusted = holm([v[key] for _, v in tested]) if options.holm else [v[key] for _, v in tested]
        for (row, v), p in zip(tested, adjusted):
            v[key] = p
            if options.holm:
                row[f"{prefix}_{'p' if key == 'p' else 'tost_p'}_holm"] = p
    for row, _ in family:
        row[f"{prefix}_family_size"] = len(family)


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


def reach(curve: list, target: float, base_cost: float | None, base_name: str = "base") -> dict:
    """Where a mean curve first gets to ``target``: the curve point at or below it and the one before, and its
    cost as a fraction of ``base_cost`` (``fraction_of_<base_name>_cost``)."""
    hit = next((i for i, (_, v, _) in enumerate(curve) if v <= target), None)
    if not curve:
        return {"reached": "no curve"}
    if hit is None:
        return {"reached": "not reached"}
    pres = curve[hit][0]
    return {
        "reached": "yes",
        "presentations_to_target": pres,
        "previous_curve_point": curve[hit - 1][0] if hit else 0,
        f"fraction_of_{base_name}_cost": pres / base_cost if base_cost else None,
    }


def time_to_target_rows(
    groups, topologies, methods, targets: list[tuple[str, dict]], base: dict, base_name: str
) -> list[dict]:
    """Presentations each method needs until its mean held-out curve first reaches a target. ``targets``: a
    study's [(what the target is called, {topology: the run whose final mean curve value is the target, or
    None})]; ``base``: {topology: the run whose total presentations the costs are fractions of}, called
    ``base_name`` in the columns. A target absent from every topology gives no rows; absent from one, a "no
    target" row there."""
    rows = []
    for kind, found in targets:
        if not any(found.values()):
            continue
        for t in topologies:
            tgt, base_group = found[t], base[t]
            target_method = tgt.schedule if tgt else kind
            tgt_curve = mean_curve(tgt) if tgt else []
            base_curve = mean_curve(base_group) if base_group else []
            if not tgt_curve:
                rows.append(
                    {
                        "target_method": target_method,
                        "topology": t,
                        "method": "all",
                        "reached": f"no {target_method} held-out curve: no target",
                    }
                )
                continue
            base_cost, target = (base_curve[-1][0] if base_curve else None), tgt_curve[-1][1]
            for m in methods:
                g = groups.get((t, m))
                curve = mean_curve(g) if g else []
                row = {
                    "target_method": target_method,
                    "topology": t,
                    "method": m,
                    "target_heldout_curve_rms_nm": target,
                    f"{base_name}_presentations": base_cost,
                    "final_curve_rms_nm": curve[-1][1] if curve else None,
                    "method_presentations": g.sched["presentations"] if g and g.sched else None,
                }
                row.update(reach(curve, target, base_cost, base_name))
                rows.append(row)
    return rows
