"""Large exemplar sets staged for the SGD kernel: each pattern's inputs and targets side by side in one row.

An online epoch presents rows in random order, so on a set larger than the caches every presentation is
a random fetch from memory, and a random address translation: with 4 KB pages a set of 10^6 patterns spans
16,000-48,000 pages, far more than a TLB holds. Prefetching the rows (``kernels/sgd.c``) did not keep the
paper's 6-13-2 within 25 % of its small-set speed. Staging copies the set once per job into rows of whole
64-byte cache lines (``nin + nout`` doubles rounded up to 8: 6-13-2 needs one line and one page a
presentation, where separate X and Y arrays need two or three lines on two pages) in memory mapped with
transparent 2 MB pages (``madvise(MADV_HUGEPAGE)``; where the kernel grants none, the rows still save the
second page and line). Both parts count: in a throwaway side-by-side script (6-13-2, n = 10^6 against
10^3, 5 runs at load 7-12), the old kernel's separate arrays took x1.22-1.56, the same arrays in 2 MB pages
x1.10-1.27, rows in 2 MB pages x1.01-1.29. The kernel reads the same numbers with a row stride, so results
are bitwise those of the unstaged path (tests/test_staging.py checks it, and the reference engine).

Measured with ``python -m selpres_bench.scale`` (both paths side by side in each run; R = 4, CPU time of
the training thread, the time of n = 10^6 over that of n = 10^3, median of 5 interleaved repeats; five runs
on the 2 shared cores at load 7-13, 2026-12-01): 6-13-2 read as is x1.01, 1.23, 1.52, 1.58, 1.72, staged
x1.03, 1.04, 1.06, 1.09, 1.12 -- within the 25 % of issue 22, item 6, in every run, where the path as is
missed it in three. The kernel before (separate arrays, a prefetch of each row's first and last line
only) measured x1.20-1.49 against x0.96-1.10 staged in a throwaway side-by-side script (4 runs of 7
repeats); prefetching every line of a row made no detectable difference by itself. 18-40-6 (about ten
times the arithmetic a presentation): as is x1.04-1.13, staged x1.04-1.23 over the same five runs, no
detectable difference. The cost: a second copy of the set (64 MB for 6-13-2
at n = 10^6, 192 MB for the PUMA's 18-40-6) for as long as the engine lives, and one copy per job (0.07 s
and 1.1 s in the run recorded in docs/benchmark.md; 2.9 s once, when the first 2 MB pages had to be
compacted out of fragmented memory).
Sets under :data:`STAGE_BYTES` (Table 1's 1002 patterns and any set that stays in the caches) are never
staged.
"""

from __future__ import annotations

import mmap

import numpy as np
import torch

STAGE_BYTES = 1 << 22  # inputs + targets of at least 4 MB (beyond a core's L2 here) are staged
LINE_DOUBLES = 8  # 64-byte cache lines
HUGE_PAGE = 2 << 20
STAGED_DTYPES = (torch.float64, torch.float32)  # read exactly into float64 by numpy
CHECK_ROWS = 64  # rows compared with the source at every reuse (a change outside torch's version counter)


def _rows(n: int, width: int) -> tuple[np.ndarray, mmap.mmap | None]:
    """A zeroed float64 [n, width] array on 2 MB boundaries in a mapping advised to use huge pages (Linux),
    or a plain numpy array where the platform has no such advice."""
    nbytes = n * width * 8
    advice = getattr(mmap, "MADV_HUGEPAGE", None)
    if advice is None or nbytes == 0:
        return np.zeros((n, width)), None
    size = -(-nbytes // HUGE_PAGE) * HUGE_PAGE + HUGE_PAGE  # room to start on a 2 MB boundary
    mm = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    try:
        mm.madvise(advice)  # before the first touch: pages are then faulted in 2 MB at a time
    except OSError:
        pass  # transparent huge pages disabled: 4 KB pages, the rows still pack inputs and targets
    flat = np.frombuffer(mm, dtype=np.float64)
    start = (-flat.ctypes.data % HUGE_PAGE) // 8
    return flat[start : start + n * width].reshape(n, width), mm


class Staged:
    """One set's rows ``[inputs, targets, padding]`` and the views the kernel reads (``X``, ``Y``: strided
    views of the rows), with what identifies the source: the tensors it was copied from (held, so
    their memory cannot be reused for another set) and their version counters (bumped by any in-place
    torch operation on them or a view of them)."""

    def __init__(self, X: torch.Tensor, Y: torch.Tensor):
        X, Y = X.detach(), Y.detach()  # the same memory and version counter
        n, nin = X.shape
        nout = Y.shape[1]
        width = -(-(nin + nout) // LINE_DOUBLES) * LINE_DOUBLES
        rows, self._map = _rows(n, width)
        rows[:, :nin] = X.numpy()  # float32 or float64, any strides: converted exactly, as .to(float64) does
        rows[:, nin : nin + nout] = Y.numpy()
        self.rows = torch.from_numpy(rows)
        self.X, self.Y = self.rows[:, :nin], self.rows[:, nin : nin + nout]
        self._source = (X, Y, X._version, Y._version)
        self._check = np.unique(np.linspace(0, n - 1, min(n, CHECK_ROWS)).astype(np.int64))

    def holds(self, X: torch.Tensor, Y: torch.Tensor) -> bool:
        """Whether these are the tensors staged, unchanged: the same memory, shape and strides, the same
        versions, and a sample of rows still bitwise equal (a write through numpy bumps no version)."""
        sx, sy, vx, vy = self._source
        X, Y = X.detach(), Y.detach()
        same = (
            X.dtype == sx.dtype
            and Y.dtype == sy.dtype
            and all(
                a.data_ptr() == b.data_ptr() and a.shape == b.shape and a.stride() == b.stride()
                for a, b in ((X, sx), (Y, sy))
            )
        )
        if not (same and X._version == vx and Y._version == vy):
            return False
        idx = self._check
        return np.array_equal(X.numpy()[idx], self.X.numpy()[idx], equal_nan=True) and np.array_equal(
            Y.numpy()[idx], self.Y.numpy()[idx], equal_nan=True
        )


def stage(previous: Staged | None, X: torch.Tensor, Y: torch.Tensor) -> Staged | None:
    """The staged set for the caller's ``X``, ``Y`` (before any conversion, so a float32 set is staged once,
    not every epoch): ``previous`` while it still holds them, a new one when they changed, None below
    :data:`STAGE_BYTES` or for what numpy cannot read exactly (not on the CPU, not float32/float64): the
    kernel then reads float64 contiguous copies as before."""
    if (X.numel() + Y.numel()) * 8 < STAGE_BYTES:
        return None
    if any(t.device.type != "cpu" or t.dtype not in STAGED_DTYPES for t in (X, Y)):
        return None
    if previous is not None and previous.holds(X, Y):
        return previous
    return Staged(X, Y)
