"""Compile, cache and load the C code of ``kernels/`` once per process (the bindings: ``sgd.py``, ``shuffle.py``).

Build: ``$CC`` (default ``cc``/``gcc``) ``-O3 -march=native -fPIC -shared`` on the real source path (so
compiler messages name its lines), once per (source and the headers it includes, macros, flags -- with
any extra flags a caller asks for, e.g. ``-mno-avx512f`` for the AVX2-only variant the tests compare --,
compiler version, CPU) into ``$SELPRES_CACHE_DIR`` (default ``~/.cache/selpres``), written to a temporary
file and renamed, so parallel processes may race safely; a ``.sha256`` sidecar written after the library
marks it complete. Before any library is opened the CPU must list AVX2 and FMA (a cache shared between
machines ends in a fallback, never in SIGILL); a cached library that fails its checksum (truncated,
corrupt, unfinished) is rebuilt. Anything missing (no compiler, a failed or timed-out build, no AVX2/FMA,
``SELPRES_NO_NATIVE=1``) raises :class:`KernelUnavailable` with the reason, and ``engine=fast``
falls back to pure torch. Only successes are remembered in the process: a later load retries a failed build.
"""

from __future__ import annotations

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
from pathlib import Path

KERNELS = Path(__file__).resolve().parent / "kernels"  # the C sources, compiled in place: errors name their lines
CFLAGS = ["-O3", "-march=native", "-fPIC", "-shared", "-std=c11"]
LIBS = ["-lm"]
COMPILE_TIMEOUT = 300  # seconds; a time-out (a busy machine) is reported and retried by a later load
REQUIRED_CPU_FEATURES = ("avx2", "fma")  # what the kernels' intrinsics need (sgd.c stops without them)

log = logging.getLogger(__name__)


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


def check_extra_flags(flags) -> tuple[str, ...]:
    """Extra compiler options a caller asks for (checked: options, not a string or other values)."""
    if isinstance(flags, str) or not all(isinstance(f, str) and f.startswith("-") for f in flags):
        raise ValueError(f"extra_flags: a sequence of options like '-mno-avx512f', not {flags!r}")
    return tuple(flags)


def compile_library(stem: str, source: Path, flags: list[str]) -> Path:
    """The cached library of ``source`` built with ``flags``, compiled first if it is missing or fails
    its checksum."""
    cc = _compiler()
    target = _library_path(stem, source, flags, cc)
    _BUILT[target] = (tuple(cc), (*CFLAGS, *flags))
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


_lock = threading.Lock()
_loaded: dict = {}  # key -> a loaded binding (sgd: topology sizes, shuffle: "shuffle"); failures are not remembered
_BUILT: dict[Path, tuple[tuple[str, ...], tuple[str, ...]]] = {}  # library -> (compiler, flags) it was built with


def build_info() -> dict | None:
    """How the native code this process loaded was built, for the record of what ran (None: it loaded none): each
    library's compiler command and flags, the compiler's version, and the instruction-set extensions the kernels use
    that ``-march=native`` enabled on this CPU (an extra flag such as ``-mno-avx512f`` shows in that library's
    flags)."""
    with _lock:
        paths = [b.path for b in _loaded.values() if getattr(b, "path", None) in _BUILT]
    if not paths:
        return None
    builds = {_BUILT[p] for p in paths}
    versions = {" ".join(cc): _compiler_version(cc).strip().splitlines()[0] for cc, _ in builds}
    flags = cpu_flags()
    return {
        "libraries": sorted(p.name for p in paths),
        "compiler": "; ".join(f"{cc} ({version})" for cc, version in sorted(versions.items())),
        # the topology's -D macros left out: the config records the topology; these are what the code is built by
        "flags": sorted({" ".join(x for x in f if not x.startswith("-D")) for _, f in builds}),
        "instruction_set": " ".join(x.upper() for x in ("avx512f", "avx2", "fma") if x in flags) or platform.machine(),
        "cpu": ", ".join(sorted({ln.split(":", 1)[-1].strip() for ln in _cpu_model().splitlines() if ln.strip()})),
    }


def load_once(key, cls: type, built: Callable[[], Path]):
    """``cls`` over the library that ``built()`` returns (built on first use), one per ``key`` and process;
    raises :class:`KernelUnavailable` if it cannot be had. Only successes are remembered: after a failed
    or timed-out build a later call tries again."""
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
