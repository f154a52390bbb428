"""The native SGD kernel behind ``make_engine("native"/"fast")``: build at first use, cache, ctypes binding.

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
library runs (results.json: ``evaluation``).

Build: ``$CC`` (default ``cc``/``gcc``) ``-O3 -march=native -fPIC -shared`` on the real source path (so
compiler messages name its lines), once per (source and the headers it includes, topology, flags -- with
any extra flags a caller asks for, e.g. ``-mno-avx512f`` for the AVX2-only variant the tests compare --,
compiler version, CPU) into
``$SELPRES_CACHE_DIR`` (default ``~/.cache/selpres``), written to a temporary file and renamed, so
parallel processes may race safely; a ``.sha256`` sidecar written after the library marks it complete.
Before any library is opened the CPU must list AVX2 and FMA (a cache shared between machines ends in a
fallback, never in SIGILL); a cached library that fails its checksum (truncated, corrupt, unfinished) is
rebuilt. Anything missing (no compiler, a failed or timed-out build, no AVX2/FMA, ``SELPRES_NO_NATIVE=1``)
raises :class:`KernelUnavailable` with the reason, and ``make_engine("fast")`` falls back to pure torch.
Only successes are remembered in the process: a later :func:`load` retries a failed build. Work arrays
live on the heap, so layer widths are bounded by memory only (not by a thread's stack).

Threads: :meth:`Kernel.train` splits the groups into contiguous chunks and runs them on a thread pool;
ctypes releases the GIL during the call, so the chunks run in parallel. :meth:`Kernel.forward`
(evaluation: outputs of every replica, no update) and :meth:`Kernel.squared_errors` (scoring: summed
squared errors, no outputs written) do the same, or split the patterns when there are fewer groups than
threads. Small calls run in the calling thread: handing a chunk to the pool costs a queue put, a wake-up
and a lock wait (0.02-0.3 ms on this 2-core machine, the most when it is busy), more than the arithmetic
of a few replicas on a few patterns; see :data:`MIN_THREAD_WORK`. Chunking never changes a result:
every replica sees the same operations in the same order however groups, patterns and blocks are split.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import platform
import re
import shlex
import shutil
import subprocess
import tempfile
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch

LANES = 4
INTERLEAVE = 2  # groups of 4 replicas advanced together in one instruction stream (see the C comment)

SOURCE = Path(__file__).resolve().parent / "kernels" / "sgd.c"  # compiled in place: errors name its lines
SHUFFLE_SOURCE = SOURCE.with_name("shuffle.c")  # the per-epoch shuffles (selpres.presentation.sampler), any topology

CFLAGS = ["-O3", "-march=native", "-fPIC", "-shared", "-std=c11"]
LIBS = ["-lm"]
# The pool takes a thread only for at least this many multiply-adds (replica lanes x patterns x
# parameters; an epoch counts TRAIN_WORK_PER_PARAMETER per parameter: forward, backward, update), so with 2
# threads a call runs in the calling thread below 2**21 (~0.3 ms of one core: forward and training both
# take ~0.15 ns a multiply-add here). Handing work to the pool costs 0.02-0.3 ms (queue put, wake-up, lock
# wait; the most on a busy machine), while a second core can save at most half the call. Measured side by
# side (6-13-2, 2 threads, load ~4 on 2 cores; calling thread vs pool): predict R = 1 on 10 patterns 12 vs
# 124 us, on 2,000 158 vs 186 us; R = 30 on 10 patterns 15 vs 36 us, on 1,000 587 vs 617 us; an epoch
# of 1002 patterns at R = 5: 366 vs 478 us. On a busy machine the pool did not pay below 4e6.
MIN_THREAD_WORK = 1 << 20
TRAIN_WORK_PER_PARAMETER = 3
SHUFFLE_WORK_PER_ELEMENT = 8  # a hash, a bucket, an insertion, a gather: ~8 multiply-adds' time (measured)
SCORE_BLOCK = 1024  # patterns per partial sum of squared_errors (fixed: results never depend on threads)
COMPILE_TIMEOUT = 300  # seconds; a time-out (a busy machine) is reported and retried by a later load()
REQUIRED_CPU_FEATURES = ("avx2", "fma")  # what the kernel's intrinsics need (sgd.c stops without them)

log = logging.getLogger(__name__)
_UINT64 = np.dtype(np.uint64)


class KernelUnavailable(RuntimeError):
    """The native kernel cannot be built or loaded here (the torch engine is used instead)."""


def cache_dir() -> Path:
    env = os.environ.get("SELPRES_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "selpres"


def _compiler() -> list[str]:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise KernelUnavailable("no C compiler (set CC or install gcc)")
    return shlex.split(cc)


def _compiler_version(cc: tuple[str, ...]) -> str:
    """``cc --version``: part of the cache key, so a changed compiler never reuses an old library."""
    try:
        proc = subprocess.run([*cc, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError) as exc:
        raise KernelUnavailable(f"C compiler {shlex.join(cc)!r} does not run: {exc}") from exc
    if proc.returncode != 0:
        raise KernelUnavailable(
            f"C compiler {shlex.join(cc)!r} does not run: `--version` exited with "
            f"{proc.returncode}: {proc.stderr.strip()[:500] or '(no message)'}"
        )
    return proc.stdout


def cpu_flags() -> frozenset[str]:
    """Feature flags that every core lists in /proc/cpuinfo (empty where it cannot be read)."""
    try:
        with open("/proc/cpuinfo") as f:
            sets = [frozenset(ln.split(":", 1)[1].split()) for ln in f if ln.startswith("flags")]
    except OSError:
        return frozenset()
    return frozenset.intersection(*sets) if sets else frozenset()


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            return "".join(sorted({ln for ln in f if ln.startswith("model name")}))
    except OSError:
        return platform.processor()


def check_cpu(flags: frozenset[str]) -> None:
    """Refuse a CPU without AVX2/FMA before any library is opened: a cache shared between machines
    must end in a fallback, never in SIGILL."""
    missing = [f for f in REQUIRED_CPU_FEATURES if f not in flags]
    if missing:
        seen = "" if flags else " (no CPU flags readable from /proc/cpuinfo)"
        raise KernelUnavailable(f"no AVX2/FMA: this CPU lacks {', '.join(missing)}{seen}")


class _Library:
    """A compiled library whose calls are split into chunks run on a thread pool (ctypes releases the
    GIL, so they run in parallel)."""

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


class Kernel(_Library):
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
    ) -> None:
        """One epoch for all groups of ``w``/``buf`` ([G, P, 4], updated in place); ``loss`` [G*4] gets
        per-lane sums. Threads take contiguous chunks of groups."""
        G, P, lanes = w.shape
        assert lanes == LANES and buf.shape == w.shape and w.is_contiguous() and buf.is_contiguous()
        assert w.dtype == buf.dtype == X.dtype == Y.dtype == loss.dtype == torch.float64
        order = order.contiguous()
        assert order.dtype == torch.int64 and order.shape[0] == G * LANES
        m = order.shape[1]
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


class Shuffler(_Library):
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


_lock = threading.Lock()
_loaded: dict = {}  # topology sizes -> Kernel, "shuffle" -> Shuffler; failures are not remembered (see _load)


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _sidecar(library: Path) -> Path:
    """``<library>.sha256``: written after the library, so a library without a matching one is damaged
    (truncated by a full disk, killed mid-copy, ...) or not finished."""
    return library.with_name(library.name + ".sha256")


def _intact(library: Path) -> bool:
    try:
        return _sidecar(library).read_text().strip() == _digest(library)
    except OSError:
        return False


def _source_text(source: Path) -> str:
    """The source and the headers it includes from its own folder (``#include "eval.h"``): an edited header
    changes the cache key as an edited source does."""
    text = source.read_text()
    headers = sorted(set(re.findall(r'^[ \t]*#[ \t]*include[ \t]*"([^"]+)"', text, re.MULTILINE)))
    return "\0".join([text, *(source.with_name(h).read_text() for h in headers)])


def _library_path(stem: str, source: Path, flags: list[str], cc: list[str] | None = None) -> Path:
    """Where the cache keeps a library: keyed by source (and its headers), macros, flags, compiler, CPU."""
    cc = cc or _compiler()
    key_text = "\0".join(
        [
            _source_text(source),
            shlex.join([*cc, *flags, *CFLAGS, *LIBS]),
            _compiler_version(tuple(cc)),
            " ".join(sorted(cpu_flags())),
            _cpu_model(),
        ]
    )
    key = hashlib.sha256(key_text.encode()).hexdigest()[:16]
    return cache_dir() / f"{stem}_{key}.so"


def _extra_flags(extra_flags) -> tuple[str, ...]:
    if isinstance(extra_flags, str) or not all(isinstance(f, str) and f.startswith("-") for f in extra_flags):
        raise ValueError(f"extra_flags: a sequence of options like '-mno-avx512f', not {extra_flags!r}")
    return tuple(extra_flags)


def build(sizes, extra_flags=()) -> Path:
    """The cached library for ``sizes``, compiled first if it is missing or fails its checksum.
    ``extra_flags`` go after the usual flags (so ``-mno-avx512f`` undoes what ``-march=native`` enables)
    and into the cache key: a variant never replaces the usual library."""
    sizes, extra = tuple(int(s) for s in sizes), _extra_flags(extra_flags)
    return _build(f"selpres_{'-'.join(map(str, sizes))}", SOURCE, [*macros(sizes), *extra])


def _build(stem: str, source: Path, flags: list[str]) -> Path:
    cc = _compiler()
    target = _library_path(stem, source, flags, cc)
    if target.exists():
        if _intact(target):
            return target
        log.warning("the cached native kernel %s fails its checksum; rebuilding it", target)
    cmd = [*cc, *CFLAGS, *flags, "-o", "<out>", str(source), *LIBS]
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
            so = Path(tmp) / "kernel.so"
            cmd[cmd.index("<out>")] = str(so)
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=COMPILE_TIMEOUT)
            if proc.returncode != 0:
                msg = (proc.stderr or proc.stdout).strip()[:2000] or "(no message)"
                raise KernelUnavailable(
                    f"compiling the native kernel failed ({shlex.join(cc)} exited with {proc.returncode}):\n{msg}"
                )
            digest = _digest(so)
            os.replace(so, target)  # atomic: concurrent builders each install a complete file
            (Path(tmp) / "sum").write_text(digest + "\n")
            os.replace(Path(tmp) / "sum", _sidecar(target))  # after the library: marks it complete
    except subprocess.TimeoutExpired as exc:
        raise KernelUnavailable(
            f"compiling the native kernel timed out after {COMPILE_TIMEOUT} s (machine busy?); a later run retries"
        ) from exc
    except (OSError, subprocess.SubprocessError) as exc:
        raise KernelUnavailable(f"cannot build the native kernel in {target.parent}: {exc}") from exc
    log.info("built native kernel %s", target)
    return target


def _load(key, cls: type, built: Callable[[], Path]):
    """``cls`` over the library that ``built()`` returns (built on first use); raises
    :class:`KernelUnavailable` if it cannot be had. Only successes are remembered: after a failed or timed-out
    build a later call tries again."""
    if os.environ.get("SELPRES_NO_NATIVE", "") not in ("", "0"):
        raise KernelUnavailable("disabled by SELPRES_NO_NATIVE")
    with _lock:
        if key not in _loaded:
            check_cpu(cpu_flags())  # before any cached library is opened
            path = built()
            try:
                _loaded[key] = cls(path)
            except OSError as exc:
                raise KernelUnavailable(f"cannot load {path}: {exc}") from exc
        return _loaded[key]


def load(sizes, extra_flags=()) -> Kernel:
    """The kernel for topology ``sizes`` (see :func:`_load`); with ``extra_flags`` (see :func:`build`) a
    variant, loaded beside the usual one (the tests compare the AVX2-only evaluation with the AVX-512 one)."""
    sizes, extra = tuple(int(s) for s in sizes), _extra_flags(extra_flags)
    if len(sizes) - 1 > 32:
        raise KernelUnavailable("more than 32 layers")
    return _load((sizes, extra) if extra else sizes, Kernel, lambda: build(sizes, extra))


def load_shuffle() -> Shuffler:
    """The native shuffles (``kernels/shuffle.c``), under the same conditions as :func:`load` (it is compiled
    with the same flags, so it needs AVX2/FMA too)."""
    return _load("shuffle", Shuffler, lambda: _build("selpres_shuffle", SHUFFLE_SOURCE, []))
