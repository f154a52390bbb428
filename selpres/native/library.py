"""A loaded native library whose calls are split into chunks run on a thread pool (``sgd.py``, ``shuffle.py``).

ctypes releases the GIL during a call, so the chunks run in parallel. Small calls run in the calling
thread: handing a chunk to the pool costs a queue put, a wake-up and a lock wait (0.02-0.3 ms on this
2-core machine, the most when it is busy), more than the arithmetic of a few replicas on a few patterns;
see :data:`MIN_THREAD_WORK`. Chunking never changes a result: every replica sees the same operations in
the same order however groups, patterns and blocks are split.
"""

from __future__ import annotations

import ctypes
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

# The pool takes a thread only for at least this many multiply-adds (replica lanes x patterns x
# parameters; an epoch counts TRAIN_WORK_PER_PARAMETER per parameter: forward, backward, update), so with 2
# threads a call runs in the calling thread below 2**21 (~0.3 ms of one core: forward and training both
# take ~0.15 ns a multiply-add here). Handing work to the pool costs 0.02-0.3 ms (queue put, wake-up, lock
# wait; the most on a busy machine), while a second core can save at most half the call. Measured side by
# side (6-13-2, 2 threads, load ~4 on 2 cores; calling thread vs pool): predict R = 1 on 10 patterns 12 vs
# 124 us, on 2,000 158 vs 186 us; R = 30 on 10 patterns 15 vs 36 us, on 1,000 587 vs 617 us; an epoch
# of 1002 patterns at R = 5: 366 vs 478 us. On a busy machine the pool did not pay below 4e6.
MIN_THREAD_WORK = 1 << 20


class Library:
    """A compiled library (``ctypes.CDLL``) and the thread pool its calls' chunks run on."""

    def __init__(self, path: Path):
        self.path = path
        self.lib = ctypes.CDLL(str(path))
        self._pool: ThreadPoolExecutor | None = None
        self._pool_size = 0

    def _executor(self, n: int) -> ThreadPoolExecutor:
        if self._pool is None or self._pool_size < n:
            if self._pool is not None:
                self._pool.shutdown(wait=True)
            self._pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="selpres")
            self._pool_size = n
        return self._pool

    def _run(self, fn, chunks: list[tuple]) -> None:
        """``fn(*chunk)`` for every chunk, on the thread pool when there are several (ctypes releases
        the GIL, so they run in parallel); a non-zero return code is an error."""

        def call(args: tuple) -> None:
            rc = fn(*args)
            if rc != 0:
                raise RuntimeError(f"selpres native kernel {fn.__name__} failed with code {rc}")

        if len(chunks) == 1:
            call(chunks[0])
            return
        pool = self._executor(len(chunks))
        for fut in [pool.submit(call, c) for c in chunks]:
            fut.result()

    @staticmethod
    def threads_for(work: int, threads: int) -> int:
        """How many threads a call of ``work`` multiply-adds gets: at most ``threads``, and no more than
        one per :data:`MIN_THREAD_WORK` (1: the calling thread, no pool)."""
        return max(1, min(int(threads), int(work) // MIN_THREAD_WORK))

    @staticmethod
    def _bounds(n: int, threads: int) -> list[tuple[int, int]]:
        T = max(1, min(int(threads), n))
        return [(n * k // T, n * (k + 1) // T) for k in range(T)]
