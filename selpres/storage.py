"""Files and identities: atomic writes and stable hashes, shared by results, checkpoints and data export."""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

# what a job folder holds besides Hydra's record: results.json marks it finished
RESULTS = "results.json"
WEIGHTS = "weights.pt"
CHECKPOINT = "checkpoint.pt"
HISTORY = "history.jsonl"  # the checkpoint's append-only record log


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
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_json(path: Path, obj: Any) -> None:
    atomic_write(path, lambda f: f.write(json.dumps(obj, indent=1, default=str).encode()))


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
