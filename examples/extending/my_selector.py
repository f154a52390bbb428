"""A selector of your own, living outside the package: the one protocol every method meets, used directly.

    PYTHONPATH=examples/extending python train.py 'schedule.pruning={_target_:my_selector.LossWeighted}'

``LossWeighted`` keeps the paper's stages (the schedule's own: a plain selector runs the configured sizes and
epochs) and presents each replica's shuffle of its current A_i (its ``source``, the staged presentation), but weights
each pattern's loss by its latest training loss over their mean (1 for a pattern not yet presented): the patterns
the network errs most on pull hardest. Its scores are its state (a public tensor: checkpointed, so a killed job
resumes exactly); it charges nothing beyond what it presents (the loop charges that), since it runs no extra
forward pass. results.json's ``selector.name`` records ``my_selector.LossWeighted``.

A selector implements ``select(ep, ledger, net) -> Presentation`` (each replica's patterns, weights and counts) and,
if it learns from the losses, ``observe(shown, losses)``; forward passes it spends choosing (``net.errors()``) it
charges with ``ledger.charge``.
"""

from __future__ import annotations

import torch

from selpres import Presentation, Selector


class LossWeighted(Selector):
    def __init__(self, params: dict, ledger):
        super().__init__(params, ledger)
        self.scores = torch.full((len(ledger.seeds), ledger.n), float("nan"), dtype=torch.float64)

    def select(self, ep, ledger, net) -> Presentation:
        order = self.source.select(ep, ledger, net).order  # [R, m]: each replica's shuffle of A_i
        s = self.scores.gather(1, order)
        known = ~s.isnan()
        mean = torch.where(known, s, 0.0).sum(1, keepdim=True) / known.sum(1, keepdim=True).clamp_min(1)
        weights = torch.where(known & (mean > 0), s / mean, 1.0)
        # counts given: the engine records each presented pattern's loss for observe()
        return Presentation(order, weights, torch.full((order.shape[0],), order.shape[1], dtype=torch.int64))

    def observe(self, shown: Presentation, losses: torch.Tensor) -> None:
        self.scores.scatter_(1, shown.order, losses)
