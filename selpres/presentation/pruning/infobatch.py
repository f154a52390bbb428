"""InfoBatch (Qin et al., "InfoBatch: Lossless training speed up by unbiased dynamic data pruning", ICLR 2024;
code NUS-HPC-AI-Lab/InfoBatch, ``infobatch/infobatch.py``).

Every pattern's score is its latest training loss (initially 3.0, above any loss here, so the first epoch keeps
everything). Each epoch the *well-learned* patterns are those scoring below the mean score; a random
``int((1 - r) |W|)`` of them are kept, their loss weighted by ``1 / (1 - r)`` (r: ``prune_ratio``), the rest are
left out of the epoch; every other pattern is kept with weight 1. A mini-batch's loss is the mean of the weighted
per-pattern losses, so the epoch's expected gradient is the full data's (``tests/test_pruning.py`` checks it
against autograd). The scores of the presented patterns are their losses in that epoch's forward passes (no extra
passes: nothing is charged for them). After a share δ (``delta``) of the epochs it trains on everything with
weight 1 (:class:`~selpres.presentation.pruning._policy.Annealing`).

Choices the paper leaves open: the weight is the published 1/(1 - r), not |W|/k (unbiased when (1 - r)|W| is
whole, biased by less than 1/|W| otherwise); scores of patterns left out keep their old value. Replica r's random
draws come from the stream (seed_r, "pruning", epoch).
"""

from __future__ import annotations

import torch

from selpres.presentation.pruning._policy import Annealing, EpochChoice, Param, ScoredByLoss, pad
from selpres.seeding import generator


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


class InfoBatch(ScoredByLoss):
    PARAMS = {
        "prune_ratio": Param(float, lambda v: 0 <= v < 1, "a share in [0, 1) (Qin et al.: 0.5)"),
        "delta": Param(float, lambda v: 0 < v <= 1, "a share of the epochs in (0, 1] (Qin et al.: 0.875)"),
    }

    def __init__(self, params: dict, ledger):
        super().__init__(params, ledger)
        self.ratio, self.delta = float(params["prune_ratio"]), float(params["delta"])
        self.annealing = Annealing(self.delta, len(ledger.seeds))

    @classmethod
    def epoch_share(cls, params: dict, selection_cost: float) -> float:
        return 1 - float(params["prune_ratio"])  # at least (1 - r) n patterns are kept

    def choose(self, epoch: int, order: torch.Tensor, losses: torch.Tensor | None) -> EpochChoice:
        led = self.ledger
        rows, weights, counts = [], [], []
        for r, seed in enumerate(led.seeds):
            o = order[r]
            if self.annealing(r, epoch, led):
                kept, w = o, torch.ones(len(o), dtype=torch.float64)
            else:
                mask, weight = infobatch_keep(self.scores[r], self.ratio, generator(seed, "pruning", epoch))
                kept = o[mask[o]]
                w = weight[kept]
            led.left_out[r] += led.n - len(kept)
            rows.append(kept)
            weights.append(w)
            counts.append(led.affordable(r, len(kept)))
        return EpochChoice(pad(rows, 0), pad(weights, 0.0), torch.tensor(counts, dtype=torch.int64))


POLICY = InfoBatch
