"""Named schedules on any n (issue 11, item 5): the paper's counts, applied by their proportions.

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

import math
from collections.abc import Sequence

from selpres.errors import ConfigError

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
    """A schedule.sizes error about counts, with the counts written as fractions (the form for any n)."""
    if e.key != "schedule.sizes" or not _counts(sizes) or sizes[-1] <= 0:
        return e
    fractions = ",".join(f"{c / sizes[-1]:.4g}" for c in sizes[:-1]) + ",1.0"
    return ConfigError(e.key, e.value, f"{e.allowed}; as fractions of n, which fit any n: schedule.sizes=[{fractions}]")
