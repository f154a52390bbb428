"""``stratified``, the paper's order: it chooses each A_i "by a uniform sampling of the entire training space";
here that is exact for every prefix: U is cut into strata (:func:`selpres.presentation.partition.strata`: ``bins``
equal-width bins per input, or k-means cells where that grid would have more than 4,096 cells), and each stratum
appears in every prefix in proportion to its share of U, within about one pattern (proportional stratified
sampling, realised by sorting on the key (rank-within-stratum + U(0,1)) / stratum size).
"""

from __future__ import annotations

import torch

from selpres.errors import ConfigError
from selpres.presentation.orders._order import Order
from selpres.presentation.partition import strata


class Stratified(Order):
    def orders(self, X: torch.Tensor, gens: list[torch.Generator]) -> list[torch.Tensor]:
        if self.strata_bins < 1:
            raise ConfigError("schedule.strata_bins", self.strata_bins, "a whole number >= 1")
        return list(stratified_orders(strata(X, self.strata_bins), gens))  # strata: once for every replica


def stratified_orders(sid: torch.Tensor, gens: list[torch.Generator]) -> torch.Tensor:
    """The stratified orders from the strata ids, one row per generator: random rank within each stratum,
    then sorted by (rank + U(0,1)) / stratum size. Each generator draws its permutation and then its
    jitter, exactly as for one replica alone; the rest is batched over the rows (stable sorts and
    element-wise arithmetic: every row is what it would be alone)."""
    n = sid.shape[0]
    draws = [(torch.randperm(n, generator=g), torch.rand(n, generator=g, dtype=torch.float64)) for g in gens]
    shuffled = torch.stack([d[0] for d in draws])  # [R, n] random rank within each stratum
    jitter = torch.stack([d[1] for d in draws])
    _, stratum, counts = torch.unique(sid, return_inverse=True, return_counts=True)  # counts: any order's
    inverse = stratum[shuffled]
    # rank of each shuffled pattern within its stratum: position minus the stratum's first position
    by_stratum = torch.argsort(inverse, dim=1, stable=True)
    first = torch.cumsum(counts, 0) - counts
    rank = torch.empty_like(shuffled)
    rank.scatter_(1, by_stratum, torch.arange(n) - first[inverse.gather(1, by_stratum)])
    key = (rank.double() + jitter) / counts[inverse].double()
    return shuffled.gather(1, torch.argsort(key, dim=1, stable=True))


ORDER = Stratified
