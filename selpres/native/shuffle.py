"""The per-epoch shuffles of ``kernels/shuffle.c`` (``selpres.presentation.sampler``): ctypes binding.

Any topology: one library, built by ``build.py`` with the same flags as the SGD kernel (so it needs
AVX2/FMA too).
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import torch

from selpres.native.build import KERNELS, compile_library, load_once
from selpres.native.library import Library

SOURCE = KERNELS / "shuffle.c"
SHUFFLE_WORK_PER_ELEMENT = 8  # a hash, a bucket, an insertion, a gather: ~8 multiply-adds' time (measured)
_UINT64 = np.dtype(np.uint64)


class Shuffler(Library):
    """The per-epoch shuffles of ``kernels/shuffle.c``: the permutations ``selpres.presentation.sampler`` defines."""

    def __init__(self, path: Path):
        super().__init__(path)
        i64, vp = ctypes.c_int64, ctypes.c_void_p
        self._shuffle = self.lib.selpres_shuffle
        self._shuffle.argtypes = [i64, i64, vp, vp, vp, i64, i64, vp]
        self._shuffle.restype = ctypes.c_int

    def shuffle(self, keys, epochs, orders: list[torch.Tensor], size: int, count: int, out: torch.Tensor, threads: int):
        """``out[r] = orders[r][argsort(hashes of replica r at its epoch)[:count]]`` for every replica r
        (``keys``, ``epochs``: uint64 numpy arrays [R]; ``orders``: contiguous int64 tensors of at least
        ``size``; ``out``: int64 [R, count]). Threads take contiguous chunks of replicas."""
        R = len(orders)
        for a in (keys, epochs):
            assert a.dtype == _UINT64 and a.shape == (R,) and a.flags.c_contiguous  # dtype.name costs 1.5 us
        assert out.dtype == torch.int64 and out.shape == (R, count) and out.is_contiguous()
        ptrs = np.fromiter((o.data_ptr() for o in orders), dtype=np.uint64, count=R)
        threads = self.threads_for(SHUFFLE_WORK_PER_ELEMENT * R * size, threads)
        rest = (keys.ctypes.data, epochs.ctypes.data, ptrs.ctypes.data, size, count, out.data_ptr())
        self._run(self._shuffle, [(r0, r1, *rest) for r0, r1 in self._bounds(R, threads)])


def load_shuffle() -> Shuffler:
    """The native shuffles, under the same conditions as :func:`selpres.native.sgd.load`."""
    return load_once("shuffle", Shuffler, lambda: compile_library("selpres_shuffle", SOURCE, []))
