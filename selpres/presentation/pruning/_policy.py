"""What every pruning policy shares: the interface (:class:`Policy`, a :class:`~selpres.presentation.selector.Selector`
that chooses each epoch's patterns from the shuffle of U), InfoBatch's annealing of the last epochs
(:class:`Annealing`, which SeTa uses too), and the epoch's choice (:class:`EpochChoice`, the selector's
:class:`~selpres.presentation.selector.Presentation`) and the job's :class:`~selpres.presentation.selector.Ledger`
under the names policies have used.

Cost (the paper's T, in presentations): a back-propagated pattern costs one presentation (the loop charges what a
policy presents); a forward pass only to choose costs ``schedule.selection_cost`` of one, charged by the policy
(``ledger.charge``). A policy whose scores come from its training passes (InfoBatch, SeTa) pays nothing for them;
one that asks for a forward pass over U (``forward_pass = True``: Selective Backprop) charges it in ``choose``.

**Budget form.** With ``schedule.budget`` every replica trains until it has spent exactly that cost (the last
epoch cut short, as a compute-matched run's is: :meth:`Ledger.affordable`), so a rival and conventional training
stopped at the same total cost are compared at one cost by construction. Without a budget the schedule runs
``schedule.epochs`` epochs and costs what it costs (recorded).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import NamedTuple

import numpy as np
import torch

from selpres.errors import ConfigError
from selpres.presentation.proportions import fit_schedule
from selpres.presentation.schedule import EpochPlan, Schedule, Stage
from selpres.presentation.selector import Ledger, Network, Presentation, Selector

__all__ = ["Annealing", "EpochChoice", "KEY", "Ledger", "Param", "Policy", "ScoredByLoss", "pad", "percentile"]

KEY = "schedule.pruning"  # the config node a policy's parameters sit in (errors name schedule.pruning.<key>)
INITIAL_SCORE = 3.0  # InfoBatch's (and SeTa's) initial score: above every loss here, so the first epoch keeps all

EpochChoice = Presentation  # what each replica presents this epoch (the first counts[r] of order[r], weighted)


def pad(rows: list[torch.Tensor], fill) -> torch.Tensor:
    """Rows of different lengths as one [R, max length] tensor, ``fill`` past each row's end."""
    m = max((len(r) for r in rows), default=0)
    out = torch.full((len(rows), m), fill, dtype=rows[0].dtype if rows else torch.int64)
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


def percentile(losses: torch.Tensor) -> torch.Tensor:
    """F(l_i) = #{j : l_j <= l_i} / n along the last dimension: [R, n] -> [R, n] float64 (a NaN loss, of a diverged
    replica, ranks above every other: F = 1).

    Counted on the sorted losses: the count of l_(k) is the position after the last loss equal to it (a run of ties
    shares one count, so the sort need not be stable), scattered back. Why numpy's argsort and not torch.sort with
    a binary search per loss: Selective Backprop ranks every pattern each epoch, and on the PUMA 560's [24, 10^5]
    losses, on one thread here, this takes 0.19 s where those took 0.76-1.0 s, the same counts."""
    a = losses.detach().cpu().numpy()
    n = a.shape[-1]
    rows = a.reshape(-1, n)
    idx = np.argsort(rows, axis=-1)  # NaNs last
    s = np.take_along_axis(rows, idx, -1)
    nan = np.isnan(s)
    last = np.empty(s.shape, dtype=bool)  # the last of its run of equal losses (NaNs one run)
    last[:, -1] = True
    np.not_equal(s[:, 1:], s[:, :-1], out=last[:, :-1])
    last[:, :-1] &= ~(nan[:, 1:] & nan[:, :-1])
    ends = np.where(last, np.arange(1, n + 1), n + 1)
    count = np.minimum.accumulate(ends[:, ::-1], axis=-1)[:, ::-1]  # the next run end at or after each position
    out = np.empty_like(count)
    np.put_along_axis(out, idx, count, -1)
    return torch.from_numpy(out.reshape(a.shape)).to(torch.float64) / n


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

    def state_dict(self) -> dict:
        return {"on": self.on}

    def load_state_dict(self, state: dict) -> None:
        on = state["on"]
        if not isinstance(on, torch.Tensor) or on.shape != self.on.shape:
            raise ValueError(f"annealing flags are not a tensor of shape {tuple(self.on.shape)}")
        self.on = on.to(torch.bool).clone()


class Param(NamedTuple):
    """One parameter of a policy: its type (float takes ints too), the range test, what is allowed (for errors)."""

    kind: type
    ok: Callable[[float], bool]
    allowed: str


class Policy(Selector):
    """A pruning policy: each epoch, from the samplers' shuffles of U, the patterns each replica presents.

    A subclass lists its parameters in ``PARAMS`` (checked by :meth:`check`, which it may extend with checks
    between them), says how cheap an epoch can be (:meth:`epoch_share`: the budget form's plan) and implements
    :meth:`choose` (and :meth:`finish` if it keeps scores). Its randomness comes from
    ``selpres.seeding.generator(seed_r, "pruning", epoch)`` and its state (its tensors, its :class:`Annealing`) is
    checkpointed, so a job is the same bit for bit, resumed or not. ``self.ledger`` is the job's ledger.
    """

    PARAMS: dict[str, Param] = {}
    forward_pass = False  # True: choose() gets every pattern's loss [R, n] from a forward pass over U (charge it)

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
    def check_schedule(cls, *, sizes: list, order: str, budget: int | None, epochs: list | None, name: str) -> None:
        """One stage of all of U, shuffled, with either a budget or one epoch count."""
        if list(sizes) != [1.0]:
            raise ConfigError("schedule.sizes", list(sizes), f"[1.0]: {name} prunes all of U every epoch")
        if order != "random":
            raise ConfigError("schedule.order", order, f"random: {name} shuffles all of U every epoch")
        if (budget is None) == (epochs is None):
            raise ConfigError(
                "schedule.budget", budget, f"either a budget or schedule.epochs=[N] for {name}, not both or neither"
            )
        if epochs is not None and len(epochs) != 1:
            raise ConfigError("schedule.epochs", list(epochs), f"one entry [N]: {name} has one stage")

    @classmethod
    def schedule(cls, node: Mapping, n: int, params: dict, cost: float) -> tuple[Schedule, str | None, int | None]:
        """The epochs the loop may run: ``epochs`` as given, or (budget form) as many as the budget (fitted to n
        as a one-stage budget is) could buy at the policy's cheapest epoch (:meth:`epoch_share`), the loop stopping
        once each replica's is spent."""
        _, budget, note = fit_schedule(node["sizes"], node.get("budget"), n)
        if budget is None:
            return Schedule((Stage(n, int(node["epochs"][0])),)), note, None
        share = cls.epoch_share(cls.check(params, budget=budget, selection_cost=cost), cost)
        return Schedule((Stage(n, math.ceil(budget / max(n * share, 1e-9)) + 1),)), note, budget

    @classmethod
    def epoch_share(cls, params: dict, selection_cost: float) -> float:
        """A lower bound on one epoch's cost as a share of n: the budget form plans budget / (share n) epochs."""
        raise NotImplementedError

    def select(self, ep: EpochPlan, ledger: Ledger, net: Network) -> Presentation:
        order = self.source.select(ep, ledger, net).order  # the samplers' shuffles of U [R, n]
        losses = net.errors() / net.Y.shape[1] if self.forward_pass else None  # mse per pattern, scaled units
        return self.choose(ep.index, order, losses)

    def observe(self, shown: Presentation, losses: torch.Tensor) -> None:
        self.finish(shown, losses)

    def choose(self, epoch: int, order: torch.Tensor, losses: torch.Tensor | None) -> EpochChoice:
        """This epoch's presentations from the samplers' shuffles of U ``order`` [R, n] (``losses``: [R, n] by
        pattern when ``forward_pass``, else None). Counts are cut to what each replica's budget pays for
        (:meth:`Ledger.affordable`); patterns left out and forward passes charged go into the ledger."""
        raise NotImplementedError

    def finish(self, choice: EpochChoice, losses: torch.Tensor) -> None:
        """After the epoch's updates, the presented patterns' losses [R, m] (first counts[r] of each row)."""

    def describe(self) -> dict:
        """results.json's parameters of the policy."""
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
