"""Strata in any dimension (selpres.presentation.partition): the paper's grid kept, k-means cells where a grid
degenerates, and prefixes that estimate U's averages better than random prefixes do."""

from __future__ import annotations

import pytest
import torch

from selpres.presentation import partition as P
from selpres.presentation.orders.stratified import stratified_orders
from selpres.presentation.partition import grid_strata

N, DIM = 8192, 18  # a 6-joint arm's inputs


@pytest.fixture(scope="module")
def cube() -> torch.Tensor:
    return torch.rand(N, DIM, dtype=torch.float64, generator=torch.Generator().manual_seed(1))


@pytest.mark.parametrize("bins", [1, 2, 3])
def test_paper_inputs_keep_the_grid_strata(exemplar, bins):
    """Six inputs: 2 bins give the 64 cells the stratified order has always used (3 bins: 729)."""
    assert torch.equal(P.strata(exemplar.X, bins), grid_strata(exemplar.X, bins))


@pytest.mark.slow  # k-means on 18 inputs
def test_many_inputs_get_64_nonempty_cells_deterministically(cube):
    sid = P.strata(cube, 2)
    assert sid.dtype == torch.long and sid.shape == (N,)
    counts = torch.bincount(sid)
    assert counts.numel() == P.CLUSTERS and int(counts.min()) > 0
    assert int(counts.max()) < 4 * N // P.CLUSTERS  # no cell swallows the set
    assert torch.equal(P.strata(cube.clone(), 2), sid)  # a function of U alone
    # the grid they replace: 2^18 cells for 8192 patterns, nearly one pattern per cell
    assert grid_strata(cube, 2).unique().numel() > 0.9 * N


def test_cells_are_nearest_centre_cells(cube):
    """Each pattern lies in the cell of its nearest cell mean (a Lloyd fixed point, up to the sample the
    centres were fitted on): checked against distances computed here."""
    sid = P.strata(cube, 2)
    U = (cube - cube.min(0).values) / (cube.max(0).values - cube.min(0).values)
    means = torch.stack([U[sid == c].mean(0) for c in range(P.CLUSTERS)])
    nearest = torch.cdist(U, means).argmin(1)
    assert (nearest == sid).double().mean() > 0.97


def test_fewer_patterns_than_cells():
    X = torch.rand(10, DIM, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    sid = P.strata(X, 2)
    assert sid.shape == (10,) and int(sid.max()) < 10


def _variance_ratio(f: torch.Tensor, order_of, k: int, seeds: int = 40) -> float:
    """Mean squared error of the k-prefix mean of f, over seeds, divided by the exact variance of a random
    k-subset's mean, S²/k · (1 − k/n) (sampling without replacement, Cochran eq. 2.8)."""
    n = f.shape[0]
    mse = sum((f[order_of(s)[:k]].mean() - f.mean()).item() ** 2 for s in range(seeds)) / seeds
    return mse / (f.var().item() / k * (1 - k / n))


def _functions(U: torch.Tensor) -> list[torch.Tensor]:
    return [U.sum(1), U[:, 0], U[:, 17], U.square().sum(1), (U[:, :9] - U[:, 9:]).abs().sum(1)]


@pytest.mark.slow  # k-means on 18 inputs
def test_stratified_prefixes_estimate_averages_better_than_random(cube):
    """The measure of a uniform cover that matters for training on a prefix: how well the prefix's average
    of a smooth function matches U's. k-means strata cut that error to about 2/3 of a random prefix's in 18
    dimensions; the 2-bin grid they replace does no better than random order; random order itself matches
    the textbook variance (which checks the yardstick)."""
    fs = _functions(cube)
    sid_kmeans, sid_grid = P.strata(cube, 2), grid_strata(cube, 2)

    def mean_ratio(order_of):
        return sum(_variance_ratio(f, order_of, k) for f in fs for k in (64, 256, 1024)) / (3 * len(fs))

    kmeans = mean_ratio(lambda s: stratified_orders(sid_kmeans, [torch.Generator().manual_seed(s)])[0])
    grid = mean_ratio(lambda s: stratified_orders(sid_grid, [torch.Generator().manual_seed(s)])[0])
    random = mean_ratio(lambda s: torch.randperm(N, generator=torch.Generator().manual_seed(s)))
    assert 0.75 < random < 1.3, random
    assert 0.75 < grid < 1.3, grid
    assert kmeans < 0.8 and kmeans < 0.8 * random, (kmeans, random)
