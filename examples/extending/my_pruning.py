"""A pruning policy of your own, living outside the package (issue 25): uniform random pruning.

Each epoch a random share ``prune_ratio`` of all patterns is left out and the kept ones are weighted
1 / (1 - prune_ratio), so the epoch's expected gradient is the full data's (InfoBatch without its scores: the
control that asks whether choosing by loss matters); after a share ``delta`` of the epochs it trains on everything.
It takes InfoBatch's parameters, so InfoBatch's schedule file runs it with one override:

    PYTHONPATH=examples/extending python train.py schedule=infobatch schedule.pruning._target_=my_pruning.UniformPruning

results.json's ``selector.name`` (and ``pruning.policy``) records ``my_pruning.UniformPruning``; the report keys it as
``infobatch[my_pruning.UniformPruning]``, apart from InfoBatch. A policy subclasses
``selpres.presentation.pruning.Policy``: it lists its parameters (checked for it, errors naming
``schedule.pruning.<key>``), says how cheap an epoch can be (the budget form's plan) and chooses each epoch's
patterns from the samplers' shuffles of U, counting what it leaves out in the ledger.
"""

from __future__ import annotations

import torch
from torch.nn.utils.rnn import pad_sequence

from selpres.presentation.pruning import Annealing, EpochChoice, Param, Policy


class UniformPruning(Policy):
    PARAMS = {
        "prune_ratio": Param(float, lambda v: 0 <= v < 1, "a share of the patterns in [0, 1)"),
        "delta": Param(float, lambda v: 0 < v <= 1, "a share of the epochs in (0, 1]"),
    }

    def __init__(self, params: dict, ledger):
        super().__init__(params, ledger)
        self.keep = 1.0 - params["prune_ratio"]
        self.annealing = Annealing(params["delta"], len(ledger.seeds))

    @classmethod
    def epoch_share(cls, params: dict, selection_cost: float) -> float:
        return 1.0 - params["prune_ratio"]

    def choose(self, epoch: int, order: torch.Tensor, losses: torch.Tensor | None) -> EpochChoice:
        led = self.ledger
        rows, weights, counts = [], [], []
        for r in range(len(led.seeds)):
            if self.annealing(r, epoch, led):
                kept, w = order[r], torch.ones(led.n, dtype=torch.float64)
            else:  # the epoch's shuffle is uniformly random already: its first share is a uniform draw
                kept = order[r][: int(self.keep * led.n)]
                w = torch.full((len(kept),), 1.0 / self.keep, dtype=torch.float64)
            led.left_out[r] += led.n - len(kept)
            rows.append(kept)
            weights.append(w)
            counts.append(led.affordable(r, len(kept)))  # what the budget (if any) still pays for
        return EpochChoice(
            pad_sequence(rows, batch_first=True), pad_sequence(weights, batch_first=True), torch.tensor(counts)
        )
