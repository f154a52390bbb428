"""Files and identities: atomic writes and stable hashes, shared by results, checkpoints and data export."""

from __future__ import annotations

import errno
import hashlib
import json
import math
import os
import re
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
    run after a kill) never see half a file, and parallel writers never share a temp file. A write that fails
    (disk full, over quota, over the file-size limit, a read-only or vanished folder) removes the temp file and
    raises an OSError naming ``path``, with the errno of the failure, also when ``write`` is ``torch.save``, which
    reports it as a RuntimeError (:func:`write_failure`): callers and the job's error path catch OSError alone."""
    path = Path(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; outputs are meant to be shared
        os.replace(tmp, path)
    except BaseException as e:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
        failure = write_failure(e)
        if failure is not None:  # name the file the user knows (a write() names none, a rename its temp file)
            raise OSError(failure.errno, failure.strerror or str(failure), str(path)) from e
        raise


# torch's own words for a write its stream writer could not finish (caffe2/serialize/inline_container.cc)
_TORCH_WRITER = re.compile(r"PytorchStreamWriter failed|inline_container\.cc|unexpected pos \d+ vs \d+")


def write_failure(e: BaseException) -> OSError | None:
    """The OSError behind a failed write, or None when ``e`` is no write failure. An OSError is itself. torch.save
    into a file object reports a failed write as a RuntimeError: its writer calls the file's ``write``, whose OSError
    (ENOSPC, EDQUOT, EFBIG, ...) leaves ``torch.save``'s ``with`` block, and the block's exit then writes the zip's
    end record and fails on the position the lost write left (``[enforce fail at inline_container.cc] . unexpected pos
    704 vs 598``, torch 2.13), so the real OSError is that RuntimeError's ``__context__``; it is returned. torch's
    writer failing with no OSError behind it (its own C++ file stream sets no errno) is an I/O error (EIO) quoting
    torch's first line."""
    if isinstance(e, OSError):
        return e
    if not isinstance(e, RuntimeError):
        return None
    for behind in (e.__cause__, e.__context__):
        if isinstance(behind, OSError):
            return behind
    if _TORCH_WRITER.search(str(e)):
        return OSError(errno.EIO, f"torch could not write it ({one_line(str(e))})")
    return None


_ESCAPES = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")  # terminal colours and bold, as torch's load errors carry


def one_line(text: str, limit: int = 200) -> str:
    """``text`` without terminal escape codes, its whitespace runs (newlines too) made one space, cut to ``limit``."""
    text = " ".join(_ESCAPES.sub("", text).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def why_unreadable(path: Path, e: BaseException) -> str:
    """Why ``torch.load(path, weights_only=True)`` failed, in one line with no escape codes, starting "cannot be
    read" (torch's own refusal is six lines of advice to load with ``weights_only=False``: wrong for a file that a
    selpres job reads back): what the file holds that a weights-only load refuses, that it is empty, cut short or
    not a torch file, or the OSError. Callers put the file's name before it."""
    text = str(e)
    if isinstance(e, OSError):
        return f"cannot be read ({e.strerror or one_line(text)})"
    if isinstance(e, EOFError) or "failed finding central directory" in text:
        try:
            size = f"{os.path.getsize(path):,} bytes"
        except OSError as gone:
            return f"cannot be read ({gone.strerror})"
        if size == "0 bytes":
            return "cannot be read: it is empty (0 bytes)"
        return f"cannot be read: it is cut short or not a torch file ({size})"
    if "Weights only load failed" in text:
        refused = re.search(r"Unsupported global: GLOBAL (\S+)", text)
        if refused:
            return (
                f"cannot be read: it names {refused.group(1)}, which a weights-only load refuses (selpres writes "
                "tensors and plain values only); it was not loaded and nothing in it ran"
            )
        detail = re.search(r"WeightsUnpickler error:\s*(.+?)(?:\n\n|$)", text, re.S)
        said = one_line(detail.group(1), 120) if detail else "refused"
        return f"cannot be read: a weights-only load refuses it ({said}); nothing in it ran"
    return f"cannot be read ({type(e).__name__}: {one_line(text) or 'no message'})"


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
