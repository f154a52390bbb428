"""The native SGD kernel behind the online engine `native` (and `fast`): its ctypes binding, built by ``build.py``.

The kernel itself is the C file ``selpres/native/kernels/sgd.c`` (read its header for the layout and the
arithmetic). Replicas are packed in groups of 4 (one AVX2 vector of float64 per parameter), a group's
parameters contiguous as ``[P, 4]`` in the replica list's order (W1 row-major, b1, W2, b2, ...).
``INTERLEAVE`` (2) groups are trained together in one instruction stream. The topology is compiled in
as macros (``-DNL=2 -DSIZES=6,13,2 ...``, see :func:`macros`): one small shared library per topology.
The sigmoid's ``exp`` is an inline AVX2 polynomial, so there is no -ffast-math and no vector-math
library: only a C compiler is needed. Evaluation (:meth:`Kernel.forward`, :meth:`Kernel.squared_errors`)
is written once for a vector width (``kernels/eval.h``) and built at 4 lanes and, where the compiler
targets AVX-512F, at 8 (two groups per zmm: 1.3x faster here, where the sigmoid's division bounds both);
the numbers are bitwise the same at either width, and :attr:`Kernel.eval_lanes` says which one the loaded
library runs (results.json: ``evaluation``). Work arrays live on the heap, so layer widths are bounded by
memory only (not by a thread's stack).

Threads (see ``library.py``): :meth:`Kernel.train` splits the groups into contiguous chunks and runs them
on a thread pool. :meth:`Kernel.forward` (evaluation: outputs of every replica, no update) and
:meth:`Kernel.squared_errors` (scoring: summed squared errors, no outputs written) do the same, or split
the patterns when there are fewer groups than threads.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import torch

from selpres.native.build import KERNELS, KernelUnavailable, check_extra_flags, compile_library, load_once
from selpres.native.library import Library

LANES = 4
INTERLEAVE = 2  # groups of 4 replicas advanced together in one instruction stream (see the C comment)
SOURCE = KERNELS / "sgd.c"
TRAIN_WORK_PER_PARAMETER = 3  # multiply-adds of an epoch per parameter and presentation (library.MIN_THREAD_WORK)
SCORE_BLOCK = 1024  # patterns per partial sum of squared_errors (fixed: results never depend on threads)


class Kernel(Library):
    """One topology's compiled library: :meth:`train` (an epoch), :meth:`forward` (evaluation),
    :meth:`squared_errors` (scoring) and :meth:`finite` (the divergence check)."""

    def __init__(self, path: Path):
        super().__init__(path)
        i64, dp, lp, c_int = ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int
        self._train = self.lib.selpres_train
        self._train.argtypes = [
            c_int,
            lp,
            i64,
            i64,
            i64,
            dp,
            dp,
            dp,
            dp,
            lp,
            i64,
            i64,
            ctypes.c_double,
            ctypes.c_double,
            dp,
            i64,
            i64,
            lp,
            dp,
            dp,
        ]
        self._train.restype = c_int
        self._forward = self.lib.selpres_forward
        self._forward.argtypes = [c_int, lp, i64, i64, i64, i64, i64, dp, dp, i64, dp]
        self._forward.restype = c_int
        self._sqerr = self.lib.selpres_sqerr
        self._sqerr.argtypes = [c_int, lp, i64, i64, i64, i64, i64, i64, dp, dp, dp, i64, i64, dp]
        self._sqerr.restype = c_int
        self._finite = self.lib.selpres_finite
        self._finite.argtypes = [i64, i64, dp, lp]
        self._finite.restype = c_int
        self._eval_lanes = self.lib.selpres_eval_lanes
        self._eval_lanes.argtypes = []
        self._eval_lanes.restype = c_int
        self._sizes: dict[tuple[int, ...], torch.Tensor] = {}

    @property
    def eval_lanes(self) -> int:
        """The vector width :meth:`forward` and :meth:`squared_errors` run at in this library: 8 where it
        was compiled for AVX-512F (pairs of groups in a zmm), else 4 (AVX2). The numbers do not depend on
        it, the speed does: a run records it as what ran."""
        return int(self._eval_lanes())

    def _sizes_arg(self, sizes) -> tuple[int, int]:
        """``(nl, pointer to sizes as int64)`` for the C entry points; the tensor is kept, not rebuilt
        per call (a call at R = 1 costs tens of microseconds, so every torch op shows)."""
        key = tuple(sizes)
        if key not in self._sizes:
            self._sizes[key] = torch.tensor(key, dtype=torch.int64)
        return len(key) - 1, self._sizes[key].data_ptr()

    def train(
        self,
        sizes,
        w: torch.Tensor,
        buf: torch.Tensor,
        X: torch.Tensor,
        Y: torch.Tensor,
        order: torch.Tensor,
        batch_size: int,
        lr: float,
        mom: float,
        loss: torch.Tensor,
        threads: int,
        counts: torch.Tensor | None = None,
        weights: torch.Tensor | None = None,
        pattern_losses: torch.Tensor | None = None,
    ) -> None:
        """One epoch for all groups of ``w``/``buf`` ([G, P, 4], updated in place); ``loss`` [G*4] gets
        per-lane sums. ``X``, ``Y``: one pattern per row, each row contiguous (contiguous arrays, or the
        strided views of :class:`selpres.native.staging.Staged`). Threads take contiguous chunks of groups.

        A pruned epoch (any of the last three given; the C file's train_groups): lane i presents the first
        ``counts[i]`` ([G*4] int64) entries of its row of ``order``, each pattern's gradient scaled by
        ``weights`` [G*4, m] float64, and ``pattern_losses`` [G*4, m] float64 gets each presented pattern's
        loss (the entries past a lane's count are left as they were)."""
        G, P, lanes = w.shape
        assert lanes == LANES and buf.shape == w.shape and w.is_contiguous() and buf.is_contiguous()
        assert w.dtype == buf.dtype == X.dtype == Y.dtype == loss.dtype == torch.float64
        assert X.stride(1) == 1 and Y.stride(1) == 1 and X.shape[0] == Y.shape[0]
        order = order.contiguous()
        assert order.dtype == torch.int64 and order.shape[0] == G * LANES
        m = order.shape[1]
        extra = []
        for t, dtype, shape in ((counts, torch.int64, (G * LANES,)), (weights, torch.float64, (G * LANES, m))):
            assert t is None or (t.dtype == dtype and tuple(t.shape) == shape and t.is_contiguous())
            extra.append(None if t is None else t.data_ptr())
        pl = pattern_losses
        assert pl is None or (pl.dtype == torch.float64 and tuple(pl.shape) == (G * LANES, m) and pl.is_contiguous())
        extra.append(None if pl is None else pl.data_ptr())
        threads = self.threads_for(TRAIN_WORK_PER_PARAMETER * G * LANES * m * P, threads)
        rest = (
            P,
            w.data_ptr(),
            buf.data_ptr(),
            X.data_ptr(),
            Y.data_ptr(),
            order.data_ptr(),
            m,
            int(batch_size),
            float(lr),
            float(mom),
            loss.data_ptr(),
            X.stride(0) if X.shape[0] > 1 else X.shape[1],  # a single row's stride may be anything
            Y.stride(0) if Y.shape[0] > 1 else Y.shape[1],
            *extra,
        )
        head = self._sizes_arg(sizes)
        self._run(self._train, [(*head, g0, g1, *rest) for g0, g1 in self._bounds(G, threads)])

    def forward(self, sizes, w: torch.Tensor, X: torch.Tensor, threads: int) -> torch.Tensor:
        """Outputs of every lane of ``w`` ([G, P, 4]) on ``X`` [N, in]: [G*4, N, out] (padded lanes too).
        Threads take chunks of groups, or chunks of patterns when there are fewer groups than threads."""
        G, P, lanes = w.shape
        assert lanes == LANES and w.is_contiguous() and w.dtype == X.dtype == torch.float64
        X = X.contiguous()
        N = X.shape[0]
        out = torch.empty(G * LANES, N, sizes[-1], dtype=torch.float64)
        threads = self.threads_for(G * LANES * N * P, threads)
        head, tail = self._sizes_arg(sizes), (P, w.data_ptr(), X.data_ptr(), N, out.data_ptr())
        if G >= threads or N < 2:
            chunks = [(*head, g0, g1, 0, N, *tail) for g0, g1 in self._bounds(G, threads)]
        else:
            chunks = [(*head, 0, G, n0, n1, *tail) for n0, n1 in self._bounds(N, threads)]
        self._run(self._forward, chunks)
        return out

    def squared_errors(self, sizes, w: torch.Tensor, X: torch.Tensor, Y: torch.Tensor, threads: int) -> torch.Tensor:
        """Per lane of ``w`` ([G, P, 4]) and output, the sum over the patterns of ``X`` [N, in] of
        (output - ``Y``)^2: [G*4, out] float64, with no [G*4, N, out] array in between. Patterns are
        summed in fixed blocks of :data:`SCORE_BLOCK` (then the blocks in order), so the numbers do not
        depend on ``threads``; threads take chunks of groups, or of blocks when there are fewer groups."""
        G, P, lanes = w.shape
        assert lanes == LANES and w.is_contiguous() and w.dtype == X.dtype == Y.dtype == torch.float64
        X, Y = X.contiguous(), Y.contiguous()
        N, nout = X.shape[0], sizes[-1]
        assert Y.shape == (N, nout)
        nb = -(-N // SCORE_BLOCK)
        if nb == 0:
            return torch.zeros(G * LANES, nout, dtype=torch.float64)
        partial = torch.empty(nb, G * LANES, nout, dtype=torch.float64)
        threads = self.threads_for(G * LANES * N * P, threads)
        head = self._sizes_arg(sizes)
        tail = (SCORE_BLOCK, P, w.data_ptr(), X.data_ptr(), Y.data_ptr(), N, G, partial.data_ptr())
        if G >= threads or nb < 2:
            chunks = [(*head, g0, g1, 0, nb, *tail) for g0, g1 in self._bounds(G, threads)]
        else:
            chunks = [(*head, 0, G, b0, b1, *tail) for b0, b1 in self._bounds(nb, threads)]
        self._run(self._sqerr, chunks)
        total = partial[0]
        for b in range(1, nb):  # in block order, one addition each (a tree sum's order depends on torch)
            total = total + partial[b]
        return total

    def finite(self, w: torch.Tensor) -> torch.Tensor:
        """[G*4] bool: whether every parameter of each lane of ``w`` ([G, P, 4]) is finite. One pass
        over the packed weights in the calling thread (no unpacking, no torch parallel region)."""
        G, P, lanes = w.shape
        assert lanes == LANES and w.is_contiguous() and w.dtype == torch.float64
        out = torch.empty(G * LANES, dtype=torch.int8)
        self._run(self._finite, [(G, P, w.data_ptr(), out.data_ptr())])
        return out.bool()


def macros(sizes) -> list[str]:
    """The ``-D`` flags that specialise ``kernels/sgd.c`` for topology ``sizes`` (see the file's header)."""
    sizes = tuple(int(s) for s in sizes)
    P = sum(o * i + o for i, o in zip(sizes[:-1], sizes[1:]))
    return [
        f"-DNL={len(sizes) - 1}",
        f"-DSIZES={','.join(map(str, sizes))}",
        f"-DP_TOTAL={P}",
        f"-DTOT_UNITS={sum(sizes)}",
        f"-DMAXW={max(sizes)}",
        f"-DNI={INTERLEAVE}",
    ]


def build(sizes, extra_flags=()) -> Path:
    """The cached library for ``sizes``, compiled first if it is missing or fails its checksum.
    ``extra_flags`` go after the usual flags (so ``-mno-avx512f`` undoes what ``-march=native`` enables)
    and into the cache key: a variant never replaces the usual library."""
    sizes, extra = tuple(int(s) for s in sizes), check_extra_flags(extra_flags)
    return compile_library(f"selpres_{'-'.join(map(str, sizes))}", SOURCE, [*macros(sizes), *extra])


def load(sizes, extra_flags=()) -> Kernel:
    """The kernel for topology ``sizes`` (see :func:`selpres.native.build.load_once`); with ``extra_flags``
    (see :func:`build`) a variant, loaded beside the usual one (the tests compare the AVX2-only evaluation
    with the AVX-512 one)."""
    sizes, extra = tuple(int(s) for s in sizes), check_extra_flags(extra_flags)
    if len(sizes) - 1 > 32:
        raise KernelUnavailable("more than 32 layers")
    return load_once((sizes, extra) if extra else sizes, Kernel, lambda: build(sizes, extra))
