"""What every pruning policy shares: the interface (:class:`Policy`), the epoch's choice (:class:`EpochChoice`),
the cost ledger of a job's replicas (:class:`Ledger`) and InfoBatch's annealing of the last epochs
(:class:`Annealing`, which SeTa uses too).

Cost (the paper's T, in presentations): a back-propagated pattern costs one presentation; a forward pass only to
choose costs ``schedule.selection_cost`` of one (1/3, as the loss orders of :mod:`selpres.presentation.selection`
are charged). A policy whose scores come from its training passes (InfoBatch, SeTa) pays nothing for them; one
that asks for a forward pass over U (``forward_pass = True``: Selective Backprop) charges it in ``choose``.

**Budget form.** With ``schedule.budget`` every replica trains until it has spent exactly that cost (the last
epoch cut short, as a compute-matched run's is: :meth:`Ledger.affordable`), so a rival and conventional training
stopped at the same total cost are compared at one cost by construction. Without a budget the schedule runs
``schedule.epochs`` epochs and costs what it costs (recorded).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import torch

from selpres.errors import ConfigError

KEY = "schedule.pruning"  # the config node a policy's parameters sit in (errors name schedule.pruning.<key>)
INITIAL_SCORE = 3.0  # InfoBatch's (and SeTa's) initial score: above every loss here, so the first epoch keeps all


@dataclass
class EpochChoice:
    """What each replica presents this epoch: the first ``counts[r]`` entries of ``order[r]``, each weighted."""

    order: torch.Tensor  # [R, m] int64 (padded past counts[r])
    weights: torch.Tensor | None  # [R, m] float64 or None (all 1)
    counts: torch.Tensor  # [R] int64


def pad(rows: list[torch.Tensor], fill) -> torch.Tensor:
    """Rows of different lengths as one [R, max length] tensor, ``fill`` past each row's end."""
    m = max((len(r) for r in rows), default=0)
    out = torch.full((len(rows), m), fill, dtype=rows[0].dtype if rows else torch.int64)
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


def percentile(losses: torch.Tensor) -> torch.Tensor:
    """F(l_i) = #{j : l_j <= l_i} / n along the last dimension: [R, n] -> [R, n]."""
    s, _ = torch.sort(losses, dim=-1)
    return torch.searchsorted(s.contiguous(), losses.contiguous(), right=True).to(torch.float64) / losses.shape[-1]


class Ledger:
    """The costs of one job's replicas so far, and the budget they run against (None: ``epochs`` epochs)."""

    def __init__(self, n: int, seeds: list[int], budget: int | None, epochs: int | None, selection_cost: float):
        self.n, self.seeds, self.budget, self.epochs = n, list(seeds), budget, epochs
        self.cost_fraction = float(selection_cost)
        R = len(seeds)
        self.spent = torch.zeros(R, dtype=torch.float64)  # training + charged forward passes, per replica
        self.trained = torch.zeros(R, dtype=torch.float64)  # back-propagated presentations
        self.charged = torch.zeros(R, dtype=torch.float64)  # forward passes charged for choosing
        # patterns not back-propagated, summed over epochs: InfoBatch's pruned, Selective Backprop's scored not chosen
        self.left_out = torch.zeros(R, dtype=torch.float64)
        self.epochs_done = torch.zeros(R, dtype=torch.int64)

    @property
    def remaining(self) -> torch.Tensor:
        if self.budget is None:
            return torch.full_like(self.spent, math.inf)
        return self.budget - self.spent

    @property
    def exhausted(self) -> bool:
        """Every replica has spent its budget (a fraction of a presentation left cannot buy one)."""
        return self.budget is not None and bool((self.remaining < min(1.0, 1.0 + self.cost_fraction)).all())

    def affordable(self, r: int, k: int) -> int:
        """How many of ``k`` presentations replica r's remaining budget pays for (the epoch is cut there)."""
        left = float(self.remaining[r])
        return k if math.isinf(left) else min(k, int(math.floor(left + 1e-9)))

    def record(self, choice: EpochChoice) -> None:
        """After the epoch's updates: the presentations it trained on."""
        self.trained += choice.counts.to(torch.float64)
        self.spent += choice.counts.to(torch.float64)
        self.epochs_done += (choice.counts > 0).to(torch.int64)


class Annealing:
    """InfoBatch's annealing: after a share δ of the epochs the policy stops pruning by loss. Without a budget
    from epoch δN; with one, per replica, once its remaining budget buys no more full epochs than (1 - δ)/δ times
    the epochs it has done, so the last share 1 - δ of its epochs are full ones, as published for an epoch count."""

    def __init__(self, delta: float, replicas: int):
        self.delta = delta
        self.on = torch.zeros(replicas, dtype=torch.bool)

    def __call__(self, r: int, epoch: int, ledger: Ledger) -> bool:
        if ledger.budget is None:
            self.on[r] = epoch >= self.delta * ledger.epochs
        elif not self.on[r]:
            full_left = float(ledger.remaining[r]) / ledger.n
            self.on[r] = full_left * self.delta <= (1 - self.delta) * int(ledger.epochs_done[r])
        return bool(self.on[r])


class Param(NamedTuple):
    """One parameter of a policy: its type (float takes ints too), the range test, what is allowed (for errors)."""

    kind: type
    ok: Callable[[float], bool]
    allowed: str


class Policy:
    """A pruning policy: each epoch, from the samplers' shuffles of U, the patterns each replica presents.

    A subclass lists its parameters in ``PARAMS`` (checked by :meth:`check`, which it may extend with checks
    between them), and implements :meth:`choose` (and :meth:`finish` if it keeps scores). Its randomness comes
    from ``selpres.seeding.generator(seed_r, "pruning", epoch)``, so a job is the same bit for bit.
    """

    PARAMS: dict[str, Param] = {}
    forward_pass = False  # True: choose() gets every pattern's loss [R, n] from a forward pass over U (charge it)

    def __init__(self, params: dict, ledger: Ledger):
        self.params, self.ledger = dict(params), ledger

    @classmethod
    def check(cls, params: dict, *, budget: int | None, selection_cost: float) -> dict:
        """The parameters as the policy reads them; a ConfigError naming ``schedule.pruning.<key>``, the value and
        what is allowed for an unknown, missing or bad one."""
        for k, v in params.items():
            if k not in cls.PARAMS:
                reads = ", ".join(cls.PARAMS) or "no parameters"
                raise ConfigError(f"{KEY}.{k}", v, f"not set: {cls.__name__} reads {reads}")
        out = {}
        for k, p in cls.PARAMS.items():
            v = params.get(k)
            if v is None:
                raise ConfigError(f"{KEY}.{k}", None, f"a value: {cls.__name__} reads it ({p.allowed})")
            number = (int, float) if p.kind is float else (p.kind,)
            if isinstance(v, bool) or not isinstance(v, number) or not p.ok(v):
                raise ConfigError(f"{KEY}.{k}", v, p.allowed)
            out[k] = p.kind(v)
        return out

    @classmethod
    def epoch_share(cls, params: dict, selection_cost: float) -> float:
        """A lower bound on one epoch's cost as a share of n: the budget form plans budget / (share n) epochs."""
        raise NotImplementedError

    def choose(self, epoch: int, order: torch.Tensor, losses: torch.Tensor | None) -> EpochChoice:
        """This epoch's presentations from the samplers' shuffles of U ``order`` [R, n] (``losses``: [R, n] by
        pattern when ``forward_pass``, else None). Counts are cut to what each replica's budget pays for
        (:meth:`Ledger.affordable`); patterns left out and forward passes charged go into the ledger."""
        raise NotImplementedError

    def finish(self, choice: EpochChoice, losses: torch.Tensor) -> None:
        """After the epoch's updates, the presented patterns' losses [R, m] (first counts[r] of each row)."""

    def describe(self) -> dict:
        """results.json's ``pruning`` parameters."""
        return dict(self.params)


class ScoredByLoss(Policy):
    """A policy whose score of a pattern is its latest training loss (InfoBatch, SeTa): ``INITIAL_SCORE`` until it
    is first presented, then its loss in the epoch's training passes (nothing charged: no extra forward pass)."""

    def __init__(self, params: dict, ledger: Ledger):
        super().__init__(params, ledger)
        self.scores = torch.full((len(ledger.seeds), ledger.n), INITIAL_SCORE, dtype=torch.float64)

    def finish(self, choice: EpochChoice, losses: torch.Tensor) -> None:
        for r in range(len(self.ledger.seeds)):
            k = int(choice.counts[r])
            self.scores[r, choice.order[r, :k]] = losses[r, :k]
