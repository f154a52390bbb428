"""Selective presentation as a ``torch.utils.data.Sampler``: the single source of presentation order.

The nested training sets A1 ⊂ A2 ⊂ … ⊂ A_{p+1} = U are the prefixes of one *priority order* of the
exemplar set, so nesting holds by construction. The paper chooses each A_i "by a uniform sampling of
the entire training space"; the ``stratified`` order makes that exact for every prefix: the six inputs
are cut into ``bins`` equal-width bins each, and each stratum (cell) appears in every prefix in
proportion to its share of U, within about one pattern (proportional stratified sampling, realised by
sorting on the key (rank-within-stratum + U(0,1)) / stratum size). ``random`` is plain random growth,
the literature's strongest simple baseline (Wu, Dyer & Neyshabur, ICLR 2021).

Within an epoch the current set is reshuffled; ``set_epoch(e)`` picks the epoch (and so the stage),
following ``DistributedSampler``'s convention. The shuffle of epoch e is a counter-based hash of
(seed, e), so a resumed run needs no sampler state beyond the epoch number, and the shuffles of all
replicas of a job are computed in one vectorised step (``epoch_orders``).
"""

from __future__ import annotations

from typing import Iterator

import numpy as np
import torch
from torch.utils.data import Sampler

from selpres.errors import ConfigError
from selpres.schedule import Schedule
from selpres.seeding import derive_seed

ORDERS = ("stratified", "random")


def strata(X: torch.Tensor, bins: int) -> torch.Tensor:
    """Stratum id of every pattern: ``bins`` equal-width bins per input column over U's own range."""
    lo, hi = X.min(0).values, X.max(0).values
    width = torch.where(hi > lo, hi - lo, torch.ones_like(hi))
    cell = ((X - lo) / width * bins).floor().clamp_(0, bins - 1).long()
    radix = bins ** torch.arange(X.shape[1] - 1, -1, -1)
    return (cell * radix).sum(1)


def priority_order(X: torch.Tensor, kind: str, gen: torch.Generator, bins: int = 2) -> torch.Tensor:
    """A permutation of U's indices whose every prefix is a uniform (stratified or random) sample."""
    n = X.shape[0]
    if kind == "random":
        return torch.randperm(n, generator=gen)
    if kind != "stratified":
        raise ConfigError("schedule.order", kind, f"one of {list(ORDERS)}")
    if bins < 1:
        raise ConfigError("schedule.strata_bins", bins, "a whole number >= 1")
    sid = strata(X, bins)
    shuffled = torch.randperm(n, generator=gen)  # random rank within each stratum
    sid_s = sid[shuffled]
    _, inverse, counts = torch.unique(sid_s, return_inverse=True, return_counts=True)
    # rank of each shuffled pattern within its stratum: position minus the stratum's first position
    by_stratum = torch.argsort(inverse, stable=True)
    first = torch.cumsum(counts, 0) - counts
    rank = torch.empty(n, dtype=torch.long)
    rank[by_stratum] = torch.arange(n) - first[inverse[by_stratum]]
    jitter = torch.rand(n, generator=gen, dtype=torch.float64)
    key = (rank.double() + jitter) / counts[inverse].double()
    return shuffled[torch.argsort(key, stable=True)]


_M = np.uint64(0xFFFFFFFFFFFFFFFF)


def _mix64(z: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser: a bijective 64-bit hash, vectorised (uint64 arithmetic wraps)."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def epoch_orders(samplers: list["SelectivePresentationSampler"]) -> torch.Tensor:
    """Every sampler's current epoch order, stacked [R, m]: one vectorised shuffle for all replicas.

    Replica r's shuffle is argsort of hash(key_r, epoch, i) over the current set's positions i, a
    counter-based permutation, so it is the same whether computed alone or with other replicas, and
    costs one argsort for the whole job instead of R generator set-ups per epoch.
    """
    plans = [s._plan[s.epoch] for s in samplers]
    size, count = plans[0].size, plans[0].presentations
    if any((p.size, p.presentations) != (size, count) for p in plans):
        raise ValueError("samplers are at different stages; set_epoch them alike")
    keys = np.array([[s._key, s.epoch] for s in samplers], dtype=np.uint64)
    with np.errstate(over="ignore"):
        base = _mix64(keys[:, 0] ^ _mix64(keys[:, 1] + np.uint64(0x9E3779B97F4A7C15)))
        h = _mix64(base[:, None] + np.arange(size, dtype=np.uint64)[None, :] * np.uint64(0x9E3779B97F4A7C15))
    perm = torch.from_numpy(np.argsort(h, axis=1)[:, :count])  # keys are distinct (bijective hash), so no ties
    orders = torch.stack([s.order[:size] for s in samplers])
    return torch.gather(orders, 1, perm)


class SelectivePresentationSampler(Sampler[int]):
    """Yields the indices presented in one epoch: the current stage's subset of U, freshly shuffled."""

    def __init__(self, order: torch.Tensor, schedule: Schedule, seed: int):
        if order.numel() != schedule.n:
            raise ValueError(f"priority order has {order.numel()} indices but the schedule ends at n = {schedule.n}")
        self.order = order
        self.schedule = schedule
        self.seed = int(seed)
        self._key = derive_seed(self.seed, "shuffle")
        self._plan = schedule.plan()
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        if not 0 <= epoch < len(self._plan):
            raise IndexError(f"epoch {epoch} outside the schedule's {len(self._plan)} epochs")
        self.epoch = epoch

    @property
    def stage(self) -> int:
        return self._plan[self.epoch].stage

    def subset(self, stage: int | None = None) -> torch.Tensor:
        """A_i as indices into U (the first n_i of the priority order)."""
        k = self.stage if stage is None else stage
        return self.order[: self.schedule.stages[k].size]

    def epoch_indices(self) -> torch.Tensor:
        """This epoch's presentation order as one tensor (what the engines consume)."""
        return epoch_orders([self])[0]

    def __iter__(self) -> Iterator[int]:
        return iter(self.epoch_indices().tolist())

    def __len__(self) -> int:
        return self._plan[self.epoch].presentations
