"""Selective Backprop (Jiang et al. 2019, "Accelerating deep learning by focusing on the biggest losers",
arXiv:1910.00762): their probabilistic rule. Not MosaicML Composer's ``selective_backprop``, which keeps a fixed
share of each mini-batch (its highest losses): that form is not implemented here.

Every candidate gets a forward pass; it is back-propagated with probability ``P = F(loss)^β``, F its loss's
percentile in a history of recent losses (β: ``beta``); the chosen ones fill mini-batches of ``optim.batch_size``.
Its forward passes are paid in full (``schedule.selection_cost`` of a presentation each).

Choices the paper leaves open: the history is the current epoch's losses of every candidate, computed in one
forward pass over U at the epoch's start (Jiang et al. interleave forward passes with training and keep the last r
losses; with r = n this is their rule with weights up to one epoch older, like their StaleSB variant, but the
forward passes are charged anyway); F(l) = #{history losses <= l} / |history|. The per-pattern loss is the mean
squared error over the outputs in scaled units. Replica r's draws come from the stream (seed_r, "pruning", epoch).
"""

from __future__ import annotations

import torch

from selpres.errors import ConfigError
from selpres.presentation.pruning._policy import EpochChoice, Param, Policy, pad, percentile
from selpres.seeding import generator


def backprop_probability(losses: torch.Tensor, beta: float) -> torch.Tensor:
    """Selective Backprop's rule: P = F(loss)^β (Jiang et al. 2019)."""
    return percentile(losses) ** beta


class SelectiveBackprop(Policy):
    PARAMS = {"beta": Param(float, lambda v: v >= 0, "a selectivity >= 0 (Jiang et al.: 1, 2, 3)")}
    forward_pass = True

    def __init__(self, params: dict, ledger):
        super().__init__(params, ledger)
        self.beta = float(params["beta"])

    @classmethod
    def check(cls, params: dict, *, budget: int | None, selection_cost: float) -> dict:
        out = super().check(params, budget=budget, selection_cost=selection_cost)
        if budget is not None and not selection_cost > 0:
            raise ConfigError("schedule.selection_cost", selection_cost, "> 0 with a budget: forward passes must cost")
        return out

    @classmethod
    def epoch_share(cls, params: dict, selection_cost: float) -> float:
        return float(selection_cost)  # every candidate's forward pass, even if none is chosen

    def choose(self, epoch: int, order: torch.Tensor, losses: torch.Tensor | None) -> EpochChoice:
        led = self.ledger
        P = backprop_probability(losses, self.beta)  # [R, n] by pattern
        rows, counts = [], []
        c = led.cost_fraction
        for r, seed in enumerate(led.seeds):
            u = torch.rand(led.n, generator=generator(seed, "pruning", epoch), dtype=torch.float64)
            chosen = (u < P[r])[order[r]]  # in the epoch's order
            cum = torch.cumsum(c + chosen.to(torch.float64), 0)
            scored = int((cum <= float(led.remaining[r]) + 1e-9).sum())  # candidates the budget pays for
            picked = order[r][:scored][chosen[:scored]]
            led.charge(c * scored, r)  # every scored candidate's forward pass
            led.left_out[r] += scored - len(picked)  # forwarded, not back-propagated
            rows.append(picked)
            counts.append(len(picked))
        return EpochChoice(pad(rows, 0), None, torch.tensor(counts, dtype=torch.int64))

    def describe(self) -> dict:
        return {"beta": self.beta, "history": "the epoch's losses of every candidate (one forward pass over U)"}


POLICY = SelectiveBackprop
