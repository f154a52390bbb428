"""What ``loss_high`` and ``loss_low`` share: adaptive, nested growth by the current network's error.

At each enlargement A_k = A_{k-1} plus the n_k - n_{k-1} patterns of U \\ A_{k-1} on which the replica's *current*
network errs most (hard first) or least (easy first): per-pattern squared error summed over the outputs, in scaled
units. Ties go to the earlier pattern of the seed's stratified order: the candidates are kept in that order, and
the chosen ones join A_k in it too. All replicas are scored together by one forward pass over U
(``engine.predict``), and the chosen patterns are found by a partition, not a sort (at R = 1000: ~13 ms against
~60-80 ms for a stable sort). Every candidate outside A_{k-1} is scored, and charged.
"""

from __future__ import annotations

import numpy as np
import torch

from selpres.presentation.orders._stagewise import StagewiseOrder
from selpres.presentation.selection import errors_of


class LossOrder(StagewiseOrder):
    hard: bool  # True: the patterns the network errs most on join first

    def candidates(self, kept: int, n: int) -> int:
        return n - kept

    def choose(self, job, stage: int, current: torch.Tensor, engine) -> torch.Tensor:
        kept, size = job.schedule.stages[stage - 1].size, job.schedule.stages[stage].size
        return enlarge_by_loss(current, errors_of(engine, job.X, job.Y), kept, size - kept, self.hard)


def enlarge_by_loss(orders: torch.Tensor, errors: torch.Tensor, kept: int, added: int, hard: bool) -> torch.Tensor:
    """New orders [R, n]: each row's first ``kept`` patterns (A_{k-1}) stay; of the candidates after them,
    the ``added`` with the largest (``hard``) or smallest ``errors`` [R, n] come next and the others after,
    both in the order the candidates were in (so equal errors go to the earlier candidate).

    Exactly the first ``added`` of a stable sort by error, found by a partition: v = the added-th value, then
    every candidate beyond v and the first of those equal to v."""
    tail = orders[:, kept:]
    e = errors.gather(1, tail).numpy()
    R, c = e.shape
    at = c - added if hard else added - 1  # v's position in each row sorted ascending
    v = np.partition(e, at, axis=1)[:, at, None]
    beyond = e > v if hard else e < v
    tied = e == v
    need = added - beyond.sum(1, keepdims=True)
    chosen = beyond | (tied & (np.cumsum(tied, 1) <= need))
    t = tail.numpy()  # numpy's boolean indexing: ~4x torch's here
    rows = (orders[:, :kept].numpy(), t[chosen].reshape(R, added), t[~chosen].reshape(R, c - added))
    return torch.from_numpy(np.concatenate(rows, axis=1))
