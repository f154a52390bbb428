"""Exact 1-D k-means: an optimal (least within-group sum of squares) partition of scores into at most G groups,
for SeTa's groups (``selpres.presentation.pruning.seta``) or any other caller.

Clusters of an optimal 1-D k-means are contiguous in sorted order, so the optimum is a dynamic programme over split
points of the sorted distinct values (weighted by their multiplicities, so equal values share a group),
D_k(i) = min_j D_{k-1}(j) + SSE(j, i), SSE from prefix sums. The sum-of-squares cost obeys the quadrangle
inequality, so the leftmost optimal split is monotone in i and each layer is solved by divide and conquer
(Grønlund et al. 2017, "Fast exact k-means, k-medians and Bregman divergence clustering in 1D"): O(G n log n).
Exact and deterministic: no seeds, no iterations to converge.

Two implementations of the one programme: ``kernels/kmeans1d.c`` (``selpres.native.load_kmeans``), used where it
builds, and numpy here (vectorised one recursion depth at a time), the fallback without a compiler or AVX2/FMA. The
C code does numpy's floating-point operations in its order, so both give the same partition (tested on random
scores with ties); :func:`kmeans_implementation` says which one runs, for the job's record.

May import: ``selpres.native`` and numpy.
"""

from __future__ import annotations

import functools
import threading

import numpy as np


def _layer(prev: np.ndarray, prefix: tuple[np.ndarray, ...], k: int, d: int) -> tuple[np.ndarray, np.ndarray]:
    """D_k(i) for i = k..d and its leftmost optimal split j, by divide and conquer over i, one depth at a time."""
    D = np.full(d + 1, np.inf)
    arg = np.zeros(d + 1, dtype=np.int64)
    tasks = np.array([[k, d, k - 1, d - 1]], dtype=np.int64)  # rows: i_lo, i_hi, j_lo, j_hi
    while len(tasks):
        i_lo, i_hi, j_lo, j_hi = tasks.T
        mid = (i_lo + i_hi) // 2
        hi = np.minimum(j_hi, mid - 1)
        lens = hi - j_lo + 1  # >= 1: j_lo <= i_lo - 1 <= mid - 1 throughout
        starts = np.concatenate(([0], np.cumsum(lens)[:-1]))
        j = np.repeat(j_lo - starts, lens) + np.arange(int(lens.sum()))  # each task's candidate splits
        W, S, Q = prefix  # the SSE of distinct values j..mid-1: (Q - S^2 / W) over that range
        ws, ss = np.repeat(W[mid], lens) - W[j], np.repeat(S[mid], lens) - S[j]
        vals = prev[j] + ((np.repeat(Q[mid], lens) - Q[j]) - ss * ss / ws)
        best = np.minimum.reduceat(vals, starts)
        first = np.minimum.reduceat(np.where(vals == np.repeat(best, lens), np.arange(len(vals)), len(vals)), starts)
        opt = j[first]
        D[mid], arg[mid] = best, opt
        left = np.stack([i_lo, mid - 1, j_lo, opt], 1)[mid - 1 >= i_lo]
        right = np.stack([mid + 1, i_hi, opt, j_hi], 1)[mid + 1 <= i_hi]
        tasks = np.concatenate([left, right])
    return D, arg


def _layers_numpy(x: np.ndarray, w: np.ndarray, G: int) -> tuple[tuple[np.ndarray, ...], np.ndarray, list[np.ndarray]]:
    """The programme over the sorted distinct (centred) values ``x`` of multiplicities ``w``: the prefix sums
    (W, S, Q), the last layer's D and every layer's leftmost minimisers (layers 2..G)."""
    d = len(x)
    W = np.concatenate(([0.0], np.cumsum(w)))
    S = np.concatenate(([0.0], np.cumsum(w * x)))
    Q = np.concatenate(([0.0], np.cumsum(w * x * x)))

    D = np.full(d + 1, np.inf)
    D[1:] = Q[1:] - S[1:] ** 2 / W[1:]  # one group: the SSE of the distinct values 0..i-1
    args = []
    for k in range(2, G + 1):
        D, arg = _layer(D, (W, S, Q), k, d)
        args.append(arg)
    return (W, S, Q), D, args


def _starts_numpy(x: np.ndarray, w: np.ndarray, G: int) -> np.ndarray:
    """Each group's first index into the sorted distinct (centred) values ``x`` of multiplicities ``w``."""
    d = len(x)
    _, _, args = _layers_numpy(x, w, G)
    bounds, end = [d], d  # backtrack the split points from the last group
    for arg in reversed(args):
        end = int(arg[end])
        bounds.append(end)
    return np.array([0, *sorted(bounds[1:])], dtype=np.int64)


@functools.lru_cache(maxsize=1)
def native_kmeans():
    """``(kernel, None)`` where ``kernels/kmeans1d.c`` loads here, else ``(None, why)``; decided once per process,
    so a missing compiler is not retried every epoch."""
    from selpres.native import KernelUnavailable, load_kmeans

    try:
        return load_kmeans(), None
    except KernelUnavailable as exc:
        return None, str(exc)


def kmeans_implementation() -> str:
    """What computes the k-means in this process, for the job's record: ``native``, or ``numpy (why)``. Both give
    the same partition (tested); only the speed differs."""
    kernel, why = native_kmeans()
    return "native" if kernel is not None else f"numpy ({why})"


class _Scratch(threading.local):
    """Each thread's arrays, reused from call to call: fresh ones of 90,000 values (0.7 MB) are mapped in page by
    page each time (glibc hands freed large blocks back to the system), which cost three times the sort here."""

    def get(self, name: str, size: int, dtype=np.float64) -> np.ndarray:
        buf = self.__dict__.get(name)
        if buf is None or len(buf) < size:
            buf = self.__dict__[name] = np.empty(max(size, 1024), dtype=dtype)
        return buf[:size]


_scratch = _Scratch()


def _distinct(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(values, return_counts=True)`` (counts as float64) of finite values, in reused arrays: the sorted
    distinct values and their multiplicities."""
    m = len(values)
    s = _scratch.get("sorted", m)
    s[:] = values
    s.sort()  # np.sort's algorithm, in place
    first = _scratch.get("first", m, bool)
    first[:1] = True
    np.not_equal(s[1:], s[:-1], out=first[1:])
    d = int(np.count_nonzero(first))
    v = np.compress(first, s, out=_scratch.get("distinct", d))
    at = np.compress(first, _arange(m), out=_scratch.get("at", d, np.int64))  # each distinct value's first place
    w = _scratch.get("counts", d)
    np.subtract(at[1:], at[:-1], out=w[:-1])
    w[-1:] = m - at[-1:]
    return v, w


def _arange(m: int) -> np.ndarray:
    a = _scratch.__dict__.get("arange")
    if a is None or len(a) < m:
        a = _scratch.__dict__["arange"] = np.arange(max(m, 1024), dtype=np.int64)
    return a[:m]


def kmeans_edges(values: np.ndarray, groups: int, *, native: bool = True) -> np.ndarray:
    """The lowest value of each group but the first, ascending, of an optimal partition of ``values`` into at most
    ``groups`` groups: group g holds the values in [edges[g - 1], edges[g]) (open at both ends). There are
    min(groups, number of distinct values) groups. ``native=False``: the numpy programme even where C loads."""
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    finite = bool(np.isfinite(values).all())
    # not finite: np.unique's rules (one NaN) and numpy's programme decide, as they always did
    v, w = _distinct(values) if finite else np.unique(values, return_counts=True)
    G = min(groups, len(v))
    if G <= 1:
        return v[:0].copy()
    x = np.subtract(v, v.mean(), out=_scratch.get("centred", len(v)))  # the prefix sums lose less to cancellation
    kernel = native_kmeans()[0] if native and finite else None
    starts = kernel.splits(x, w, G) if kernel is not None else None
    if starts is None:
        starts = _starts_numpy(x, w, G)
    return v[starts[1:]]


def kmeans_1d(values: np.ndarray, groups: int, *, native: bool = True) -> np.ndarray:
    """An optimal (least within-group sum of squares) partition of ``values`` into at most ``groups`` groups:
    each value's group index, 0 = the lowest centre. Groups are contiguous in sorted order, equal values share one,
    and there are min(groups, number of distinct values) of them."""
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    return np.searchsorted(kmeans_edges(values, groups, native=native), values, side="right")
