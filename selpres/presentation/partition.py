"""Strata of the exemplar set for the stratified order, in any input dimension (issue 11, item 6).

The stratified order makes every prefix A_i a proportional stratified sample of U: each stratum appears
in A_i in proportion to its share of U. What that buys is Cochran's (Sampling Techniques, 3rd ed. 1977,
section 5.6): the prefix mean of any function f of the inputs has the variance of a random prefix of the
same size times the *within*-strata share of f's variance, so the strata should leave little variance
inside them, for every smooth f at once.

* Few inputs (``bins ** inputs <= GRID_MAX_CELLS``): ``bins`` equal-width bins per input over U's range,
  the paper's case (6 inputs, 2 bins: 64 cells) unchanged (``selpres.presentation.orders.strata``).
* More inputs: the grid degenerates. Two bins per input make 2^18 = 262,144 cells for a 6-joint arm's 18
  inputs, more than there are patterns, so nearly every pattern is its own cell and proportional
  allocation is random order (measured in tests/test_partition.py). There the strata are ``clusters``
  (64) k-means cells of U in its unit cube: k-means minimises the mean squared distance of a pattern to
  its cell's centre, and for an L-Lipschitz f the within-cell variance is at most L² times that
  distance, so the partition bounds the within-strata variance of every smooth f, in any dimension,
  with as many cells as the paper's grid had. Lloyd's algorithm (k-means++ seeding, Arthur & Vassilvitskii
  2007) runs on at most ``FIT_POINTS`` patterns, then every pattern joins its nearest centre (about 1-3 s
  for n = 10^6 and 18 inputs on the 2-core development machine).

The strata are a deterministic function of U (the seed is fixed): every replica and every job of a
config gets the same partition, as with the grid.
"""

from __future__ import annotations

import torch

GRID_MAX_CELLS = 4096  # equal-width grids up to this many cells (the paper's: 2^6 = 64; 3^6 = 729)
CLUSTERS = 64  # k-means strata above it: as many cells as the paper's grid
FIT_POINTS = 1 << 14  # Lloyd's iterations on a sample of this many patterns
ITERATIONS = 50  # at most; stops when no sample pattern changes cell
_ROWS = 1 << 16  # patterns assigned per distance block
SEED = 0  # the partition is part of the config's task, not of a replica


def unit_cube(X: torch.Tensor) -> torch.Tensor:
    """Every input column mapped onto [0, 1] by U's own range (a constant column onto 0)."""
    lo, hi = X.min(0).values, X.max(0).values
    width = torch.where(hi > lo, hi - lo, torch.ones_like(hi))
    return (X - lo) / width


def grid_strata(X: torch.Tensor, bins: int) -> torch.Tensor:
    """Stratum id of every pattern: ``bins`` equal-width bins per input column over U's own range."""
    cell = (unit_cube(X) * bins).floor().clamp_(0, bins - 1).long()
    radix = bins ** torch.arange(X.shape[1] - 1, -1, -1)
    return (cell * radix).sum(1)


def strata(
    X: torch.Tensor, bins: int = 2, *, clusters: int = CLUSTERS, max_grid_cells: int = GRID_MAX_CELLS
) -> torch.Tensor:
    """Stratum id of every pattern of ``X [n, inputs]`` (LongTensor ``[n]``): the equal-width grid when
    it has at most ``max_grid_cells`` cells, else ``clusters`` k-means cells (see the module docstring)."""
    if bins ** X.shape[1] <= max_grid_cells:
        return grid_strata(X, bins)
    return cluster_strata(X, clusters)


def _nearest(points: torch.Tensor, centres: torch.Tensor) -> torch.Tensor:
    """Index of each point's nearest centre (squared Euclidean distance), in blocks of rows."""
    c2 = centres.square().sum(1)
    out = torch.empty(points.shape[0], dtype=torch.long)
    for s in range(0, points.shape[0], _ROWS):
        p = points[s : s + _ROWS]
        out[s : s + _ROWS] = torch.addmm(c2, p, centres.T, alpha=-2.0).argmin(1)  # |p|² is common to a row
    return out


def _seed_centres(points: torch.Tensor, k: int, gen: torch.Generator) -> torch.Tensor:
    """k-means++: each next centre drawn with probability proportional to the squared distance to the
    nearest centre so far."""
    first = int(torch.randint(points.shape[0], (1,), generator=gen))
    centres = [points[first]]
    d2 = (points - points[first]).square().sum(1)
    for _ in range(1, k):
        pick = (
            int(torch.multinomial(d2, 1, generator=gen))
            if float(d2.sum()) > 0
            else int(torch.randint(points.shape[0], (1,), generator=gen))
        )
        centres.append(points[pick])
        d2 = torch.minimum(d2, (points - points[pick]).square().sum(1))
    return torch.stack(centres)


def cluster_strata(X: torch.Tensor, clusters: int = CLUSTERS) -> torch.Tensor:
    """``clusters`` k-means cells of U in its unit cube (fewer if U has fewer patterns), ids 0..k-1."""
    U = unit_cube(X.double())
    n = U.shape[0]
    k = max(1, min(int(clusters), n))
    gen = torch.Generator().manual_seed(SEED)
    fit = U if n <= FIT_POINTS else U[torch.randperm(n, generator=gen)[:FIT_POINTS]]
    centres = _seed_centres(fit, k, gen)
    cell = _nearest(fit, centres)
    for _ in range(ITERATIONS):
        member = torch.nn.functional.one_hot(cell, k).to(fit.dtype)  # [points, k]: a matmul, not a scatter
        sums, counts = member.T @ fit, member.sum(0).unsqueeze(1)
        centres = torch.where(counts > 0, sums / counts.clamp(min=1), centres)  # an empty cell keeps its centre
        moved = _nearest(fit, centres)
        if torch.equal(moved, cell):
            break
        cell = moved
    ids = _nearest(U, centres)
    _, ids = torch.unique(ids, return_inverse=True)  # ids 0..k-1 over the cells that hold patterns
    return ids
