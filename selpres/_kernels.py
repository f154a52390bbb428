"""The native SGD kernel behind ``make_engine("native"/"fast")``: build at first use, cache, ctypes binding.

The kernel itself is the C file ``selpres/kernels/sgd.c`` (read its header for the layout and the
arithmetic). Replicas are packed in groups of 4 (one AVX2 vector of float64 per parameter), a group's
parameters contiguous as ``[P, 4]`` in the replica list's order (W1 row-major, b1, W2, b2, ...).
``INTERLEAVE`` (2) groups are trained together in one instruction stream. The topology is compiled in
as macros (``-DNL=2 -DSIZES=6,13,2 ...``, see :func:`macros`): one small shared library per topology.
The sigmoid's ``exp`` is an inline AVX2 polynomial, so there is no -ffast-math and no vector-math
library: only a C compiler is needed.

Build: ``$CC`` (default ``cc``/``gcc``) ``-O3 -march=native -fPIC -shared`` on the real source path (so
compiler messages name its lines), once per (source, topology, flags, compiler, CPU) into
``$SELPRES_CACHE_DIR`` (default ``~/.cache/selpres``), written to a temporary file and renamed, so
parallel processes may race safely. Any failure (no compiler, no AVX2/FMA) raises
:class:`KernelUnavailable` and ``make_engine("fast")`` falls back to pure torch.
``SELPRES_NO_NATIVE=1`` forces that fallback.

Threads: :meth:`Kernel.train` splits the groups into ``threads`` contiguous chunks and runs them on a
thread pool; ctypes releases the GIL during the call, so the chunks run in parallel.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
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


class KernelUnavailable(RuntimeError):
    """The native kernel cannot be built or loaded here (the torch engine is used instead)."""


def cache_dir() -> Path:
    env = os.environ.get("SELPRES_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "selpres"


def _compiler() -> str:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if not cc:
        raise KernelUnavailable("no C compiler (set CC or install gcc)")
    return cc


def _cpu_id() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            lines = [ln for ln in f if ln.startswith(("flags", "model name"))]
        return "".join(sorted(set(lines)))
    except OSError:
        return platform.processor()


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
        """One epoch for all groups of ``w``/``buf`` ([G, P, 4], updated in place); ``loss`` [G*4] gets sums."""
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
_kernels: dict[tuple[int, ...], Kernel] = {}
_errors: dict[tuple[int, ...], str] = {}


def build(sizes, verbose: bool = False) -> Path:
    """Compile the kernel for ``sizes`` into the cache (if not already there); return the library's path."""
    cc = _compiler()
    defs = macros(sizes)
    try:
        version = subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        raise KernelUnavailable(f"C compiler {cc!r} does not run: {exc}") from exc
    text = "\0".join([SOURCE.read_text(), " ".join(defs + CFLAGS + LIBS), version, _cpu_id()])
    key = hashlib.sha256(text.encode()).hexdigest()[:16]
    out_dir = cache_dir()
    target = out_dir / f"selpres_{'-'.join(map(str, sizes))}_{key}.so"
    if target.exists():
        return target
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=out_dir) as tmp:
            so = Path(tmp) / "kernel.so"
            proc = subprocess.run([cc, *CFLAGS, *defs, "-o", str(so), str(SOURCE), *LIBS],
                                  capture_output=True, text=True, timeout=300)
            if proc.returncode != 0:
                raise KernelUnavailable(f"compiling the native kernel failed:\n{proc.stderr.strip()[:2000]}")
            os.replace(so, target)  # atomic: concurrent builders each install a complete file
    except (OSError, subprocess.SubprocessError) as exc:
        raise KernelUnavailable(f"cannot build the native kernel in {out_dir}: {exc}") from exc
    if verbose:
        print(f"selpres: built native kernel {target}")
    return target


def load(sizes) -> Kernel:
    """The kernel for topology ``sizes`` (built on first use); raises :class:`KernelUnavailable` if it cannot be had."""
    sizes = tuple(int(s) for s in sizes)
    if os.environ.get("SELPRES_NO_NATIVE", "") not in ("", "0"):
        raise KernelUnavailable("disabled by SELPRES_NO_NATIVE")
    if len(sizes) - 1 > 32:
        raise KernelUnavailable("more than 32 layers")
    with _lock:
        if sizes in _kernels:
            return _kernels[sizes]
        if sizes in _errors:
            raise KernelUnavailable(_errors[sizes])
        try:
            path = build(sizes)
            try:
                _kernels[sizes] = Kernel(path)
            except OSError as exc:
                raise KernelUnavailable(f"cannot load {path}: {exc}") from exc
        except KernelUnavailable as exc:
            _errors[sizes] = str(exc)
            raise
        return _kernels[sizes]
