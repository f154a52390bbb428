"""Schedules as the config gives them, on any n: the parametric schedule's rule, and the paper's counts applied by
their proportions.

**The parametric schedule** (``configs/schedule/stages.yaml``, issue 38): every knob one sweepable key, so a Hydra
sweep's product of values is a product of valid schedules. ``p`` enlargements (p + 1 sets); ``first`` = n_1, a count
or a share of n; ``growth``: ``geometric`` (n_i / n = f^(1 - i/p), f = n_1 / n), ``linear`` (f + (1 - f) i/p) or
``paper`` (Table 1's n_2 … n_4 = 100, 400, 800 of 1002 as shares of n, p = 4); the epochs N_i by the ``profile``
(weights equal, increasing 1 … p+1, decreasing p+1 … 1) with the total fixed: ``total_epochs`` = ΣN_i (apportioned
by the largest remainders, ties to the later stages), or a presentation ``budget`` (N_i ∝ weight, rounded down,
what is left given as whole epochs to the stages with the largest remainders that fit, the rest one partial epoch
of the last stage: the cost is exactly the budget, so a sweep varies the shape at equal cost); or ``epochs``
listed, one per stage. Sizes are rounded half up, as every fraction of n is. A schedule is given in one form:
listed sizes (``schedule.sizes``, the presets: every design and many commands override their lists) or the
parameters (``schedule.p`` set); a key of the other form is refused, naming both (:func:`check_form`). The presets
are instances of the rule (tests/test_stages.py derives each from it); :func:`rule_of` names a listed schedule's
growth and profile where the rule reproduces its sizes and epochs exactly, so results.json and TensorBoard describe
every schedule in the same words.

**Named schedules on any n** (issue 11, item 5): the paper's counts, applied by their proportions.

The named schedules (``configs/schedule/*.yaml``) give the paper's stage sizes 50, 100, 400, 800, 1002 and
the compute-matched budget 70,560 presentations: counts that fit only the paper's n = 1002. On an
exemplar set of another size they are applied by their proportions: every count c of a schedule whose
last stage is the paper's n becomes the fraction c / 1002 of n (rounded half up, as
``selpres.presentation.schedule.resolve_sizes`` rounds every fraction), and a one-stage budget b becomes
b · n / 1002 presentations (rounded half up), so epochs per stage, the cost ratio T/T_con and the
matched budget's share of the selective cost stay the paper's. What was applied is logged and recorded
(the resolved sizes and presentations are in results.json's ``schedule``). Counts that do not end at
1002 are the user's own and stay counts; if they do not end at n either, the schedule refuses them,
and the message shows them as fractions, the form that fits any n.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

from selpres.errors import ConfigError
from selpres.presentation.schedule import Schedule, Stage, build_schedule

PAPER_N = 1002  # the paper's exemplar set (section 5.1)
_PAPER_SIZES = [50, 100, 400, 800, 1002]  # Table 1's n_i

# ``configs/schedule/*.yaml`` for library callers (``SelectivePresentation(X, schedule="selective")``), who may not
# have the configs folder (it is not in the wheel); tests/test_selective_presentation.py checks both agree.
NAMED = {
    "conventional": {"sizes": [1.0], "epochs": [150], "budget": None, "order": "stratified"},
    "selective": {"sizes": _PAPER_SIZES, "epochs": [30] * 5, "budget": None, "order": "stratified"},
    "random_growth": {"sizes": _PAPER_SIZES, "epochs": [30] * 5, "budget": None, "order": "random"},
    "matched": {"sizes": [1.0], "epochs": None, "budget": 70_560, "order": "stratified"},
    "geometric": {"sizes": [0.0625, 0.125, 0.25, 0.5, 1.0], "epochs": [30] * 5, "budget": None, "order": "stratified"},
    "linear": {"sizes": [0.2, 0.4, 0.6, 0.8, 1.0], "epochs": [30] * 5, "budget": None, "order": "stratified"},
    "two_stage": {"sizes": [0.1, 1.0], "epochs": [75, 75], "budget": None, "order": "stratified"},
}


def _counts(sizes: Sequence) -> bool:
    return bool(sizes) and all(isinstance(v, int) and not isinstance(v, bool) for v in sizes)


def fit_schedule(sizes: Sequence, budget: int | None, n: int) -> tuple[list, int | None, str | None]:
    """(sizes, budget, what was applied or None) for an exemplar set of n patterns."""
    if n == PAPER_N:
        return list(sizes), budget, None
    notes = []
    if _counts(sizes) and sizes[-1] == PAPER_N:
        fractions = [c / PAPER_N for c in sizes]
        fractions[-1] = 1.0
        notes.append(
            f"schedule.sizes={list(sizes)} are the paper's counts for n = {PAPER_N}; applied as fractions "
            f"{[round(f, 4) for f in fractions]} of n = {n:,}"
        )
        sizes = fractions
    if isinstance(budget, int) and not isinstance(budget, bool) and budget > 0:
        scaled = max(1, math.floor(budget * n / PAPER_N + 0.5))
        notes.append(
            f"schedule.budget={budget:,} presentations (for the paper's n = {PAPER_N}) scaled by "
            f"n/{PAPER_N} to {scaled:,}"
        )
        budget = scaled
    return list(sizes), budget, "; ".join(notes) or None


def with_fraction_form(e: ConfigError, sizes: Sequence) -> ConfigError:
    """A schedule.sizes error about counts that do not fit this n, with the counts written as fractions (the form
    for any n); only where those fractions are themselves valid (increasing, positive): sizes that are not nested
    are wrong on every n, and their fractions would be too."""
    valid = _counts(sizes) and sizes[0] > 0 and all(a < b for a, b in zip(sizes, sizes[1:]))
    if e.key != "schedule.sizes" or not valid:
        return e
    fractions = ",".join(f"{c / sizes[-1]:.4g}" for c in sizes[:-1]) + ",1.0"
    return ConfigError(e.key, e.value, f"{e.allowed}; as fractions of n, which fit any n: schedule.sizes=[{fractions}]")


# ------------------------------------------------------------------------------------------ the parametric schedule
RULE_KEYS = ("p", "first", "growth", "profile", "total_epochs")  # the parametric schedule's own keys
GROWTHS = ("geometric", "linear", "paper")
PROFILES = ("equal", "increasing", "decreasing")
_PAPER_SHARES = [c / PAPER_N for c in _PAPER_SIZES[1:-1]]  # Table 1's n_2, n_3, n_4 as shares of n
PARAMETRIC = "the parametric schedule (schedule=stages)"


def _shown(v) -> str:
    return "null" if v is None else str(v).replace(" ", "")


def check_form(sch: Mapping) -> None:
    """A schedule node in one form: listed sizes, or the parametric keys (``schedule.p`` set). A key of the other form
    is refused in one line naming both (it would otherwise be recorded as if it had shaped the run)."""
    p, sizes = sch.get("p"), sch.get("sizes")
    if p is None:
        for k in RULE_KEYS[1:]:
            if sch.get(k) is not None:
                raise ConfigError(
                    f"schedule.{k}",
                    sch[k],
                    f"null here: schedule.sizes={_shown(sizes)} lists the sizes, and {k} is a key of {PARAMETRIC}, "
                    f"read only with schedule.p set (e.g. schedule=stages schedule.{k}={_shown(sch[k])})",
                )
        if sizes is None:
            raise ConfigError("schedule.sizes", None, "the stage sizes, or schedule.p and the keys of " + PARAMETRIC)
        return
    if sizes is not None:
        raise ConfigError(
            "schedule.p",
            p,
            f"null with listed sizes (schedule.sizes={_shown(sizes)}): p is a key of {PARAMETRIC}, where the sizes "
            f"follow from p, first and growth (e.g. schedule=stages schedule.p={_shown(p)})",
        )
    if sch.get("pruning") is not None:
        raise ConfigError("schedule.p", p, "null with schedule.pruning: a pruning policy runs one stage of all n")
    _whole("schedule.p", p, 0)  # the checks that need no n, before the task is built
    if p and sch.get("growth") not in GROWTHS:
        raise ConfigError("schedule.growth", sch.get("growth"), f"one of {', '.join(GROWTHS)}")
    if isinstance(sch.get("first"), float) and not 0 < sch["first"] < 1:
        raise ConfigError("schedule.first", sch["first"], "a share of n in (0, 1), or n_1 as a count")
    _lengths(sch)
    if sch.get("profile") is not None:
        _weights(sch["profile"], 1)


def _lengths(sch: Mapping) -> str:
    """Which key fixes the epochs of a parametric schedule: exactly one of epochs, total_epochs, budget."""
    given = [(k, sch.get(k)) for k in ("epochs", "total_epochs", "budget") if sch.get(k) is not None]
    if len(given) != 1:
        what = " and ".join(f"schedule.{k}={_shown(v)}" for k, v in given) or "none of them"
        # the key named is the one given beside stages.yaml's total_epochs; the fix nulls that default
        key, value = next(
            ((k, v) for k, v in given if k != "total_epochs"), given[0] if given else ("total_epochs", None)
        )
        fix = " (e.g. schedule.total_epochs=null" if len(given) > 1 and "total_epochs" in dict(given) else ""
        fix += ("; with epochs listed also schedule.profile=null)" if key == "epochs" else ")") if fix else ""
        raise ConfigError(
            f"schedule.{key}",
            value,
            f"one of schedule.total_epochs (ΣN_i), schedule.budget (presentations) or schedule.epochs (one N_i per "
            f"stage) for {PARAMETRIC}, the others null{fix}; got {what}",
        )
    return given[0][0]


def _whole(key: str, v, low: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < low:
        raise ConfigError(key, v, f"a whole number >= {low}")
    return v


def _first_share(first, p: int, n: int) -> float:
    """n_1 / n from ``schedule.first`` (a count of at most n, or a share in (0, 1))."""
    if isinstance(first, bool) or not isinstance(first, (int, float)) or not math.isfinite(first):
        raise ConfigError("schedule.first", first, f"n_1 as a count (1 .. n = {n:,}) or a share of n in (0, 1)")
    if isinstance(first, float):
        if not 0 < first < 1:
            raise ConfigError("schedule.first", first, f"a share of n in (0, 1), or n_1 as a count (1 .. {n - 1:,})")
        return first
    if not 1 <= first < n:
        raise ConfigError(
            "schedule.first", first, f"n_1 below n = {n:,} for p={p} enlargements (a count 1 .. {n - 1:,}, or a share)"
        )
    return first / n


def stage_sizes(p: int, first, growth, n: int) -> list[int]:
    """n_1 … n_{p+1} = n of the parametric schedule; ConfigError naming the keys when they cannot be built on n."""
    p = _whole("schedule.p", p, 0)
    if p == 0:
        return [n]
    if p >= n:
        raise ConfigError("schedule.p", p, f"fewer enlargements than n = {n:,} patterns (each adds at least one)")
    if growth not in GROWTHS:
        raise ConfigError("schedule.growth", growth, f"one of {', '.join(GROWTHS)}")
    f = _first_share(first, p, n)
    half_up = lambda share: max(1, math.floor(share * n + 0.5))
    if growth == "paper":
        if p != len(_PAPER_SHARES) + 1:
            raise ConfigError(
                "schedule.p",
                p,
                "4 with schedule.growth=paper (Table 1's five sizes); any p: growth geometric or linear",
            )
        sizes = [half_up(f), *(half_up(s) for s in _PAPER_SHARES), n]
    elif growth == "geometric":
        sizes = [half_up(f ** (1 - i / p)) for i in range(p)] + [n]
    else:
        sizes = [half_up(f + (1 - f) * i / p) for i in range(p)] + [n]
    bad = next((i for i in range(p) if sizes[i + 1] <= sizes[i]), None)
    if bad is not None:
        raise ConfigError(
            "schedule.p",
            p,
            f"sizes that grow: p={p}, first={_shown(first)}, growth={growth} on n = {n:,} round to {sizes} "
            f"(n_{bad + 1} >= n_{bad + 2}); fewer enlargements, another first or another growth",
        )
    return sizes


def _weights(profile, k: int) -> list[int]:
    if profile not in PROFILES:
        raise ConfigError("schedule.profile", profile, f"one of {', '.join(PROFILES)} (the N_i rule)")
    return {"equal": [1] * k, "increasing": list(range(1, k + 1)), "decreasing": list(range(k, 0, -1))}[profile]


def _largest_remainders(ideal: list[float], total: int) -> list[int]:
    """Whole numbers summing to ``total``, each the floor of its ideal share or one more (the largest remainders,
    ties to the later stages)."""
    out = [math.floor(x) for x in ideal]
    by = sorted(range(len(ideal)), key=lambda i: (ideal[i] - out[i], i), reverse=True)
    for i in by[: total - sum(out)]:
        out[i] += 1
    return out


def stage_epochs(profile, total: int, k: int) -> list[int]:
    """N_1 … N_k summing to ``total`` (ΣN_i), shaped by the profile's weights; every stage at least one epoch."""
    w = _weights(profile, k)
    total = _whole("schedule.total_epochs", total, k)
    shaped = lambda t: _largest_remainders([x * t / sum(w) for x in w], t)
    epochs = shaped(total)
    if min(epochs) < 1:
        least = next(t for t in range(total, total * k + 1) if min(shaped(t)) >= 1)
        raise ConfigError(
            "schedule.total_epochs", total, f"at least {least} for profile={profile} over {k} stages (N_i = {epochs})"
        )
    return epochs


def split_budget(profile, budget, sizes: list[int]) -> tuple[Stage, ...]:
    """Stages whose presentations sum to exactly ``budget``: N_i ∝ the profile's weight (rounded down), the
    presentations left given as whole epochs to the stages with the largest remainders that fit, the rest one
    partial epoch of the last stage."""
    w = _weights(profile, len(sizes))
    if isinstance(budget, bool) or not isinstance(budget, int) or budget < sizes[0]:
        raise ConfigError(
            "schedule.budget", budget, f"at least one pass over A_1 (n_1 = {sizes[0]:,} presentations), a whole number"
        )
    per = budget / sum(wi * s for wi, s in zip(w, sizes))
    ideal = [wi * per for wi in w]
    epochs = [math.floor(x) for x in ideal]
    if min(epochs) < 1:
        least = math.ceil(sum(wi * s for wi, s in zip(w, sizes)) / min(w))
        raise ConfigError(
            "schedule.budget",
            budget,
            f"at least {least:,} presentations: one epoch on each of the {len(sizes)} sets {sizes} with "
            f"profile={profile}",
        )
    left = budget - sum(e * s for e, s in zip(epochs, sizes))
    for i in sorted(range(len(sizes)), key=lambda i: (ideal[i] - epochs[i], i), reverse=True):
        if sizes[i] <= left:
            epochs[i], left = epochs[i] + 1, left - sizes[i]
    epochs[-1] += left // sizes[-1]
    return tuple(Stage(s, e) for s, e in zip(sizes[:-1], epochs)) + (Stage(sizes[-1], epochs[-1], left % sizes[-1]),)


def parametric_schedule(sch: Mapping, n: int) -> Schedule:
    """The parametric schedule ``sch`` (``schedule.*`` as plain values, :func:`check_form`'s second form) on n."""
    p, epochs, total, budget = sch.get("p"), sch.get("epochs"), sch.get("total_epochs"), sch.get("budget")
    sizes = stage_sizes(p, sch.get("first"), sch.get("growth"), n)
    key = _lengths(sch)
    if key != "epochs" and sch.get("profile") is None:
        raise ConfigError("schedule.profile", None, f"one of {', '.join(PROFILES)}: how {key} is split over the stages")
    if key == "epochs" and sch.get("profile") is not None:
        raise ConfigError("schedule.profile", sch["profile"], "null when schedule.epochs lists N_i")
    if key == "budget":
        stages = split_budget(sch["profile"], budget, sizes)
    elif key == "epochs":
        stages = build_schedule(sizes, list(epochs), n).stages
    else:
        stages = tuple(Stage(s, e) for s, e in zip(sizes, stage_epochs(sch["profile"], total, len(sizes))))
    rule = {"form": "parametric", **{k: sch.get(k) for k in (*RULE_KEYS, "budget")}}
    if p == 0:  # one stage of all n: n_1, the growth and the profile have nothing to shape
        rule.update(growth="one stage", profile="one stage")
    return Schedule(stages, rule)


def schedule_of(sch: Mapping, n: int) -> tuple[Schedule, str | None]:
    """The schedule a ``schedule.*`` node (plain values) gives on n, in either form, and how named counts were applied
    (None: as given); every refusal one ConfigError naming the keys, before any work."""
    check_form(sch)
    if sch.get("p") is not None:
        return parametric_schedule(sch, n), None
    sizes, budget, note = fit_schedule(sch["sizes"], sch.get("budget"), n)
    try:
        built = build_schedule(sizes, sch.get("epochs"), n, budget)
    except ConfigError as e:
        raise with_fraction_form(e, sizes) from None
    return dataclasses.replace(built, rule=rule_of(built)), note


def rule_of(s: Schedule) -> dict:
    """A listed schedule in the parametric schedule's words: the growth and profile names where the rule reproduces
    its sizes and epochs exactly (within the rounding of whole patterns and epochs), else "listed"."""
    sizes, n, p = s.sizes, s.n, s.p
    growth = "one stage" if p == 0 else next((g for g in GROWTHS if _grows(g, sizes, n)), "listed")
    full = [st.epochs for st in s.stages]
    profile = "one stage" if p == 0 else "listed"
    for name in PROFILES if p else ():
        try:
            if any(st.extra for st in s.stages):
                same = split_budget(name, s.presentations, sizes) == s.stages
            else:
                same = stage_epochs(name, sum(full), p + 1) == full
        except ConfigError:
            same = False
        if same:
            profile = name
            break
    return {"form": "listed", "growth": growth, "profile": profile}


def _grows(growth: str, sizes: list[int], n: int) -> bool:
    """Whether some n_1 / n makes the rule ``growth`` give ``sizes`` (each size pins it to an interval)."""
    p, lo, hi = len(sizes) - 1, 0.0, 1.0
    if growth == "paper":
        return (
            p == 4 and sizes[1:-1] == [max(1, math.floor(x * n + 0.5)) for x in _PAPER_SHARES] and sizes[0] < sizes[1]
        )
    for i, s in enumerate(sizes[:-1]):
        a, b = (s - 0.5) / n, (s + 0.5) / n  # the share the rule must give for stage i, to the rounding
        if growth == "geometric":  # f ** (1 - i/p) in [a, b)
            e = 1 / (1 - i / p)
            a, b = max(a, 0.0) ** e, b**e
        else:  # f + (1 - f) i/p in [a, b)
            t = i / p
            a, b = (a - t) / (1 - t), (b - t) / (1 - t)
        lo, hi = max(lo, a), min(hi, b)
    return lo < hi and (growth != "geometric" or sizes[-1] == n)
