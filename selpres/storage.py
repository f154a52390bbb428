"""Files and identities: atomic writes and stable hashes, shared by results, checkpoints and data export."""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO

import orjson

# what a job folder holds besides Hydra's record: results.json marks it finished
RESULTS = "results.json"
WEIGHTS = "weights.pt"
CHECKPOINT = "checkpoint.pt"
CHECKPOINT_ALT = "checkpoint.alt.pt"  # checkpoints alternate between the two names (selpres.run.checkpoint)
HISTORY = "history.jsonl"  # the checkpoint's append-only record log (one JSON record a line: it cannot run code)
HISTORY_PICKLE = "history.pkl"  # the same log as written by selpres before issue 26 (read without running code)


def atomic_write(path: Path, write: Callable[[BinaryIO], Any]) -> None:
    """Write through a unique temp file in the same directory, then os.replace: readers (and a resumed
    run after a kill) never see half a file, and parallel writers never share a temp file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; outputs are meant to be shared
        os.replace(tmp, path)
    except BaseException as e:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(e, OSError):  # name the file the user knows (a write() names none, a rename its temp file)
            raise OSError(e.errno, e.strerror, str(path)) from e
        raise


def remove_stale_temps(folder: Path, names=(RESULTS, WEIGHTS, CHECKPOINT, CHECKPOINT_ALT)) -> list[Path]:
    """Remove the temp files :func:`atomic_write` left for ``names`` when a kill cut it short; call only while
    holding the folder's lock (selpres.run.lock), when no write of this job can be under way. Returns them."""
    stale = [p for name in names for p in Path(folder).glob(f".{name}.*.tmp")]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


@contextmanager
def naming(path: Path):
    """An OSError of a write() inside names ``path`` (write errors carry no file name of their own)."""
    try:
        yield
    except OSError as e:
        if e.filename is None:
            raise OSError(e.errno, e.strerror, str(path)) from e
        raise


def write_json(path: Path, obj: Any) -> None:
    atomic_write(path, lambda f: f.write((to_json(obj) + "\n").encode()))


_CONTAINERS = (dict, list, tuple)
_NUMBERS = {int, float}
_encode = json.JSONEncoder(default=str).encode  # one encoder: json.dumps(default=) builds one per call


def to_json(obj: Any, depth: int = 0) -> str:
    """JSON laid out for reading: a dict one key per line, a list of dicts or lists one item per line,
    and any other value (a list of numbers: one per replica) on one line. The leaves go through ``json``'s
    C encoder (``indent=`` would send everything through the pure-Python one, seconds for the curves of a
    1000-replica job), lists of finite numbers through orjson: Python's shortest float repr took 0.17 s for
    the 330,000 numbers of an R = 1000 job's curves, orjson's 0.01 s (the same values: both write the
    shortest digits that read back exactly, orjson without spaces and with its own exponent rule:
    ``[0.00001,1.5e-7]`` where json writes ``[1e-05, 1.5e-07]``)."""
    pad, end = " " * (depth + 1), "\n" + " " * depth
    if isinstance(obj, dict) and obj:
        items = (
            f"{pad}{_encode(k if isinstance(k, str) else _encode(k))}: {to_json(v, depth + 1)}" for k, v in obj.items()
        )
        return "{\n" + ",\n".join(items) + end + "}"
    if isinstance(obj, (list, tuple)):
        types = set(map(type, obj))  # in one C-speed pass: a record's lists hold a number per replica
        if any(issubclass(t, _CONTAINERS) for t in types):
            return "[\n" + ",\n".join(pad + to_json(v, depth + 1) for v in obj) + end + "]"
        if obj and types <= _NUMBERS:
            try:  # orjson would write NaN and infinities as null; json keeps them (NaN, Infinity), as before
                if math.isfinite(sum(obj)):
                    return orjson.dumps(obj).decode()
            except (OverflowError, orjson.JSONEncodeError):  # an int beyond float or 64 bits: json writes it
                pass
    return _encode(obj)


def flatten(d: dict, sep: str = ".", prefix: str = "") -> dict[str, Any]:
    """Nested dicts to one level, keys joined by ``sep`` (``{"a": {"b": 1}}`` -> ``{"a.b": 1}``): how a
    config becomes comparable key by key (the report's method labels) or a flat list (TensorBoard hparams)."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        out.update(flatten(v, sep, key + sep) if isinstance(v, dict) else {key: v})
    return out


def stable_hash(obj: Any) -> str:
    """First 16 hex digits of the sha256 of a canonical JSON: the identity of a config or of data."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
