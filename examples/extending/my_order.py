"""Orders of your own, living outside the package (issue 25), named by their import path:

    PYTHONPATH=examples/extending python train.py schedule.order=my_order.CentreOut

results.json's ``schedule.order_class`` records ``my_order.CentreOut``. An order fixed before training subclasses
``selpres.presentation.orders.Order`` and returns one permutation of U per replica (every prefix a training set
A_i); one that chooses A_k at each stage start subclasses ``StagewiseOrder`` (its job starts from the stratified
orders) and says how many patterns it scores there, each charged ``schedule.selection_cost`` of a presentation.

* ``CentreOut``: a curriculum from the interior out: patterns nearest the centre of U's unit cube first, equal
  distances in the replica's random order.
* ``Redrawn``: each stage a fresh uniformly random subset of its size (``reselect`` without the strata), charged as
  if it had scored every pattern of U (a stand-in for a choice that asks the network).
"""

from __future__ import annotations

import torch

from selpres.presentation.orders import Order, StagewiseOrder
from selpres.seeding import generator


class CentreOut(Order):
    def orders(self, X: torch.Tensor, gens: list[torch.Generator]) -> list[torch.Tensor]:
        lo, hi = X.min(0).values, X.max(0).values
        d = ((X - lo) / (hi - lo).clamp_min(1e-12) - 0.5).square().sum(1)  # squared distance from the centre
        out = []
        for g in gens:
            perm = torch.randperm(X.shape[0], generator=g)
            out.append(perm[torch.argsort(d[perm], stable=True)])
        return out


class Redrawn(StagewiseOrder):
    def candidates(self, kept: int, n: int) -> int:
        return n

    def choose(self, job, stage: int, current: torch.Tensor, engine) -> torch.Tensor:
        n = current.shape[1]
        return torch.stack([torch.randperm(n, generator=generator(s, "redrawn", stage)) for s in job.seeds])
