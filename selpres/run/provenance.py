"""What ran: the versions and the build behind a job's numbers, recorded in results.json ``provenance``.

selpres's version; its commit and whether its checkout had uncommitted changes, only when selpres runs from its own
checkout: the folder above the package is the top of a git work tree and holds a ``pyproject.toml`` naming the
project ``selpres``. An installed wheel, or the package copied or installed inside another project's repository (a
virtual environment in a project's checkout), has no commit of its own (``commit: null``): that repository's commit
is never taken for selpres's. Then Python, torch and numpy, the platform, the CPUs, and how the native kernels this
process loaded were built (:func:`selpres.native.build.build_info`; null when none ran). The report's runs section
says when a sweep's jobs ran on different versions (:mod:`selpres.report.sections.runs`).
"""

from __future__ import annotations

import functools
import importlib.metadata
import os
import platform
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import torch

PACKAGE = Path(__file__).resolve().parents[1]  # the selpres package folder this process imported
_NAME = re.compile(r'^name\s*=\s*["\']selpres["\']\s*$', re.M)
_VERSION = re.compile(r'^version\s*=\s*["\']([^"\']+)["\']\s*$', re.M)


def record() -> dict:
    """The provenance of a job run by this process (its native build as loaded so far: call it at the end)."""
    from selpres.native.build import build_info

    return {**_fixed(), "native": build_info()}


@functools.lru_cache(maxsize=1)
def _fixed() -> dict:
    """What does not change while the process runs (asked once: two git calls, ~10 ms)."""
    try:
        usable = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = None
    return {
        "selpres": selpres_source(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numpy": np.__version__,
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "usable_cpus": usable,  # this process's CPU affinity (a batch system's share)
    }


def selpres_source(package: Path = PACKAGE) -> dict:
    """selpres's version and where it ran from; ``commit`` (full hash) and ``dirty`` (tracked files changed, or
    files git does not know inside the package) only from selpres's own checkout, else None."""
    root = checkout_of(package)
    version = None
    if root is not None:
        found = _VERSION.search((root / "pyproject.toml").read_text(errors="replace"))
        version = found.group(1) if found else None
    if version is None:
        try:
            version = importlib.metadata.version("selpres")
        except importlib.metadata.PackageNotFoundError:
            pass
    out = {"version": version, "location": str(package), "checkout": root is not None, "commit": None, "dirty": None}
    if root is not None:
        out["commit"] = _git(root, "rev-parse", "HEAD")
        status = _git(root, "status", "--porcelain", "--untracked-files=all", "--", ".")
        if out["commit"] is not None and status is not None:
            inside = f"{package.relative_to(root).as_posix()}/"
            out["dirty"] = any(
                not line.startswith("??") or line[3:].startswith(inside) for line in status.splitlines() if line
            )
    return out


def checkout_of(package: Path) -> Path | None:
    """The root of selpres's own checkout that ``package`` is in (None: it is not in one)."""
    root = package.parent
    try:
        if not _NAME.search((root / "pyproject.toml").read_text(errors="replace")):
            return None
    except OSError:
        return None
    top = _git(root, "rev-parse", "--show-toplevel")
    return root if top is not None and Path(top).resolve() == root.resolve() else None


def _git(where: Path, *args: str) -> str | None:
    """``git args`` in ``where`` (its output, stripped; None when git is missing or fails). The user's GIT_*
    variables are left out: GIT_DIR would point it at another repository."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("GIT_")}
    try:
        done = subprocess.run(["git", *args], cwd=where, env=env, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


if __name__ == "__main__":  # python -m selpres.run.provenance: this installation's record
    import json

    json.dump(record(), sys.stdout, indent=1)
    print()
