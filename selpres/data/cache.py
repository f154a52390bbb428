"""Tasks built before, kept on disk, so a job does not simulate the same data again.

The default ``python train.py`` spent 0.10-0.13 s of its 0.3 s job simulating the paper's grid (1,050,625
candidates) and drawing its 10,000 held-out patterns; the PUMA's drawn 10^5 patterns take 0.7 s. Loading the same
task takes ~2 ms (0.03 s for the PUMA's). A task is stored under a key that holds everything it is a function of:
the robot and data configs, the source of the code that builds tasks (``selpres/arms``, ``selpres/data``,
``seeding.py``, ``storage.py``), and torch's and numpy's versions and the machine type, so an edit to any of them
builds afresh. Tasks read from a user's file (a CSV, a URDF) are not stored: reading the file is most of their
cost.

Where: ``$SELPRES_DATA_CACHE`` if set (``off`` turns the cache off), else ``$XDG_CACHE_HOME/selpres/tasks``, else
``~/.cache/selpres/tasks``. What a job did is recorded in results.json ``data.cache`` (``hit``, ``stored``,
``off``, ``not stored (<why>)``, or ``not written: <file>: <cause> (errno N)`` when the disk refused the entry:
full, over quota or a file-size limit, read-only, the folder gone; the job then runs on without the cache, with
one warning in its log). An entry that cannot be read is built again with one warning saying why. Each entry
also holds what its key was made of (the two configs and the source digest) and is checked against them on load:
a copied, synced or colliding entry of other configs is a miss with one warning naming what differs, never another
task's numbers. Entries are written atomically (a racing job writes the same bytes) and only entries of this cache
are ever replaced or removed (the oldest beyond :data:`KEEP`).
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import platform
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from selpres.patterns import ExemplarSet, Patterns, Scaler, TestSets
from selpres.storage import atomic_write, flatten, why_unreadable

log = logging.getLogger("selpres")

KEEP = 16  # entries kept; the least recently used beyond it are removed
MAX_BYTES = 512 * 2**20  # a larger task is not stored (a 10^6-pattern PUMA set is ~150 MB)
FORMAT = 2  # bump when the stored layout below changes (2: entries carry their own key)
_SUFFIX = ".task.pt"
_NAME = re.compile(r"[0-9a-f]{32}" + re.escape(_SUFFIX))  # the entries' names (key + suffix): nothing else is removed
STALE_TEMP_S = 3600.0  # a temp file this old is a killed write's, not a running one's


def cache_dir() -> Path | None:
    """The cache folder (None: turned off by SELPRES_DATA_CACHE=off)."""
    env = os.environ.get("SELPRES_DATA_CACHE")
    if env is not None:
        return None if env.strip().lower() in ("off", "0", "false", "") else Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "selpres" / "tasks"


@functools.lru_cache(maxsize=1)
def code_digest() -> str:
    """sha256 of the source that builds tasks and of the numeric libraries' versions."""
    root = Path(__file__).resolve().parents[1]  # selpres/
    h = hashlib.sha256(f"{FORMAT} {torch.__version__} {np.__version__} {platform.machine()}".encode())
    files = [*sorted((root / "arms").rglob("*.py")), *sorted((root / "data").rglob("*.py"))]
    files += [root / "seeding.py", root / "storage.py"]  # storage: the config hash a task records
    for p in files:
        h.update(str(p.relative_to(root)).encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


def key(robot_json: str, data_json: str) -> str:
    return hashlib.sha256(f"{code_digest()}\0{robot_json}\0{data_json}".encode()).hexdigest()[:32]


def _own(x):
    """A tensor's own copy: torch.save writes a view's whole storage (the held-out set is a view of its draws)."""
    return x.clone() if isinstance(x, torch.Tensor) else x


def _made_of(robot_json: str, data_json: str) -> dict:
    """What an entry's key is a function of, stored in the entry and compared on load."""
    return {"robot": robot_json, "data": data_json, "code": code_digest()}


def _differs(stored, wanted: dict) -> str | None:
    """None when an entry's record of what it was built from is ``wanted``; else what differs, briefly."""
    if not isinstance(stored, dict):
        return "it does not record what it was built from"
    if stored.get("code") != wanted["code"]:
        return "it was built by other source or library versions"
    for part in ("robot", "data"):
        if stored.get(part) != wanted[part]:
            try:
                a, b = flatten(json.loads(stored[part])), flatten(json.loads(wanted[part]))
            except (TypeError, ValueError, AttributeError, KeyError):
                return f"it holds the task of another {part} config"
            keys = [k for k in sorted({*a, *b}) if a.get(k) != b.get(k)][:3]
            said = ", ".join(f"{part}.{k}={a.get(k)!r} (this job: {b.get(k)!r})" for k in keys)
            return f"it holds the task of {said or f'another {part} config'}"
    return None


def _pack(task, made_of: dict) -> dict:
    ex, t = task.exemplar, task.tests
    sc = task.scaler
    return {
        "made_of": made_of,
        "exemplar": (_own(ex.X), _own(ex.Y), ex.n_candidates),
        "test10": (_own(t.test10.X), _own(t.test10.Y), _own(t.test10_from_exemplar)),
        "heldout": (_own(t.heldout.X), _own(t.heldout.Y)),
        "scaler": tuple(_own(v) for v in (sc.x_min, sc.x_max, sc.y_min, sc.y_max)),
        "scaler_range": (sc.lo, sc.hi),
        "names": (list(task.input_names), list(task.output_names)),
        "json": json.dumps({"info": task.info, "arm": task.arm}),
        "wrench": _own(task.wrench),
        "commanded": None if task.commanded is None else [_own(v) for v in task.commanded],
    }


def _unpack(d: dict, make: Callable[..., Any]):
    X, Y, n_candidates = d["exemplar"]
    extra = json.loads(d["json"])
    return make(
        exemplar=ExemplarSet(X, Y, n_candidates=int(n_candidates)),
        tests=TestSets(Patterns(*d["test10"][:2]), d["test10"][2], Patterns(*d["heldout"])),
        scaler=Scaler(*d["scaler"], *d["scaler_range"]),
        input_names=tuple(d["names"][0]),
        output_names=tuple(d["names"][1]),
        info=extra["info"],
        arm=extra["arm"],
        wrench=d["wrench"],
        commanded=None if d["commanded"] is None else tuple(d["commanded"]),
    )


def cached(robot_json: str, data_json: str, build: Callable[[], Any], make: Callable[..., Any]):
    """The task of these configs: loaded when stored before, else ``build()`` and stored. ``make`` builds a
    Task from its fields. ``info["cache"]`` says which (and why not stored)."""
    folder = cache_dir()
    if folder is None:
        task = build()
        task.info["cache"] = "off (SELPRES_DATA_CACHE=off)"
        return task
    path = folder / (key(robot_json, data_json) + _SUFFIX)
    try:
        present = path.is_file()
    except OSError as e:  # a folder this user cannot read: build, and say so when storing fails too
        log.warning("data cache: cannot look in %s (%s); building the task", folder, e.strerror or e)
        present = False
    made_of = _made_of(robot_json, data_json)
    task = None
    if present:
        try:
            entry = torch.load(path, weights_only=True)
            why = _differs(entry.get("made_of"), made_of) if isinstance(entry, dict) else "it is not a task entry"
            if why is None:
                task = _unpack(entry, make)
        except Exception as e:  # a cut or foreign file, or one removed meanwhile: build afresh and replace it
            log.warning("data cache: %s %s; building the task again", path, why_unreadable(path, e))
        else:
            if why is not None:  # copied, synced or colliding: another task's numbers must never be used
                log.warning("data cache: %s is not this job's entry (%s); building the task again", path, why)
        if task is not None:
            try:
                os.utime(path)  # recently used (a read-only or shared cache cannot record it: no matter)
            except OSError:
                pass
            task.info["cache"] = f"hit ({path})"
            return task
    task = build()
    task.info["cache"] = _store(path, task, made_of)
    return task


def _store(path: Path, task, made_of: dict) -> str:
    packed = _pack(task, made_of)
    size = sum(v.numel() * v.element_size() for v in _tensors(packed))
    if size > MAX_BYTES:
        return f"not stored ({size / 2**20:.0f} MB > {MAX_BYTES / 2**20:.0f} MB)"
    try:
        atomic_write(path, lambda f: torch.save(packed, f))  # a failed torch.save arrives as OSError (storage)
    except OSError as e:  # full, over quota or a file-size limit, read-only, vanished: the job needs no cache
        why = f"{e.filename or path}: {e.strerror or e} (errno {e.errno})"
        log.warning("data cache: cannot write %s; the job goes on without the cache", why)
        return f"not written: {why}"
    try:
        _evict(path.parent)
    except OSError as e:  # the entry is stored; old ones stay until a later job can remove them
        log.warning("data cache: cannot remove old entries from %s (%s)", path.parent, e.strerror or e)
    return f"stored ({path})"


def _tensors(obj):
    if isinstance(obj, torch.Tensor):
        yield obj
    elif isinstance(obj, dict | list | tuple):
        for v in obj.values() if isinstance(obj, dict) else obj:
            yield from _tensors(v)


def _evict(folder: Path) -> None:
    """Remove this cache's least recently used entries beyond KEEP and its killed writes' temp files (only
    files named like its own)."""

    def used(p: Path) -> float:
        try:
            return p.stat().st_mtime
        except FileNotFoundError:  # a racing job removed it
            return 0.0

    ours = [p for p in folder.glob("*" + _SUFFIX) if _NAME.fullmatch(p.name)]
    for p in sorted(ours, key=used, reverse=True)[KEEP:]:
        p.unlink(missing_ok=True)
    now = time.time()
    for p in folder.glob(f".*{_SUFFIX}.*.tmp"):  # left by a killed write (selpres.storage.atomic_write)
        if now - used(p) > STALE_TEMP_S:
            p.unlink(missing_ok=True)
