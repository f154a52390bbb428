"""Exact 1-D k-means in C (``kernels/kmeans1d.c``): ctypes binding of the split points of an optimal partition.

Generic: sorted distinct values and their multiplicities in, each group's first index out (the numpy dynamic
programme and its callers: ``selpres.presentation.kmeans``). The C code does the numpy programme's floating-point
operations in its order, so the partition is the same one, not just as good. One library for every size, built by
``build.py`` with the kernels' flags (so it needs AVX2/FMA too, and falls back as they do).
"""

from __future__ import annotations

import ctypes
import threading
from pathlib import Path

import numpy as np

from selpres.native.build import KERNELS, check_extra_flags, compile_library, load_once
from selpres.native.library import Library

SOURCE = KERNELS / "kmeans1d.c"
_F64 = np.dtype(np.float64)


class KMeans1D(Library):
    """The split points of ``kernels/kmeans1d.c`` (one call, in the calling thread: no chunks to share). Each
    thread keeps its work array between calls: a fresh one (6 MB at 90,000 values) is mapped in page by page,
    which cost a fifth of the call."""

    def __init__(self, path: Path):
        super().__init__(path)
        i64, vp = ctypes.c_int64, ctypes.c_void_p
        self._splits = self.lib.selpres_kmeans1d
        self._splits.argtypes = [vp, vp, i64, i64, vp, vp]
        self._splits.restype = ctypes.c_int
        self._words = self.lib.selpres_kmeans1d_work
        self._words.argtypes = [i64, i64]
        self._words.restype = i64
        self._layers = self.lib.selpres_kmeans1d_layers
        self._layers.argtypes = [vp, vp, i64, i64, vp]
        self._layers.restype = ctypes.c_int
        self._local = threading.local()

    def _work(self, words: int) -> np.ndarray:
        work = getattr(self._local, "work", None)
        if work is None or len(work) < words:
            work = self._local.work = np.empty(words, dtype=np.float64)
        return work

    def splits(self, x: np.ndarray, w: np.ndarray, groups: int) -> np.ndarray | None:
        """Each group's first index into ``x`` (sorted distinct values, float64; ``w`` their multiplicities,
        float64), ``groups`` in [1, len(x)]; None where a candidate cost is not finite (then the numpy
        programme decides, with its own rules for NaN and infinity)."""
        d = len(x)
        for a in (x, w):
            assert a.dtype == _F64 and a.shape == (d,) and a.flags.c_contiguous
        starts = np.empty(groups, dtype=np.int64)
        work = self._work(self._words(d, groups))
        rc = self._splits(x.ctypes.data, w.ctypes.data, d, int(groups), starts.ctypes.data, work.ctypes.data)
        if rc == -2:
            return None
        if rc != 0:
            raise ValueError(f"selpres_kmeans1d: groups = {groups} outside [1, {d}] (code {rc})")
        return starts

    def layers(self, x: np.ndarray, w: np.ndarray, groups: int) -> dict[str, np.ndarray] | None:
        """For the tests: the whole programme, every layer in full, as the C code holds it: the prefix sums
        ``W``, ``S``, ``Q`` [d + 1], the last layer's ``D`` [d + 1] and every layer's minimisers ``arg``
        [groups - 1, d + 1] (entries below layer k's first i are not computed); None as for :meth:`splits`."""
        d, n1 = len(x), len(x) + 1
        assert 2 <= groups <= d and x.dtype == w.dtype == _F64
        work = np.empty(self._words(d, groups), dtype=np.float64)
        rc = self._layers(
            np.ascontiguousarray(x).ctypes.data, np.ascontiguousarray(w).ctypes.data, d, groups, work.ctypes.data
        )
        if rc == -2:
            return None
        parts = {name: work[k * n1 : (k + 1) * n1].copy() for k, name in ((0, "W"), (1, "S"), (2, "Q"), (3, "D"))}
        parts["arg"] = work[5 * n1 : (groups + 4) * n1].view(np.int64).reshape(groups - 1, n1).copy()
        return parts


FLAGS = ["-ffp-contract=off"]  # no FMA for a multiply and an add (clang fuses by default; gcc's -std=c11 does not)


def load_kmeans(extra_flags=()) -> KMeans1D:
    """The native exact 1-D k-means, under the same conditions as :func:`selpres.native.sgd.load`; with
    ``extra_flags`` (after the usual ones) a variant loaded beside it (the tests compare the AVX2-only one)."""
    extra = check_extra_flags(extra_flags)
    key = ("kmeans1d", extra) if extra else "kmeans1d"
    return load_once(key, KMeans1D, lambda: compile_library("selpres_kmeans1d", SOURCE, [*FLAGS, *extra]))
