"""Stages of selective presentation and their cost (paper, section 3).

A schedule is the list of training sets A1 ⊂ A2 ⊂ … ⊂ A_{p+1} = U by their sizes n_i, and the epochs
N_i spent on each. Its cost is T = t·Σ n_i·N_i presentations; conventional training is the one-stage
schedule (n, N) with T_con = t·n·N. A *budget* turns a one-stage schedule into the compute-matched
baseline: as many full epochs as fit, then one partial epoch presenting the first few patterns of
that epoch's shuffled order, so the total equals the budget exactly.
"""

from __future__ import annotations

import bisect
import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from selpres.errors import ConfigError


@dataclass(frozen=True)
class Stage:
    size: int  # n_i, patterns in the training set A_i
    epochs: int  # N_i full epochs on A_i
    extra: int = 0  # presentations of one trailing partial epoch (budget-matched schedules only)

    @property
    def presentations(self) -> int:
        return self.size * self.epochs + self.extra


@dataclass(frozen=True)
class EpochPlan:
    """One epoch as the training loop sees it: which stage, how large its set, how many presentations."""

    index: int
    stage: int
    size: int
    presentations: int


@dataclass(frozen=True)
class Schedule:
    stages: tuple[Stage, ...]
    # how the sizes and epochs were given, in the parametric schedule's words (selpres.presentation.proportions
    # ``rule_of``: p, first, growth, profile, the total or budget): recorded, never part of what the stages are
    rule: dict | None = field(default=None, compare=False, hash=False)

    @property
    def n(self) -> int:
        return self.stages[-1].size

    @property
    def p(self) -> int:
        """Number of enlargements (the paper's p)."""
        return len(self.stages) - 1

    @property
    def sizes(self) -> list[int]:
        return [s.size for s in self.stages]

    @property
    def epochs(self) -> list[int]:
        return [s.epochs for s in self.stages]

    @property
    def total_epochs(self) -> int:
        """Σ N_i, counting a partial epoch as one (it is one pass of the loop)."""
        return sum(s.epochs + (1 if s.extra else 0) for s in self.stages)

    @property
    def presentations(self) -> int:
        """T / t = Σ n_i·N_i (+ a partial epoch's presentations)."""
        return sum(s.presentations for s in self.stages)

    @property
    def conventional_presentations(self) -> int:
        """T_con / t = n·N for conventional training with the same number of epochs N = Σ N_i
        (a one-stage schedule's partial epoch counts as the fraction of an epoch it is)."""
        return self.n * sum(s.epochs for s in self.stages) + sum(s.extra for s in self.stages)

    def plan(self) -> Sequence[EpochPlan]:
        """Every epoch in order, one per schedule (every replica's sampler shares it): a tuple, or a lazy
        :class:`Plan` when longer than MATERIALISED_EPOCHS."""
        return _plan(self.stages)

    def stage_ends(self) -> list[int]:
        """Global index of each stage's last epoch (where the loop scores, reports and checkpoints)."""
        ends, e = [], -1
        for st in self.stages:
            e += st.epochs + (1 if st.extra else 0)
            ends.append(e)
        return ends

    def describe(self) -> dict:
        return {
            "p": self.p,
            "sizes": self.sizes,
            "epochs": self.epochs,
            "extra_presentations": [s.extra for s in self.stages],
            "presentations_per_stage": [s.presentations for s in self.stages],
            "presentations": self.presentations,
            "conventional_presentations": self.conventional_presentations,
            "cost_ratio": self.presentations / self.conventional_presentations,
            "n1": self.sizes[0],
            "epochs_total": sum(self.epochs),  # ΣN_i, full epochs (a partial one is in extra_presentations)
            **(self.rule or {}),
        }


class Plan(Sequence):
    """Every epoch of a schedule, in order, made on demand: ``plan[i]``, ``len(plan)``, ``plan[a:b]`` and
    iteration cost O(stages) memory, so a plan of 10^12 epochs (``schedule.budget=1e15``) is never built
    whole (selpres.run.estimate refuses the job before it would run)."""

    def __init__(self, stages: tuple[Stage, ...], start: int = 0, stop: int | None = None):
        self._stages = stages
        self._ends = list(itertools.accumulate(st.epochs + (1 if st.extra else 0) for st in stages))
        total = self._ends[-1] if self._ends else 0
        self._start, self._stop = start, total if stop is None else stop
        self._asked, self._last = None, None  # the index last asked for (as given) and its epoch

    def __len__(self) -> int:
        return max(0, self._stop - self._start)

    def _at(self, i: int) -> EpochPlan:
        k = bisect.bisect_right(self._ends, i)
        st = self._stages[k]
        partial = st.extra and i == self._ends[k] - 1
        return EpochPlan(i, k, st.size, st.extra if partial else st.size)

    def __getitem__(self, i):
        if i == self._asked:  # every replica's sampler asks for the same epoch in turn: one comparison
            return self._last
        if isinstance(i, slice):
            start, stop, step = i.indices(len(self))
            if step != 1:
                return tuple(self[j] for j in range(start, stop, step))
            return Plan(self._stages, self._start + start, self._start + max(start, stop))
        j = i + len(self) if i < 0 else i
        if not 0 <= j < len(self):
            raise IndexError(f"epoch {i} outside the plan's {len(self)} epochs")
        self._last, self._asked = self._at(self._start + j), i
        return self._last

    def __iter__(self):
        for i in range(self._start, self._stop):
            yield self._at(i)

    def __eq__(self, other) -> bool:
        return isinstance(other, Sequence) and len(self) == len(other) and all(a == b for a, b in zip(self, other))

    def __repr__(self) -> str:
        return f"Plan({len(self)} epochs of {len(self._stages)} stages)"


MATERIALISED_EPOCHS = 1_000_000  # plans up to this long are a tuple (~0.1 GB at most): the loop's fastest lookup


@functools.lru_cache(maxsize=64)
def _plan(stages: tuple[Stage, ...]) -> Sequence[EpochPlan]:
    plan = Plan(stages)
    return tuple(plan) if len(plan) <= MATERIALISED_EPOCHS else plan


def _is_fraction(v) -> bool:
    return isinstance(v, float)


def resolve_sizes(sizes: Sequence, n: int, key: str = "schedule.sizes") -> list[int]:
    """Counts stay counts; floats are fractions of n in (0, 1] (rounded half up, at least 1)."""
    if not isinstance(sizes, (list, tuple)) or len(sizes) == 0:
        raise ConfigError(
            key, sizes, "a non-empty list of counts (e.g. [50, 100, 1002]) or fractions of n (e.g. [0.05, 1.0])"
        )
    out = []
    for v in sizes:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ConfigError(key, sizes, f"numbers only; {v!r} is not a count or a fraction")
        if not math.isfinite(v):
            raise ConfigError(key, sizes, "finite numbers (no NaN or inf)")
        if _is_fraction(v):
            if not 0.0 < v <= 1.0:
                raise ConfigError(key, sizes, f"fractions of n must lie in (0, 1]; got {v}")
            out.append(max(1, math.floor(v * n + 0.5)))  # half up: 0.25 of 1002 -> 251
        else:
            if v <= 0:
                raise ConfigError(key, sizes, f"counts must be positive; got {v}")
            out.append(int(v))
    if any(b <= a for a, b in zip(out, out[1:])):
        raise ConfigError(key, sizes, f"sizes strictly increasing (A1 ⊂ A2 ⊂ …); resolved to {out}")
    if out[-1] > n:
        raise ConfigError(key, sizes, f"sizes at most n = {n}, the exemplar set's size; resolved to {out}")
    if out[-1] != n:
        raise ConfigError(
            key, sizes, f"the last stage to be the whole exemplar set (n = {n}, or 1.0); resolved to {out}"
        )
    return out


def build_schedule(sizes: Sequence, epochs: Sequence | None, n: int, budget: int | None = None) -> Schedule:
    """Validate a schedule config against the exemplar set's size n, before any work is done."""
    counts = resolve_sizes(sizes, n)
    if budget is not None:
        if isinstance(budget, bool) or not isinstance(budget, int) or budget <= 0:
            raise ConfigError("schedule.budget", budget, "a positive whole number of presentations, or null")
        if len(counts) != 1:
            raise ConfigError(
                "schedule.budget", budget, "a budget only with a one-stage (conventional) schedule: sizes = [n]"
            )
        if epochs is not None:
            raise ConfigError(
                "schedule.epochs", list(epochs), "null when schedule.budget is set (epochs follow from the budget)"
            )
        full, extra = divmod(budget, n)
        return Schedule((Stage(n, full, extra),))
    if epochs is None or not isinstance(epochs, (list, tuple)):
        raise ConfigError(
            "schedule.epochs", epochs, "a list of positive epoch counts, one per stage (or set schedule.budget)"
        )
    if len(epochs) != len(counts):
        raise ConfigError(
            "schedule.epochs",
            list(epochs),
            f"one entry per stage: {len(counts)} sizes {list(sizes)} but {len(epochs)} epochs",
        )
    for e in epochs:
        if isinstance(e, bool) or not isinstance(e, int) or e <= 0:
            raise ConfigError("schedule.epochs", list(epochs), "positive whole numbers of epochs")
    return Schedule(tuple(Stage(s, int(e)) for s, e in zip(counts, epochs)))
