"""Dynamic data pruning as schedules: InfoBatch and Selective Backprop, charged on the same cost axis.

Selective presentation decides *before* each stage which patterns to present. The methods it competes with
today decide every epoch from the network's losses (issue 22):

* **InfoBatch** (Qin et al., ICLR 2024; code NUS-HPC-AI-Lab/InfoBatch, ``infobatch/infobatch.py``). Every
  pattern's score is its latest training loss (initially 3.0, above any loss here, so the first epoch keeps
  everything). Each epoch the *well-learned* patterns are those scoring below the mean score; a random
  ``int((1 - r) |W|)`` of them are kept, their loss weighted by ``1 / (1 - r)`` (r: ``schedule.prune_ratio``),
  the rest are left out of the epoch; every other pattern is kept with weight 1. A mini-batch's loss is the
  mean of the weighted per-pattern losses, so the epoch's expected gradient is the full data's
  (``tests/test_pruning.py`` checks it against autograd). The scores of the presented patterns are their
  losses in that epoch's forward passes (no extra passes: nothing is charged for them). After a share δ
  (``schedule.delta``) of the epochs it trains on everything with weight 1 (annealing).
* **Selective Backprop** (Jiang et al. 2019, "Accelerating deep learning by focusing on the biggest losers",
  arXiv:1910.00762). Every candidate gets a forward pass; it is back-propagated with probability
  ``P = F(loss)^β``, F its loss's percentile in a history of recent losses (β: ``schedule.beta``); the
  chosen ones fill mini-batches of ``optim.batch_size``.

Cost (the paper's T, in presentations): a back-propagated pattern costs one presentation; a forward pass
only to choose costs ``schedule.selection_cost`` of one (1/3, as the loss orders of
:mod:`selpres.presentation.selection` are charged). InfoBatch's scores come from its training passes and cost
nothing extra; Selective Backprop pays its forward passes in full.

**Budget form.** With ``schedule.budget`` every replica trains until it has spent exactly that cost (the last
epoch cut short, as a compute-matched run's is), so the rival and conventional training stopped at the same
total cost are compared at one cost by construction, and the cosine learning rate decays over that budget.
InfoBatch's annealing then begins, per replica, once its remaining budget buys no more full epochs than
(1 - δ)/δ times the epochs it has done, so the last share 1 - δ of its epochs are full ones, as published
for an epoch count. Without a budget the schedule runs ``schedule.epochs`` epochs (InfoBatch anneals from
epoch δN) and costs what it costs (recorded); a cosine rate then decays over n·N presentations, more than the
run spends, so it does not reach zero (use the budget form with ``optim.lr_schedule=cosine``).

**Choices the papers leave open** (also in the config files): Selective Backprop's history is the current
epoch's losses of every candidate, computed in one forward pass over U at the epoch's start (Jiang et al.
interleave forward passes with training and keep the last r losses; with r = n this is their rule with
weights up to one epoch older, like their StaleSB variant, but the forward passes are charged anyway);
F(l) = #{history losses <= l} / |history|. The per-pattern loss is the mean squared error over the outputs
in scaled units. InfoBatch's weight is the published 1/(1 - r), not |W|/k: unbiased when (1 - r)|W| is whole,
biased by less than 1/|W| otherwise. Replica r's random draws come from the stream (seed_r, "pruning", epoch).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from selpres.errors import ConfigError
from selpres.presentation.schedule import Schedule, Stage
from selpres.presentation.selection import errors_of, one_thread
from selpres.seeding import generator

PRUNINGS = ("infobatch", "selective_backprop")
INITIAL_SCORE = 3.0  # InfoBatch's initial score: above every loss, so the first epoch keeps all patterns


@dataclass
class EpochChoice:
    """What each replica presents this epoch: the first ``counts[r]`` entries of ``order[r]``, each weighted."""

    order: torch.Tensor  # [R, m] int64 (padded past counts[r])
    weights: torch.Tensor | None  # [R, m] float64 or None (all 1)
    counts: torch.Tensor  # [R] int64


def percentile(losses: torch.Tensor) -> torch.Tensor:
    """F(l_i) = #{j : l_j <= l_i} / n along the last dimension: [R, n] -> [R, n]."""
    s, _ = torch.sort(losses, dim=-1)
    return torch.searchsorted(s.contiguous(), losses.contiguous(), right=True).to(torch.float64) / losses.shape[-1]


def backprop_probability(losses: torch.Tensor, beta: float) -> torch.Tensor:
    """Selective Backprop's rule: P = F(loss)^β (Jiang et al. 2019)."""
    return percentile(losses) ** beta


def infobatch_keep(scores: torch.Tensor, ratio: float, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """One replica's pruning draw over its n scores: (kept mask [n] bool, weight [n] float64).
    Well-learned = score below the mean; int((1 - ratio) |W|) of them kept at weight 1/(1 - ratio)."""
    keep_ratio = 1.0 - ratio
    well = scores < scores.mean()
    W = torch.nonzero(well).flatten()
    k = int(keep_ratio * len(W))
    chosen = W[torch.randperm(len(W), generator=gen)[:k]]
    kept = ~well
    kept[chosen] = True
    weight = torch.ones(scores.shape[0], dtype=torch.float64)
    weight[chosen] = 1.0 / keep_ratio
    return kept, weight


def _pad(rows: list[torch.Tensor], fill) -> torch.Tensor:
    m = max((len(r) for r in rows), default=0)
    out = torch.full((len(rows), m), fill, dtype=rows[0].dtype if rows else torch.int64)
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


class Pruning:
    """The state of one job's pruning over its replicas: costs so far, and (InfoBatch) the scores."""

    def __init__(self, kind: str, cfg_schedule, n: int, seeds: list[int], budget: int | None, epochs: int | None):
        self.kind, self.n, self.seeds = kind, n, list(seeds)
        self.budget, self.epochs = budget, epochs
        self.cost_fraction = float(cfg_schedule.selection_cost)
        R = len(seeds)
        self.spent = torch.zeros(R, dtype=torch.float64)  # training + charged forward passes, per replica
        self.trained = torch.zeros(R, dtype=torch.float64)  # back-propagated presentations
        self.charged = torch.zeros(R, dtype=torch.float64)  # forward passes charged for choosing
        # patterns not back-propagated, summed over epochs: InfoBatch's pruned, Selective Backprop's scored not chosen
        self.left_out = torch.zeros(R, dtype=torch.float64)
        self.epochs_done = torch.zeros(R, dtype=torch.int64)
        if kind == "infobatch":
            self.ratio, self.delta = float(cfg_schedule.prune_ratio), float(cfg_schedule.delta)
            self.scores = torch.full((R, n), INITIAL_SCORE, dtype=torch.float64)
            self.annealing = torch.zeros(R, dtype=torch.bool)
        else:
            self.beta = float(cfg_schedule.beta)

    @property
    def remaining(self) -> torch.Tensor:
        if self.budget is None:
            return torch.full_like(self.spent, math.inf)
        return self.budget - self.spent

    @property
    def exhausted(self) -> bool:
        """Every replica has spent its budget (a fraction of a presentation left cannot buy one)."""
        return self.budget is not None and bool((self.remaining < min(1.0, 1.0 + self.cost_fraction)).all())

    def choose(self, epoch: int, order: torch.Tensor, engine, X: torch.Tensor, Y: torch.Tensor) -> EpochChoice:
        """This epoch's presentations from the samplers' shuffles of U ``order`` [R, n]."""
        if self.kind == "infobatch":
            return self._infobatch(epoch, order)
        with one_thread():
            losses = errors_of(engine, X, Y) / Y.shape[1]  # per-pattern mse: the forward pass over U
        return self._selective_backprop(epoch, order, losses)

    def _infobatch(self, epoch: int, order: torch.Tensor) -> EpochChoice:
        rows, weights, counts = [], [], []
        for r, seed in enumerate(self.seeds):
            if self.budget is None:
                self.annealing[r] = epoch >= self.delta * self.epochs
            elif not self.annealing[r]:
                full_left = float(self.remaining[r]) / self.n
                self.annealing[r] = full_left * self.delta <= (1 - self.delta) * int(self.epochs_done[r])
            o = order[r]
            if self.annealing[r]:
                kept, w = o, torch.ones(len(o), dtype=torch.float64)
            else:
                mask, weight = infobatch_keep(self.scores[r], self.ratio, generator(seed, "pruning", epoch))
                kept = o[mask[o]]
                w = weight[kept]
            self.left_out[r] += self.n - len(kept)
            rows.append(kept)
            weights.append(w)
            left = float(self.remaining[r])
            counts.append(len(kept) if math.isinf(left) else min(len(kept), int(math.floor(left + 1e-9))))
        return EpochChoice(_pad(rows, 0), _pad(weights, 0.0), torch.tensor(counts, dtype=torch.int64))

    def _selective_backprop(self, epoch: int, order: torch.Tensor, losses: torch.Tensor) -> EpochChoice:
        P = backprop_probability(losses, self.beta)  # [R, n] by pattern
        rows, counts = [], []
        c = self.cost_fraction
        for r, seed in enumerate(self.seeds):
            u = torch.rand(self.n, generator=generator(seed, "pruning", epoch), dtype=torch.float64)
            chosen = (u < P[r])[order[r]]  # in the epoch's order
            cum = torch.cumsum(c + chosen.to(torch.float64), 0)
            scored = int((cum <= float(self.remaining[r]) + 1e-9).sum())  # candidates the budget pays for
            picked = order[r][:scored][chosen[:scored]]
            self.charged[r] += c * scored
            self.spent[r] += c * scored
            self.left_out[r] += scored - len(picked)  # forwarded, not back-propagated
            rows.append(picked)
            counts.append(len(picked))
        return EpochChoice(_pad(rows, 0), None, torch.tensor(counts, dtype=torch.int64))

    def finish(self, choice: EpochChoice, losses: torch.Tensor) -> None:
        """After the epoch's updates: costs, and InfoBatch's scores from the losses [R, m] of the presented."""
        self.trained += choice.counts.to(torch.float64)
        self.spent += choice.counts.to(torch.float64)
        self.epochs_done += (choice.counts > 0).to(torch.int64)
        if self.kind == "infobatch":
            for r in range(len(self.seeds)):
                k = int(choice.counts[r])
                self.scores[r, choice.order[r, :k]] = losses[r, :k]

    def describe(self) -> dict:
        """results.json's ``pruning``: what was applied and what it cost, per replica."""
        params = (
            {"prune_ratio": self.ratio, "delta": self.delta}
            if self.kind == "infobatch"
            else {"beta": self.beta, "history": "the epoch's losses of every candidate (one forward pass over U)"}
        )
        return {
            "kind": self.kind,
            **params,
            "budget": self.budget,
            "selection_cost": self.cost_fraction,
            "cost": self.spent.tolist(),
            "trained_presentations": self.trained.tolist(),
            "charged_presentations": self.charged.tolist(),
            "left_out": self.left_out.tolist(),
            "epochs": self.epochs_done.tolist(),
            "checkpointed": False,  # the scores are not in a checkpoint: a killed pruning job starts again
        }


def check_pruning(s) -> str | None:
    """The pruning keys of ``cfg.schedule`` (ConfigError naming the key); returns the kind or None."""
    kind = None if s.pruning is None else s.pruning.value
    keys = {"infobatch": ("prune_ratio", "delta"), "selective_backprop": ("beta",)}
    for other, ks in keys.items():
        for k in ks:
            if s[k] is not None and other != kind:
                raise ConfigError(f"schedule.{k}", s[k], f"null: only schedule.pruning={other} reads it")
            if s[k] is None and other == kind:
                raise ConfigError(f"schedule.{k}", None, f"a value: schedule.pruning={kind} reads it")
    if kind is None:
        return None
    if kind == "infobatch":
        if not 0 <= s.prune_ratio < 1:
            raise ConfigError("schedule.prune_ratio", s.prune_ratio, "a share in [0, 1) (Qin et al.: 0.5)")
        if not 0 < s.delta <= 1:
            raise ConfigError("schedule.delta", s.delta, "a share of the epochs in (0, 1] (Qin et al.: 0.875)")
    elif not s.beta >= 0:
        raise ConfigError("schedule.beta", s.beta, "a selectivity >= 0 (Jiang et al.: 1, 2, 3)")
    if list(s.sizes) != [1.0]:
        raise ConfigError("schedule.sizes", list(s.sizes), f"[1.0]: {kind} prunes all of U every epoch")
    if s.order.value != "random":
        raise ConfigError("schedule.order", s.order.value, f"random: {kind} shuffles all of U every epoch")
    if (s.budget is None) == (s.epochs is None):
        raise ConfigError(
            "schedule.budget", s.budget, f"either a budget or schedule.epochs=[N] for {kind}, not both or neither"
        )
    if s.epochs is not None and len(s.epochs) != 1:
        raise ConfigError("schedule.epochs", list(s.epochs), f"one entry [N]: {kind} has one stage")
    if kind == "selective_backprop" and s.budget is not None and not s.selection_cost > 0:
        raise ConfigError("schedule.selection_cost", s.selection_cost, "> 0 with a budget: forward passes must cost")
    return kind


def pruning_plan(kind: str, cfg_schedule, n: int, budget: int | None) -> Schedule:
    """The epochs the loop may run: ``schedule.epochs`` as given, or (budget form) as many as the budget
    could buy at the cheapest epoch (InfoBatch keeps at least (1 - r) n, Selective Backprop pays c n for its
    forward passes); the loop stops once the budget is spent."""
    if budget is None:
        return Schedule((Stage(n, int(cfg_schedule.epochs[0])),))
    cheapest = n * (
        (1 - float(cfg_schedule.prune_ratio)) if kind == "infobatch" else float(cfg_schedule.selection_cost)
    )
    return Schedule((Stage(n, math.ceil(budget / max(cheapest, 1e-9)) + 1),))
