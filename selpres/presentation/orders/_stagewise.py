"""The second interface of an order: one that chooses A_k at the start of stage k (its first epoch) from what the
job knows then, so each replica's sampler gets a new order there (``selpres.presentation.staged`` runs it and
charges it). The job starts from the seed's *stratified* orders: there is no network to ask for A_1 yet.
"""

from __future__ import annotations

from typing import Protocol

import torch

from selpres.presentation.orders._order import Order
from selpres.presentation.orders.stratified import Stratified
from selpres.presentation.schedule import Schedule


class StageJob(Protocol):
    """What does not change in a job, as a stage-wise order reads it (the staged selector is one)."""

    schedule: Schedule  # its stages[k].size = n_k
    seeds: list[int]  # one per replica
    X: torch.Tensor  # U's inputs, scaled [n, inputs]
    Y: torch.Tensor  # U's targets, scaled [n, outputs]
    strata: torch.Tensor  # U's strata ids [n], computed once


class StagewiseOrder(Order):
    """An order whose A_k is chosen at stage k's start: implement :meth:`choose` (and :meth:`Order.candidates`
    if it scores patterns with the network)."""

    stagewise = True

    def orders(self, X: torch.Tensor, gens: list[torch.Generator]) -> list[torch.Tensor]:
        return Stratified(self.strata_bins).orders(X, gens)

    def choose(self, job: StageJob, stage: int, current: torch.Tensor, engine) -> torch.Tensor:
        """Every replica's order [R, n] for stage ``stage`` >= 1, whose first n_k patterns are A_k. ``current``:
        the orders presented so far [R, n]; ``engine.predict`` scores U with the replicas' current networks; ``job``
        holds what does not change in a job (:class:`StageJob`)."""
        raise NotImplementedError
