"""``coverage``: greedy farthest-point order (Gonzalez, "Clustering to minimize the maximum intercluster
distance", Theoretical Computer Science 38:293-306, 1985): each next pattern is the one farthest from those already
chosen, so every prefix of k patterns covers U within a radius at most twice the best k-point cover's. It needs no
network. Exact up to ``COVERAGE_EXACT_MAX`` patterns; above that the *two-level* approximation of
``coverage_orders``.

Distances are Euclidean in U's unit cube (each input column mapped onto [0, 1] by U's own range, as for the strata):
with the default ``exemplar`` scaling that is the network's scaled input space up to one common factor, which
leaves a farthest-point order unchanged. Raw and scaled inputs thus define the same order up to rounding, but on
the paper's grid many distances tie exactly, and rounding can break such ties differently (measured: the orders
differ from the 10th pattern on), so one config should always pass the same X (``selpres.run.problem.prepare``
passes the raw exemplar inputs).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from selpres.presentation.orders._order import Order
from selpres.presentation.partition import unit_cube

COVERAGE_EXACT_MAX = 20_000  # exact greedy up to here: O(n^2) time (~a few s at 2e4), O(n) memory
LEVEL1_WORK = 10**8  # two-level approximation: first-level centres K = max(sqrt(n), LEVEL1_WORK / n)
_MATRIX_MAX = 2048  # up to here the exact greedy looks distances up in the n x n matrix (<= 32 MB)
_BATCH = 2**20  # replicas ordered together: about this many distances per step ([replicas, n] float64)
_CHUNK = 2**16  # second level: cells run in lockstep, about this many padded points per chunk


def coverage_orders(
    X: torch.Tensor, gens: list[torch.Generator], exact_max: int = COVERAGE_EXACT_MAX, level1: int | None = None
) -> list[torch.Tensor]:
    """Greedy farthest-point orders of U in its unit cube, one per generator, which draws the first pattern.

    n <= ``exact_max``: the exact greedy (Gonzalez 1985), O(n^2) time and O(n) memory per order (the
    replicas' orders advance together; up to n = 2048 the distances are looked up in the n x n matrix);
    ties in distance go to the lowest index. Larger n: the *two-level* approximation, one order at a
    time. The exact greedy runs for the first K patterns (``level1``, default max(sqrt(n), LEVEL1_WORK /
    n), capped at n), so those prefixes are exact; every other pattern belongs to the Voronoi cell of its
    nearest first-level centre, the greedy continues inside each cell separately (all cells in
    lockstep), and the patterns of all cells follow the K centres in decreasing order of their insertion
    radius (distance to the chosen patterns of their own cell when chosen). Each prefix then still
    covers U within the next pattern's insertion radius, but neighbouring cells ignore each other's
    choices, so near cell borders a prefix holds more patterns than the greedy would for that radius
    (tests/test_orders.py, uniform 6-D data: covering radii within 1.3x the exact greedy's at every
    prefix size). Cost O(n K + n^2 / K): seconds at n = 1e5.
    """
    n = X.shape[0]
    cols = np.ascontiguousarray(unit_cube(X.double()).numpy().T)  # [inputs, n]: one column per input
    firsts = np.array([int(torch.randint(n, (1,), generator=g)) for g in gens], dtype=np.int64)
    if n > exact_max:
        K = min(n, level1 or max(math.isqrt(n), LEVEL1_WORK // n))
        return [_two_level(cols, f, K) for f in firsts]
    C = cols[None]
    if n <= _MATRIX_MAX:  # row i of the table: the very sums _distance_rows would compute
        table = _sq_distances(C, cols.T, np.empty((n, n)), np.empty((n, n)))
    orders = []
    for lo in range(0, len(firsts), max(1, _BATCH // n)):
        start = firsts[lo : lo + max(1, _BATCH // n)]
        if n <= _MATRIX_MAX:
            dist = lambda i, out: np.take(table, i, axis=0, out=out)
        else:
            dist = _distance_rows(C, len(start))
        picks, _ = _farthest_first(np.full((len(start), n), np.inf), n, dist, start)
        orders += [torch.from_numpy(p) for p in picks]
    return orders


class Coverage(Order):
    def orders(self, X: torch.Tensor, gens: list[torch.Generator]) -> list[torch.Tensor]:
        return coverage_orders(X, gens)


def coverage_order(X: torch.Tensor, gen: torch.Generator, **kw) -> torch.Tensor:
    """``coverage_orders`` for one generator."""
    return coverage_orders(X, [gen], **kw)[0]


def _two_level(cols: np.ndarray, first: int, K: int) -> torch.Tensor:
    """The two-level approximation for one first pattern: K exact greedy steps, then within cells."""
    n = cols.shape[1]
    d, owner = np.full((1, n), np.inf), np.zeros((1, n), dtype=np.int64)
    centres, _ = _farthest_first(d, K, _distance_rows(cols[None], 1), np.array([first]), owner)
    return torch.from_numpy(np.concatenate([centres[0], _within_cells(cols, d[0], owner[0], K)]))


def _sq_distances(C: np.ndarray, c: np.ndarray, out: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """out[g, i] = sum_j (C[g, j, i] - c[g, j])^2 (C may have one group for all), column by column in a
    fixed order: identical on every machine, unlike a BLAS product, and in every code path."""
    np.subtract(C[:, 0], c[:, 0, None], out=out)
    np.multiply(out, out, out=out)
    for j in range(1, C.shape[1]):
        np.subtract(C[:, j], c[:, j, None], out=tmp)
        np.multiply(tmp, tmp, out=tmp)
        out += tmp
    return out


def _distance_rows(C: np.ndarray, groups: int):
    """``dist(i, out)`` for ``_farthest_first``: out[g] = squared distances from point i[g] of group g to
    all points of that group (C: [G, inputs, m], or [1, inputs, m] shared by all groups)."""
    tmp = np.empty((groups, C.shape[2]))
    group = 0 if C.shape[0] == 1 else np.arange(groups)
    return lambda i, out: _sq_distances(C, C[group, :, i], out, tmp)


def _farthest_first(
    d: np.ndarray, steps: int, dist, start: np.ndarray | None = None, owner: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Greedy farthest-point steps in G independent groups at once.

    d: [G, m] squared distance of each point to its group's chosen set, updated in place (-inf marks a
    chosen point or padding; +inf: nothing chosen yet); ``dist(i, out)`` fills out[g] with the squared
    distances from pick i[g]. Each step every group picks its farthest point (``start`` at step 0 if
    given) and lowers d to the distance to it; ``owner`` (if given) records for each point the step whose
    pick is nearest. Returns the picks [G, steps] and their squared insertion radii [G, steps] (-inf once
    a group has nothing left).
    """
    G, m = d.shape
    rows = np.arange(G)
    picks = np.empty((G, steps), dtype=np.int64)
    radii = np.empty((G, steps))
    nd = np.empty((G, m))
    for t in range(steps):
        i = start if t == 0 and start is not None else d.argmax(1)
        picks[:, t], radii[:, t] = i, d[rows, i]
        dist(i, nd)
        if owner is not None:
            np.copyto(owner, t, where=nd < d)
        np.minimum(d, nd, out=d)
        d[rows, i] = -np.inf
    return picks, radii


def _within_cells(cols: np.ndarray, d: np.ndarray, owner: np.ndarray, K: int) -> np.ndarray:
    """The two-level approximation's second level: the greedy inside each first-level cell, continued
    from the distances to the cell's centre, cells in lockstep chunks of similar size; all picks merged
    by decreasing insertion radius (ties: lower index first)."""
    members = np.argsort(owner, kind="stable")  # points grouped by cell
    sizes = np.bincount(owner, minlength=K)
    starts = np.cumsum(sizes) - sizes
    ids, rads = [], []
    by_size = np.argsort(-sizes, kind="stable")
    lo = 0
    while lo < K:
        m = int(sizes[by_size[lo]])
        hi = min(K, lo + max(1, _CHUNK // max(m, 1)))
        cells = by_size[lo:hi]
        lo = hi
        if m <= 1:  # cells of their centre alone: nothing left to order
            continue
        slot = np.arange(m)
        valid = slot[None, :] < sizes[cells][:, None]
        idx = np.where(valid, starts[cells][:, None] + slot[None, :], 0)
        idx = members[idx]  # [G, m] point ids, padded with point members[0]
        dc = np.where(valid, d[idx], -np.inf)  # the centres are -inf already (chosen)
        C = np.ascontiguousarray(cols[:, idx].transpose(1, 0, 2))  # [G, inputs, m]
        picks, radii = _farthest_first(dc, m - 1, _distance_rows(C, len(cells)))
        keep = radii > -np.inf
        ids.append(np.take_along_axis(idx, picks, 1)[keep])
        rads.append(radii[keep])
    ids, rads = np.concatenate(ids), np.concatenate(rads)
    return ids[np.lexsort((ids, -rads))]


ORDER = Coverage
