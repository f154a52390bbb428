"""The native SGD kernel behind ``make_engine("native"/"fast")``: build at first use, cache, ctypes binding.

The kernel itself is the C file ``selpres/kernels/sgd.c`` (read its header for the layout and the
arithmetic). Replicas are packed in groups of 4 (one AVX2 vector of float64 per parameter), a group's
parameters contiguous as ``[P, 4]`` in the replica list's order (W1 row-major, b1, W2, b2, ...).
``INTERLEAVE`` (2) groups are trained together in one instruction stream. The topology is compiled in
as macros (``-DNL=2 -DSIZES=6,13,2 ...``, see :func:`macros`): one small shared library per topology.
The sigmoid's ``exp`` is an inline AVX2 polynomial, so there is no -ffast-math and no vector-math
library: only a C compiler is needed.

Build: ``$CC`` (default ``cc``/``gcc``) ``-O3 -march=native -fPIC -shared`` on the real source path (so
compiler messages name its lines), once per (source, topology, flags, compiler version, CPU) into
``$SELPRES_CACHE_DIR`` (default ``~/.cache/selpres``), written to a temporary file and renamed, so
parallel processes may race safely; a ``.sha256`` sidecar written after the library marks it complete.
Before any library is opened the CPU must list AVX2 and FMA (a cache shared between machines ends in a
fallback, never in SIGILL); a cached library that fails its checksum (truncated, corrupt, unfinished) is
rebuilt. Anything missing (no compiler, a failed or timed-out build, no AVX2/FMA, ``SELPRES_NO_NATIVE=1``)
raises :class:`KernelUnavailable` with the reason, and ``make_engine("fast")`` falls back to pure torch.
Only successes are remembered in the process: a later :func:`load` retries a failed build. Work arrays
live on the heap, so layer widths are bounded by memory only (not by a thread's stack).

Threads: :meth:`Kernel.train` splits the groups into ``threads`` contiguous chunks and runs them on a
thread pool; ctypes releases the GIL during the call, so the chunks run in parallel.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import platform
import shlex
import shutil
import subprocess
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import torch

LANES = 4
INTERLEAVE = 2  # groups of 4 replicas advanced together in one instruction stream (see the C comment)

SOURCE = Path(__file__).resolve().parent / "kernels" / "sgd.c"  # compiled in place: errors name its lines

CFLAGS = ["-O3", "-march=native", "-fPIC", "-shared", "-std=c11"]
LIBS = ["-lm"]
COMPILE_TIMEOUT = 300  # seconds; a time-out (a busy machine) is reported and retried by a later load()

log = logging.getLogger(__name__)


class KernelUnavailable(RuntimeError):
    """The native kernel cannot be built or loaded here (the torch engine is used instead)."""


def cache_dir() -> Path:
    env = os.environ.get("SELPRES_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "selpres"


REQUIRED_CPU_FEATURES = ("avx2", "fma")  # what the kernel's intrinsics need (sgd.c stops without them)


def _compiler() -> list[str]:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise KernelUnavailable("no C compiler (set CC or install gcc)")
    return shlex.split(cc)


def _compiler_version(cc: list[str]) -> str:
    """``cc --version``: part of the cache key, so a changed compiler never reuses an old library."""
    try:
        proc = subprocess.run([*cc, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError) as exc:
        raise KernelUnavailable(f"C compiler {shlex.join(cc)!r} does not run: {exc}") from exc
    if proc.returncode != 0:
        raise KernelUnavailable(f"C compiler {shlex.join(cc)!r} does not run: `--version` exited with "
                                f"{proc.returncode}: {proc.stderr.strip()[:500] or '(no message)'}")
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


class Kernel:
    def __init__(self, path: Path):
        self.path = path
        self.lib = ctypes.CDLL(str(path))
        f = self.lib.selpres_train
        i64, dp, lp = ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p
        f.argtypes = [ctypes.c_int, lp, i64, i64, i64, dp, dp, dp, dp, lp, i64, i64,
                      ctypes.c_double, ctypes.c_double, dp]
        f.restype = ctypes.c_int
        self._f = f
        self._pool: ThreadPoolExecutor | None = None
        self._pool_size = 0

    def _executor(self, n: int) -> ThreadPoolExecutor:
        if self._pool is None or self._pool_size < n:
            if self._pool is not None:
                self._pool.shutdown(wait=True)
            self._pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="selpres")
            self._pool_size = n
        return self._pool

    def train(self, sizes, w: torch.Tensor, buf: torch.Tensor, X: torch.Tensor, Y: torch.Tensor,
              order: torch.Tensor, batch_size: int, lr: float, mom: float, loss: torch.Tensor,
              threads: int) -> None:
        """One epoch for all groups of ``w``/``buf`` ([G, P, 4], updated in place); ``loss`` [G*4] gets
        per-lane sums."""
        G, P, lanes = w.shape
        assert lanes == LANES and buf.shape == w.shape and w.is_contiguous() and buf.is_contiguous()
        assert w.dtype == buf.dtype == X.dtype == Y.dtype == loss.dtype == torch.float64
        order = order.contiguous()
        assert order.dtype == torch.int64 and order.shape[0] == G * LANES
        sz = torch.tensor(list(sizes), dtype=torch.int64)
        m = order.shape[1]
        common = (sz.data_ptr(), P, w.data_ptr(), buf.data_ptr(), X.data_ptr(), Y.data_ptr(),
                  order.data_ptr(), m, int(batch_size), float(lr), float(mom), loss.data_ptr())
        nl = len(sizes) - 1

        def run(g0: int, g1: int) -> None:
            rc = self._f(nl, common[0], g0, g1, *common[1:])
            if rc != 0:
                raise RuntimeError(f"selpres native kernel failed with code {rc}")

        T = max(1, min(int(threads), G))
        if T == 1:
            run(0, G)
            return
        bounds = [G * k // T for k in range(T + 1)]
        futures = [self._executor(T).submit(run, bounds[k], bounds[k + 1]) for k in range(T)]
        for fut in futures:
            fut.result()


def macros(sizes) -> list[str]:
    """The ``-D`` flags that specialise ``kernels/sgd.c`` for topology ``sizes`` (see the file's header)."""
    sizes = tuple(int(s) for s in sizes)
    P = sum(o * i + o for i, o in zip(sizes[:-1], sizes[1:]))
    return [f"-DNL={len(sizes) - 1}", f"-DSIZES={','.join(map(str, sizes))}", f"-DP_TOTAL={P}",
            f"-DTOT_UNITS={sum(sizes)}", f"-DMAXW={max(sizes)}", f"-DNI={INTERLEAVE}"]


_lock = threading.Lock()
_kernels: dict[tuple[int, ...], Kernel] = {}  # loaded libraries; failures are not remembered (see load)


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


def library_path(sizes, cc: list[str] | None = None) -> Path:
    """Where the cache keeps the library for ``sizes``: keyed by source, macros, flags, compiler and CPU."""
    cc = cc or _compiler()
    key_text = "\0".join([SOURCE.read_text(), shlex.join([*cc, *macros(sizes), *CFLAGS, *LIBS]),
                          _compiler_version(cc), " ".join(sorted(cpu_flags())), _cpu_model()])
    key = hashlib.sha256(key_text.encode()).hexdigest()[:16]
    return cache_dir() / f"selpres_{'-'.join(map(str, sizes))}_{key}.so"


def build(sizes) -> Path:
    """The cached library for ``sizes``, compiled first if it is missing or fails its checksum."""
    sizes = tuple(int(s) for s in sizes)
    cc = _compiler()
    target = library_path(sizes, cc)
    if target.exists():
        if _intact(target):
            return target
        log.warning("the cached native kernel %s fails its checksum; rebuilding it", target)
    cmd = [*cc, *CFLAGS, *macros(sizes), "-o", "<out>", str(SOURCE), *LIBS]
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
            so = Path(tmp) / "kernel.so"
            cmd[cmd.index("<out>")] = str(so)
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=COMPILE_TIMEOUT)
            if proc.returncode != 0:
                msg = (proc.stderr or proc.stdout).strip()[:2000] or "(no message)"
                raise KernelUnavailable(f"compiling the native kernel failed ({shlex.join(cc)} exited with "
                                        f"{proc.returncode}):\n{msg}")
            digest = _digest(so)
            os.replace(so, target)  # atomic: concurrent builders each install a complete file
            (Path(tmp) / "sum").write_text(digest + "\n")
            os.replace(Path(tmp) / "sum", _sidecar(target))  # after the library: marks it complete
    except subprocess.TimeoutExpired as exc:
        raise KernelUnavailable(f"compiling the native kernel timed out after {COMPILE_TIMEOUT} s "
                                "(machine busy?); a later run retries") from exc
    except (OSError, subprocess.SubprocessError) as exc:
        raise KernelUnavailable(f"cannot build the native kernel in {target.parent}: {exc}") from exc
    log.info("built native kernel %s", target)
    return target


def load(sizes) -> Kernel:
    """The kernel for topology ``sizes``, built on first use; raises :class:`KernelUnavailable` if it cannot
    be had. Only successes are remembered: after a failed or timed-out build a later call tries again."""
    sizes = tuple(int(s) for s in sizes)
    if os.environ.get("SELPRES_NO_NATIVE", "") not in ("", "0"):
        raise KernelUnavailable("disabled by SELPRES_NO_NATIVE")
    if len(sizes) - 1 > 32:
        raise KernelUnavailable("more than 32 layers")
    with _lock:
        if sizes in _kernels:
            return _kernels[sizes]
        check_cpu(cpu_flags())  # before any cached library is opened
        path = build(sizes)
        try:
            _kernels[sizes] = Kernel(path)
        except OSError as exc:
            raise KernelUnavailable(f"cannot load {path}: {exc}") from exc
        return _kernels[sizes]
