"""Exact 1-D k-means (selpres.presentation.kmeans): the C kernel's partition is the numpy programme's, bit for bit,
on random scores with ties (AVX-512 and AVX2 builds alike); both are optimal against brute force; what cannot be
computed in C goes to numpy; and a SeTa job records which one ran and has the same numbers either way."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from selpres.native import load_kmeans
from selpres.presentation import kmeans as K

from conftest import cfg_of, numbers, requires_native

AVX2_ONLY = ("-mno-avx512f",)  # after -march=native: the same source at 4 lanes


def _scores(rng: np.random.Generator, kind: int, n: int) -> np.ndarray:
    """Scores as SeTa meets them, and harder: losses (heavy tail) with a block never presented (3.0), values
    rounded to few distinct ones (many ties), mirror-symmetric sets (tied costs: the leftmost split must win),
    and a wide dynamic range."""
    if kind == 0:
        x = rng.exponential(size=n) ** 2
        x[rng.random(n) < 0.1] = 3.0
        return x
    if kind == 1:
        return np.round(rng.random(n) * rng.integers(1, 40)) / 7
    if kind == 2:
        half = rng.random(n // 2 + 1)
        return np.concatenate([half, 2.0 - half])[:n]  # symmetric about 1: every split has a mirror twin
    if kind == 3:
        return np.exp(rng.normal(0, 8, size=n))
    # a few clusters of values 1e-13 apart: splits inside a cluster cost the same to the last bit (equal costs in
    # long runs of candidates, where the leftmost must win)
    return rng.integers(0, 4, size=n) + 1e-13 * rng.integers(0, 200, size=n)


def _cases(seed: int, count: int, largest: int):
    rng = np.random.default_rng(seed)
    for t in range(count):
        n = int(rng.integers(1, largest))
        yield _scores(rng, t % 5, n), int(rng.integers(1, 10))


@requires_native
def test_native_and_numpy_give_the_same_partition_on_random_scores_with_ties():
    for x, G in itertools.chain(_cases(0, 400, 300), _cases(1, 40, 20_000)):
        native, numpy = K.kmeans_edges(x, G), K.kmeans_edges(x, G, native=False)
        assert np.array_equal(native, numpy), (len(x), G)  # the same edges: the same groups
        assert np.array_equal(K.kmeans_1d(x, G), K.kmeans_1d(x, G, native=False))


def _bits(a: np.ndarray) -> np.ndarray:
    return a.view(np.int64)  # equal bits: the same rounding everywhere (and -0.0 is not 0.0)


@requires_native
@pytest.mark.parametrize("flags", [(), AVX2_ONLY], ids=["usual", "avx2"])
def test_every_prefix_sum_cost_and_minimiser_is_numpy_s_bit_for_bit(flags):
    """Not only the same groups: the C kernel's prefix sums, its last layer's costs D_G(i) for every i and every
    layer's minimisers are numpy's, bit for bit (no FMA, no reordered sum, the leftmost of equal costs)."""
    kernel = load_kmeans(flags)
    for x, G in itertools.chain(_cases(5, 200, 300), _cases(6, 12, 20_000)):
        v, w = np.unique(x, return_counts=True)
        if not 2 <= G <= len(v):
            continue
        xc, wf = v - v.mean(), w.astype(np.float64)
        got = kernel.layers(xc, wf, G)
        (W, S, Q), D, args = K._layers_numpy(xc, wf, G)
        for name, want in (("W", W), ("S", S), ("Q", Q)):
            assert np.array_equal(_bits(got[name]), _bits(want)), name
        assert np.array_equal(_bits(got["D"][G:]), _bits(D[G:])), (len(v), G)
        for k, arg in enumerate(args, start=2):
            assert np.array_equal(got["arg"][k - 2, k:], arg[k:]), (len(v), G, k)


@requires_native
def test_the_avx2_build_splits_as_the_usual_one():
    """Four lanes a vector or eight, masked tails or not: the same minimisers (on a CPU without AVX-512 both
    builds are AVX2, and this compares a build with itself)."""
    usual, avx2 = load_kmeans(), load_kmeans(AVX2_ONLY)
    assert usual is not avx2
    for x, G in itertools.chain(_cases(2, 300, 300), _cases(3, 20, 20_000)):
        v, w = np.unique(x, return_counts=True)
        if G > len(v):
            continue
        xc, wf = v - v.mean(), w.astype(np.float64)
        assert np.array_equal(usual.splits(xc, wf, G), avx2.splits(xc, wf, G)), (len(x), G)


def _sse(x: np.ndarray, labels: np.ndarray) -> float:
    return float(sum(((x[labels == g] - x[labels == g].mean()) ** 2).sum() for g in np.unique(labels)))


@pytest.mark.parametrize("native", [True, False])
def test_either_way_no_labelling_has_a_smaller_sum_of_squares(native):
    """Every assignment of up to 7 values to G labels (not only contiguous ones), ties included."""
    rng = np.random.default_rng(4)
    for t in range(120):
        n, G = int(rng.integers(1, 8)), int(rng.integers(1, 4))
        x = np.round(rng.random(n) * 3, 1) if t % 2 else rng.random(n)
        got = K.kmeans_1d(x, G, native=native)
        assert len(np.unique(got)) == min(G, len(np.unique(x)))
        best = min(_sse(x, np.array(lab)) for lab in itertools.product(range(G), repeat=n))
        assert _sse(x, got) == pytest.approx(best, abs=1e-12), (x, G)
    # a tie in cost: {0}, {1, 2} and {0, 1}, {2} both cost 0.5; the leftmost split point wins, either way
    assert K.kmeans_1d(np.array([2.0, 1.0, 0.0]), 2, native=native).tolist() == [1, 1, 0]


@requires_native
def test_what_c_cannot_compute_goes_to_numpy():
    """A candidate cost that overflows (or NaN) makes the kernel answer None; kmeans_edges then runs numpy's
    programme, so both ways end alike (for these, as before the kernel: numpy's IndexError)."""
    kernel = load_kmeans()
    v = np.array([-1e200, 1.0, 2.0, 1e200])
    assert kernel.splits(v - v.mean(), np.ones(4), 2) is None
    assert kernel.splits(np.array([0.0, 1.0, 5.0]), np.ones(3), 2).tolist() == [0, 2]
    for x in ([1.0, 2.0, np.nan, 3.0], [1.0, np.inf, 2.0], [1e200, 1.0, 2.0, -1e200]):
        for native in (True, False):
            with np.errstate(all="ignore"), pytest.raises(IndexError):
                K.kmeans_edges(np.array(x), 2, native=native)
    with pytest.raises(ValueError, match="groups = 4 outside"):
        kernel.splits(np.array([0.0, 1.0]), np.ones(2), 4)


def test_without_the_kernel_a_seta_job_says_so_and_has_the_same_numbers(monkeypatch):
    from selpres.run.train import train

    args = ("schedule=seta", "schedule.epochs=[4]", "replicas=2", "engine=reference")  # only the k-means differs
    runs = {}
    for off in ("0", "1"):
        monkeypatch.setenv("SELPRES_NO_NATIVE", off)
        K.native_kmeans.cache_clear()
        runs[off] = train(cfg_of(*args))
    K.native_kmeans.cache_clear()
    assert runs["1"]["selector"]["kmeans"] == "numpy (disabled by SELPRES_NO_NATIVE)"
    if runs["0"]["selector"]["kmeans"] == "native":
        assert numbers(runs["0"]) == numbers(runs["1"])
