"""Sensitivity: how much each family's final error depends on where in its range its parameters are set,
and a verdict on the paper's sentence "the proposed method is not very sensitive to actual values of
parameters like p, N_i and n_i" (as compared with speed-up techniques that rely on exact values).

Two things are kept apart. *Spread*: worst ÷ best over a family's range, and the share of its settings
within 10 % of its own best. *Level*: its best ÷ the best of any family at that cost. A family that is bad
everywhere has a small spread without being insensitive in the sense that matters; the verdict compares
selective presentation's spread with that of the rivals that reach the best level. Because N = ΣN_i
changes the cost, selective presentation is also read at the paper's N = 150, and each of its settings is
set against conventional training stopped at the same cost (its budget-matched partner).

Shown when some family has more than one setting (:mod:`selpres_studies._families`).
"""

from __future__ import annotations

import math

from selpres.report import Context, Section, fmt, signed_interval, table
from selpres_studies import _error_cost as error_cost
from selpres_studies._families import (
    BUDGET_MATCHED,
    SCHEDULE,
    SELECTIVE,
)
from selpres_studies._sensitivity import FAMILY, FIXED, PAPER_TOTAL, TOLERANCE, sensitivity_rows, versus_matched_rows

NOTE = (
    "A *family* is one method with its parameters swept (see `studies/selpres_studies/_families.py`): the schedule's "
    "kind (one stage = conventional; several stages in the stratified order = selective presentation) and "
    "the optimizer (`optim._target_`); one-stage families are split by their cost, except conventional training "
    "stopped at each staged run's cost, which is one family (*budget-matched*). A *setting* is one swept "
    "point; its error is the mean final held-out RMS (Nm) over its complete seeds. Best, median and worst "
    "are over the family's settings; *within 10 %* counts the settings whose mean is at most 1.1 × the "
    "family's best (spread); *level* is the family's best ÷ the lowest mean of any setting of any family at "
    "the cost of that best (within 1 %): 1.000 means no method does better at that cost, and a family far "
    "above 1 is bad over its whole range, whatever its spread. *±95 %* is the median over settings of the "
    "half-width of a setting mean's 95 % t-interval (as a percentage of the mean; unpaired). *Worst − "
    "best, paired*: the worst setting minus the best, seed by seed, with its 95 % t-interval: above 0, the "
    "spread exceeds the seeds' noise. A setting with no complete seed counts as infinitely bad (∞); one that "
    "lost some seeds to divergence is counted under *diverged* and its mean covers the rest. *Time to "
    "target*: the presentations at which a setting's mean held-out curve first reaches the final curve RMS "
    "of the paper's conventional run (150,300 t, lr 0.15, momentum 0.9; else the only SGD run of 150 epochs) of "
    "the same topology; the fastest setting, and the median over all settings (a setting that never "
    "reaches it counts as never). The row *at ΣN_i = 150* keeps selective presentation's total epochs at "
    "the paper's (its p, n_i and N_i profile varied); rows *at …* of other keys hold a staged family's "
    "non-schedule parameters fixed, so their spread is over p, N_i, n_i alone."
)


def _ratio(x: float | None) -> str:
    return "n/a" if x is None else ("∞" if x == math.inf else f"{x:.3f}")


def _level(x: float | None) -> str:
    return "n/a" if x is None else ("∞" if x == math.inf else f"{x:.2f}")


def _nm(x: float) -> str:
    return "∞ (no seed finished)" if x == math.inf else fmt(x)


def _to_target(r: dict) -> str:
    if r["target_heldout_curve_rms_nm"] is None:
        return "no target (no conventional run of the paper's in this topology)"
    fastest, med = r["presentations_to_target_fastest"], r["presentations_to_target_median"]
    if fastest == math.inf:
        return f"0/{r['settings']} reach"
    return f"{r['reach_settings']}/{r['settings']} reach; fastest {fastest:,.0f}; median " + (
        "never" if med == math.inf else f"{med:,.0f}"
    )


def _resolved(r: dict) -> bool:
    """Whether the worst setting is worse than the best beyond the seeds' noise (paired interval above 0)."""
    return r["worst_minus_best_ci_lo"] is not None and r["worst_minus_best_ci_lo"] > 0


def _spread(r: dict) -> str:
    if r["worst_minus_best_ci_lo"] is None:
        return f"n/a ({r['worst_minus_best_pairs']} pairs)"
    lo, hi = r["worst_minus_best_ci_lo"], r["worst_minus_best_ci_hi"]
    return f"{r['worst_minus_best_nm']:+.4f} {signed_interval(lo, hi)}"


def _within(r: dict) -> str:
    return f"{r['within_10pct']}/{r['settings']} ({100 * r['within_10pct_fraction']:.0f} %)"


def sensitivity_markdown(rows: list[dict]) -> str:
    head = [
        "family",
        "topology",
        "settings",
        "swept (ranges)",
        "presentations",
        "best (setting)",
        "median",
        "worst (setting)",
        "worst ÷ best",
        "within 10 % of best",
        "level: best ÷ best at that cost",
        "worst − best, paired [95 % CI]",
        "±95 %",
        "time to conventional's final",
        "diverged settings (replicas)",
    ]
    body = []
    for r in rows:
        lo, hi = r["presentations_min"], r["presentations_max"]
        cost = f"{lo:,}" if lo == hi else f"{lo:,}–{hi:,}"
        body.append(
            [
                r["family"],
                r["topology"],
                str(r["settings"]),
                r["swept_terms"] or "—",
                cost,
                f"{_nm(r['best_heldout_nm'])} ({r['best_setting']})",
                _nm(r["median_heldout_nm"]),
                f"{_nm(r['worst_heldout_nm'])} ({r['worst_setting']})",
                _ratio(r["worst_over_best"]),
                _within(r),
                _level(r["level"]),
                _spread(r),
                "n/a" if r["ci95_half_width_pct"] is None else f"{r['ci95_half_width_pct']:.1f} %",
                _to_target(r),
                f"{r['diverged_settings']} ({r['diverged_replicas']})",
            ]
        )
    return table(head, body)


def versus_matched_markdown(rows: list[dict]) -> str:
    """Each staged setting beside conventional training at the same cost."""
    head = [
        "family",
        "topology",
        "p",
        "n_i",
        "N_i",
        "N",
        "presentations",
        "held-out RMS Nm [95 % CI]",
        "within 10 % of family best",
        "budget-matched conventional Nm",
        "÷ budget-matched",
    ]
    body = []
    for r in rows:
        ci = "" if r["heldout_nm_ci_lo"] is None else f" [{fmt(r['heldout_nm_ci_lo'])}, {fmt(r['heldout_nm_ci_hi'])}]"
        within = {True: "yes", False: "no", None: "n/a"}[r["within_10pct_of_family_best"]]
        matched = "none at this cost" if r["matched"] is None else fmt(r["matched_heldout_nm_mean"])
        body.append(
            [
                r["family"],
                r["topology"],
                str(r["p"]),
                r["sizes"].replace(" ", ", "),
                r["epochs"].replace(" ", ", "),
                str(r["total_epochs"]),
                f"{r['presentations']:,}",
                fmt(r["heldout_nm_mean"]) + ci,
                within,
                matched,
                _ratio(r["over_matched"]),
            ]
        )
    return table(head, body)


def _inf(x: float | None) -> float:
    """A ratio, None (a setting that never finished) standing for ∞."""
    return math.inf if x is None else x


def _span(values: list[float], show) -> str:
    lo, hi = min(values), max(values)
    return show(lo) if lo == hi else f"{show(lo)}–{show(hi)}"


def _schedule_alone(rows: list[dict], sel: dict) -> str:
    """Selective presentation's spread over p, N_i, n_i alone, from its rows at fixed other parameters."""
    parts = [
        r
        for r in rows
        if r["topology"] == sel["topology"] and r["kind"] == FIXED and r["family"].startswith(SELECTIVE + " at ")
    ]
    if not parts:
        return ""
    fixed = ", ".join(k for k in sel["swept_keys"].split() if not k.startswith(SCHEDULE))
    ratios = _span([_inf(r["worst_over_best"]) for r in parts], _ratio)
    within = _span([100 * r["within_10pct_fraction"] for r in parts], lambda x: f"{x:.0f}") + " %"
    return (
        f"With {fixed} held fixed ({len(parts)} values), selective presentation's spread over the "
        f"schedule alone is worst ÷ best {ratios}, with {within} of settings within 10 % of the best. "
    )


def _reading(sel: dict, rivals: list[dict]) -> str:
    """Whether the sentence holds for ``sel`` against ``rivals``: by both measures of spread, one, or none."""
    ratio_ok = all(_inf(sel["worst_over_best"]) <= _inf(r["worst_over_best"]) for r in rivals)
    within_ok = all(sel["within_10pct_fraction"] >= r["within_10pct_fraction"] for r in rivals)
    if ratio_ok and within_ok:
        return "holds: selective presentation is at least as insensitive by both measures"
    if not ratio_ok and not within_ok:
        return "does not hold: by each measure of spread some rival is less sensitive than selective presentation"
    better, worse = ("worst ÷ best", "the share within 10 %")
    if not ratio_ok:
        better, worse = worse, better
    return f"holds only in part: selective presentation is at least as insensitive by {better}, not by {worse}"


def _good(r: dict) -> bool:
    """Whether a family reaches the best level at its cost (its best within 10 % of the best there)."""
    return r["level"] is not None and r["level"] <= 1 + TOLERANCE


def _names(rows: list[dict]) -> str:
    return ", ".join(r["family"] for r in rows)


def _plural(n: int, one: str, many: str) -> str:
    return one if n == 1 else many


def _answer(sel: dict, primary: dict, at: str, rivals: list[dict]) -> str:
    """The paper's sentence answered in plain words: selective presentation's spread against that of the
    rivals that reach the best level at their cost; the others' spread set aside, with why."""
    good, bad = [r for r in rivals if _good(r)], [r for r in rivals if not _good(r)]
    mine = (
        f"elective presentation{at} varies by worst ÷ best {_ratio(primary['worst_over_best'])}, with "
        f"{_within(primary)} of its settings within 10 % of its best"
    )
    if not rivals:
        return (
            f"S{mine}; no rival family (one-stage training, an optimizer swept over its parameters) has "
            "more than one setting, so the comparison the sentence makes cannot be made here."
        )
    if good:
        n = len(good)
        theirs = "; ".join(f"{r['family']} {_ratio(r['worst_over_best'])} with {_within(r)}" for r in good)
        who = _plural(n, "rival that reaches", "rivals that reach")
        text = (
            f"Over these ranges, compared with the {who} the best level at {_plural(n, 'its', 'their')} "
            f"cost, the sentence {_reading(primary, good)}. S{mine}, against {theirs}."
        )
    else:
        text = (
            "No rival family comes within 1.1 × of the best at its cost anywhere in its range, so none "
            f"is a working alternative whose sensitivity could be compared; s{mine}."
        )
    if bad:
        n = len(bad)
        levels = _span([_inf(r["level"]) for r in bad], _level)
        spreads = _span([_inf(r["worst_over_best"]) for r in bad], _ratio)
        who = _plural(n, "rival family never gets", "rival families never get")
        its = _plural(n, "its", "their")
        text += (
            f" {'The other' if good else 'The'} {n} {who} within 1.1 × of the best at {its} cost (best "
            f"{levels} × it): bad over the whole range, so {its} spread ({spreads}) is not "
            "insensitivity."
        )
    if not _good(sel):
        text += (
            f" Selective presentation's own best is {_level(sel['level'])} × the best at its cost "
            f"({sel['level_reference_family']})."
        )
    return text


def _spread_line(
    sel: dict | None, total: dict | None, matched: dict | None, rivals: list[dict], others: list[dict]
) -> str:
    parts = [
        f"{r['family']}: {_ratio(r['worst_over_best'])}, {_within(r)}"
        for r in (sel, total, matched, *others)
        if r is not None
    ]
    if rivals:
        parts.append(
            f"rivals at a fixed cost: {_span([_inf(r['worst_over_best']) for r in rivals], _ratio)} "
            f"({_span([100 * r['within_10pct_fraction'] for r in rivals], lambda x: f'{x:.0f}')} %)"
        )
    return (
        "- *Spread* (how much the error depends on where in its range a family is set: worst ÷ best, and "
        "the settings within 10 % of its own best): " + "; ".join(parts) + "."
    )


def _level_line(main: list[dict], rivals: list[dict]) -> str:
    text = (
        "- *Level* (how good a family is at its best: its best ÷ the best of any family at that cost, "
        "1.00 = nothing does better there): " + "; ".join(f"{r['family']}: {_level(r['level'])}" for r in main) + "."
    )
    bad = [r for r in rivals if not _good(r)]
    if bad:
        flattest = min(bad, key=lambda r: _inf(r["worst_over_best"]))
        text += (
            f" A small spread far above the best level is not insensitivity: {flattest['family']} has "
            f"worst ÷ best {_ratio(flattest['worst_over_best'])}, but even its best is "
            f"{_level(flattest['level'])} × the best at its cost."
        )
    return text


def _cost_line(sel: dict, total: dict | None, matched: dict | None, versus: list[dict]) -> str:
    """How much of selective presentation's spread is cost, and each setting against conventional training
    at the same cost."""
    text = ""
    if total is not None:
        text += (
            f"Over the total epochs N as well, selective presentation spreads "
            f"{_ratio(sel['worst_over_best'])} against {_ratio(total['worst_over_best'])} at the "
            "paper's N: N changes the cost, and a longer run is better for any method"
        )
        text += (
            f"; conventional SGD stopped at the same budgets ({matched['presentations_min']:,}–"
            f"{matched['presentations_max']:,} t) spreads {_ratio(matched['worst_over_best'])}. "
            if matched
            else ". "
        )
    pairs = [
        r
        for r in versus
        if r["topology"] == sel["topology"] and r["family"] == sel["family"] and r["over_matched"] is not None
    ]
    if pairs:
        lower = sum(r["over_matched"] < 1 for r in pairs)
        text += (
            "Set against conventional training at the same cost, each of its settings has "
            f"{_span([r['over_matched'] for r in pairs], _ratio)} × conventional's error ({lower} of "
            f"{len(pairs)} lower on the mean; whether each difference exceeds the seeds' noise is in "
            "the selection verdict)."
        )
    return f"- *Cost*: {text.strip()}" if text else ""


def _noise_line(main: list[dict]) -> str:
    resolved = [r for r in main if _resolved(r)]
    rest = [r for r in main if not _resolved(r)]
    which = (
        f" (all but {_names(rest)})"
        if rest and len(resolved) > len(rest)
        else f" ({_names(resolved)})"
        if resolved
        else ""
    )
    return (
        f"- *Noise*: worst − best, paired by seed, has a 95 % interval above 0 for {len(resolved)} of "
        f"{len(main)} families{which}; where it does not, the family's spread is within the seeds' "
        "noise."
    )


def verdict_text(rows: list[dict], topology: str, versus: list[dict] | None = None) -> str:
    """The paper's sentence read against one topology's families, in plain words, with the numbers: the
    answer (selective presentation's spread against that of the rivals that reach the best level at their
    cost), then spread, level, cost and noise apart."""
    here = [r for r in rows if r["topology"] == topology]
    main = [r for r in here if r["kind"] == FAMILY]
    if not main:
        return f"**{topology}.** No family with more than one setting."
    sel = next((r for r in main if r["family"] == SELECTIVE), None)
    total = next((r for r in here if r["kind"] == PAPER_TOTAL and r["family"].startswith(SELECTIVE + " at ")), None)
    matched = next((r for r in main if r["family"].endswith(", " + BUDGET_MATCHED)), None)
    # the one-stage speed-up techniques at a fixed cost, not other orders nor the budget-matched reference
    rivals = [r for r in main if not r["staged"] and r is not matched]
    others = [r for r in main if r["staged"] and r is not sel]  # other orders, other optimizers
    lines = [_spread_line(sel, total, matched, rivals, others), _level_line(main, rivals)]
    if sel is None:
        answer = "No selective presentation family with more than one setting: the sentence is not tested."
    elif not any(k.startswith(SCHEDULE) for k in sel["swept_keys"].split()):
        answer = (
            "Selective presentation's swept keys include none of p, N_i, n_i (schedule.*): the sentence is not tested."
        )
    else:
        at = " at the paper's N = ΣN_i = 150 (over p, n_i and the N_i profile)" if total else ""
        answer = _answer(sel, total or sel, at, rivals) + " " + _schedule_alone(rows, sel)
        lines.append(_cost_line(sel, total, matched, versus or []))
    lines.append(_noise_line(main))
    return f"**{topology}.** {answer.strip()}\n\n" + "\n".join(line for line in lines if line)


def ranges_text(rows: list[dict], topology: str) -> str:
    """The ranges the verdict depends on, one line per family."""
    lines = [
        f"- {r['family']}: {r['swept_terms'] or '—'}" for r in rows if r["topology"] == topology and r["kind"] == FAMILY
    ]
    return (
        f"The verdict on {topology} depends on these ranges (a wider range can only raise a family's "
        "worst ÷ best, a narrower one can hide a cliff):\n\n" + "\n".join(lines)
    )


def section(ctx: Context) -> Section | None:
    rows = sensitivity_rows(ctx.groups, ctx.topologies)
    if not rows:
        return None
    versus = versus_matched_rows(ctx.groups, ctx.topologies)
    here = [t for t in ctx.topologies if any(r["topology"] == t for r in rows)]
    verdicts = "\n\n".join(f"{verdict_text(rows, t, versus)}\n\n{ranges_text(rows, t)}" for t in here)
    title = 'Sensitivity: is selective presentation "not very sensitive to p, N_i and n_i"? (final held-out RMS, Nm)'
    blocks = [verdicts, sensitivity_markdown(rows), NOTE]
    csv = {"sensitivity.csv": rows}
    if versus:
        blocks += [
            "Each setting of selective presentation (and of any other staged family) beside "
            "conventional training stopped at the same presentations (its budget-matched partner, "
            "the same other settings): the cost is the same, so the ratio shows what the choice of p, "
            "n_i and N_i does beyond buying more or fewer presentations.",
            versus_matched_markdown(versus),
        ]
        csv["sensitivity_vs_matched.csv"] = versus
    return Section(title, blocks, csv=csv)


def study(ctx: Context) -> list[Section] | None:
    """The sensitivity study's report: its verdicts, then the error–cost plane of the same families."""
    sec = section(ctx)
    return None if sec is None else [sec, *filter(None, [error_cost.section(ctx)])]


SECTION = study
