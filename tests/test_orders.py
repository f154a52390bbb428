"""Coverage order (greedy farthest-point, Gonzalez 1985): its defining properties, checked against
independent computations (a plain one-step-at-a-time greedy, distance matrices from torch.cdist)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from selpres.presentation.orders import coverage as O
from selpres.presentation.orders import priority_order, priority_orders
from selpres.presentation.orders.coverage import coverage_order, coverage_orders
from selpres.seeding import generator

PAPER_SIZES = (50, 100, 400, 800)


@pytest.fixture(scope="module")
def X(exemplar):
    return exemplar.X


def _cube(X: torch.Tensor) -> np.ndarray:
    """U's unit cube, computed here: (x - min) / (max - min) per input column (0 for a constant one)."""
    A = X.numpy()
    lo, hi = A.min(0), A.max(0)
    return (A - lo) / np.where(hi > lo, hi - lo, 1.0)


def _first(n: int, seed: int) -> int:
    """The first pattern: one draw from the seed's subset generator."""
    return int(torch.randint(n, (1,), generator=generator(seed, "subset")))


def _plain_greedy(P: np.ndarray, first: int, steps: int | None = None) -> list[int]:
    """The definition, one step at a time: the next pattern is the one farthest (Euclidean) from those
    already chosen, the lowest index on ties; squared distances summed input by input."""
    n = len(P)
    d, chosen, order, i = np.full(n, np.inf), np.zeros(n, bool), [], first
    for _ in range(n if steps is None else steps):
        order.append(i)
        chosen[i] = True
        nd = np.zeros(n)
        for j in range(P.shape[1]):
            nd += (P[:, j] - P[i, j]) ** 2
        d = np.minimum(d, nd)
        d[chosen] = -np.inf
        i = int(np.argmax(d))
    return order


def _radius_profile(P: np.ndarray, order) -> tuple[np.ndarray, np.ndarray]:
    """r[k] = covering radius of U by the first k patterns (max over U of the distance to the nearest of
    them), and s[k] = smallest distance between two of the first k patterns (inf for k = 1), for
    k = 1..n, from torch.cdist's distance matrix."""
    T = torch.from_numpy(P)
    Dm = torch.cdist(T, T).numpy()
    n = len(order)
    near = np.full(n, np.inf)
    r, s = np.empty(n + 1), np.empty(n + 1)
    r[0], s[0], s[1] = np.inf, np.inf, np.inf
    for k, p in enumerate(order, 1):
        if k > 1:
            s[k] = min(s[k - 1], near[p])  # near[p]: p's distance to the k - 1 chosen before it
        near = np.minimum(near, Dm[p])
        r[k] = near.max()
    return r, s


def _prefix_radii(P: np.ndarray, order, sizes) -> np.ndarray:
    r, _ = _radius_profile(P, order)
    return r[list(sizes)]


# --------------------------------------------------------------------------------- the definition


def test_coverage_orders_equal_the_plain_greedy_on_the_paper_set(X):
    """n = 1002 (distances from the n x n table), five replicas ordered together: each is the plain greedy
    from its seed's first pattern."""
    P, seeds = _cube(X), [0, 1, 2, 3, 4]
    got = coverage_orders(X, [generator(s, "subset") for s in seeds])
    for s, order in zip(seeds, got):
        assert order.dtype == torch.int64
        assert order.tolist() == _plain_greedy(P, _first(len(P), s))
    assert torch.equal(priority_order(X, "coverage", generator(3, "subset")), got[3])  # alone == together


def test_coverage_orders_equal_the_plain_greedy_without_the_table(monkeypatch):
    """n = 3000 (above the table's limit: distances computed each step), replicas in batches of two."""
    n = 3000
    X = torch.rand(n, 6, generator=torch.Generator().manual_seed(11), dtype=torch.float64) * 5 - 1
    X[:, 4] = 0.25  # a constant input: its column is 0 in the unit cube
    X[::7, :2] = X[1::7, :2][: len(X[::7])]  # some shared coordinates
    assert n > O._MATRIX_MAX
    monkeypatch.setattr(O, "_BATCH", 2 * n)
    seeds = [5, 6, 7]
    got = coverage_orders(X, [generator(s, "subset") for s in seeds])
    P = _cube(X)
    for s, order in zip(seeds, got):
        assert order.tolist() == _plain_greedy(P, _first(n, s))


def test_ties_go_to_the_lowest_index():
    """Four corners of a square and a centre, worked out by hand: from corner 0 the farthest is the
    opposite corner 3; then corners 1 and 2 tie (distance 1 from both chosen) and 1 wins; then 2; the
    centre (distance sqrt(0.5)) comes last."""
    X = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.5]], dtype=torch.float64)
    seed = next(s for s in range(100) if _first(5, s) == 0)
    assert coverage_order(X, generator(seed, "subset")).tolist() == [0, 3, 1, 2, 4]


# ------------------------------------------------------------------------ the covering property


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_every_prefix_is_within_twice_the_best_cover(X, seed):
    """The greedy certificate, checked on cdist's distances: for every k, the (k+1)-th pattern is the one
    farthest from the first k (so r_k is its distance to them), and the first k+1 patterns are pairwise
    at least r_k apart. Two of those k+1 points then share a centre of any k-point cover, so the best
    k-point cover has radius >= r_k / 2: r_k <= 2 r*_k for every prefix A_i whatever its size."""
    P = _cube(X)
    order = priority_order(X, "coverage", generator(seed, "subset")).numpy()
    assert sorted(order.tolist()) == list(range(len(P)))
    r, s = _radius_profile(P, order)
    k = np.arange(1, len(P))
    assert np.all(r[k] <= s[k + 1] * (1 + 1e-12))
    # random growth breaks the certificate at most prefix sizes: the check can fail
    rnd = priority_order(X, "random", generator(seed, "subset")).numpy()
    r_rnd, s_rnd = _radius_profile(P, rnd)
    assert np.mean(r_rnd[k] <= s_rnd[k + 1] * (1 + 1e-12)) < 0.2


def test_prefixes_cover_better_than_random_and_stratified(X):
    """Mean over five seeds of the covering radius of A_i at the paper's sizes 50, 100, 400, 800."""
    P = _cube(X)
    mean = {}
    for kind in ("coverage", "random", "stratified"):
        radii = [
            _prefix_radii(P, priority_order(X, kind, generator(s, "subset")).numpy(), PAPER_SIZES) for s in range(5)
        ]
        mean[kind] = np.mean(radii, axis=0)
    assert np.all(mean["coverage"] < 0.8 * mean["random"]), mean  # measured: 0.66-0.73
    assert np.all(mean["coverage"] < 0.9 * mean["stratified"]), mean  # measured: 0.69-0.82


def test_coverage_is_deterministic_per_seed(X):
    a, b, c = (priority_order(X, "coverage", generator(s, "subset")) for s in (7, 7, 8))
    assert torch.equal(a, b)
    assert _first(len(X), 7) != _first(len(X), 8) and a[0] != c[0]
    assert not torch.equal(a[:50].sort().values, c[:50].sort().values)  # a different A1


def test_priority_orders_equal_one_call_per_generator(X):
    for kind in ("stratified", "random", "coverage"):
        together = priority_orders(X, kind, [generator(s, "subset") for s in (3, 4)], 2)
        alone = [priority_order(X, kind, generator(s, "subset"), 2) for s in (3, 4)]
        assert all(torch.equal(a, b) for a, b in zip(together, alone)), kind


# ------------------------------------------------------------------- the two-level approximation


def test_two_level_approximation_keeps_exact_centres_and_covers_nearly_as_well():
    """Above ``exact_max``: the first K patterns are the exact greedy's, the order is a permutation and
    deterministic, and every prefix covers U within 1.3x the exact greedy's radius (measured: <= 1.22x)
    and far better than random order."""
    n, K = 4000, 100
    X = torch.rand(n, 6, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    P = _cube(X)
    approx = coverage_order(X, generator(0, "subset"), exact_max=1000, level1=K)
    assert sorted(approx.tolist()) == list(range(n))
    assert torch.equal(approx, coverage_order(X, generator(0, "subset"), exact_max=1000, level1=K))
    exact = coverage_order(X, generator(0, "subset"))
    assert exact.tolist() == _plain_greedy(P, _first(n, 0))
    assert torch.equal(approx[:K], exact[:K])
    sizes = (150, 300, 600, 1000, 2000, 3000, 3900)
    ra, re = _prefix_radii(P, approx.numpy(), sizes), _prefix_radii(P, exact.numpy(), sizes)
    rr = _prefix_radii(P, torch.randperm(n, generator=generator(0, "subset")).numpy(), sizes)
    assert np.all(ra <= 1.3 * re), ra / re
    assert np.all(ra < 0.85 * rr), ra / rr


def test_two_level_approximation_handles_duplicates_and_tiny_cells():
    """Many identical patterns (distance 0) and more first-level centres than distinct points."""
    base = torch.rand(30, 3, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    X = base.repeat(20, 1)  # 600 patterns, 30 distinct
    order = coverage_order(X, generator(1, "subset"), exact_max=50, level1=40)
    assert sorted(order.tolist()) == list(range(600))
    distinct = {tuple(row) for row in X[order[:30]].tolist()}
    assert len(distinct) == 30  # the 30 distinct points come first: every later one is at distance 0
