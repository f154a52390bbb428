"""``reselect``: not nested. Stage k's A_k is a fresh stratified draw of size n_k (stage 1's is the ``stratified``
order's A_1; stage k > 1 draws from the seed's stream ``(seed, "subset", k)``), so consecutive subsets overlap only
by chance, about n_{k-1} n_k / n patterns; the last stage is U. A draw needs no network and is charged nothing."""

from __future__ import annotations

import torch

from selpres.presentation.orders._stagewise import StagewiseOrder
from selpres.presentation.orders.stratified import stratified_orders
from selpres.seeding import generator


class Reselect(StagewiseOrder):
    def choose(self, job, stage: int, current: torch.Tensor, engine) -> torch.Tensor:
        return reselected_orders(job.strata, job.seeds, stage)


def reselected_orders(sid: torch.Tensor, seeds: list[int], stage: int) -> torch.Tensor:
    """Stage ``stage``'s fresh stratified orders [R, n] of U's strata ``sid`` (``partition.strata``, computed
    once per job; stage 0: the ``stratified`` order's own draw)."""
    gens = [generator(s, "subset") if stage == 0 else generator(s, "subset", stage) for s in seeds]
    return stratified_orders(sid, gens)


ORDER = Reselect
