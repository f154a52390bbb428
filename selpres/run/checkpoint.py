"""Checkpoints: what a killed job needs to resume exactly, written so that its cost stays flat.

A checkpoint is the engine's state (weights, momentum buffers), the epoch reached (shuffles are
counter-based, so a fixed priority order needs nothing more), the state of every other part the job names: the
selector's (``selpres.presentation.selector``: the orders a stage-wise order chose, a pruning policy's scores and
annealing flags) and the ledger's (each replica's cost so far), for every job alike; the presentations (selection's
share too) and seconds so far, and which replicas diverged.
The logged history is not re-encoded each time: its records are appended once to ``history.jsonl``, one JSON
record a line (orjson: the shortest float text that reads back exactly; a file a resume reads must not be able
to run code, as a pickle can: 0.8 ms a record at R = 1000 where pickle took 0.08, one-off timing, each record
written once), and the checkpoint remembers how many bytes of that file belong to it. The
checkpoint's atomic rename is what commits the records: a kill between the append and the rename loses nothing
and duplicates nothing, and a resume cuts the file back to its checkpoint's length. results.json holds the same
records, once, at the end.

A history that cannot be read (cut short, not JSON, not records) is said in one line: the newest checkpoint whose
records read is resumed, else the job's checkpoints and history are moved aside (never deleted) and it starts
afresh. The ``history.pkl`` of a folder checkpointed by an older selpres is read by an unpickler that admits no
class or function (its records are dicts, lists, numbers, strings: pickle names no global for them), so a planted
payload is refused as unreadable, never run.

The checkpoint itself is written by ``torch.save`` and read with ``weights_only=True``. (A hand-written pickler
saved ~0.2 ms a checkpoint at R = 1, a few ms a job: no command a user runs shows it, so the library is used.)
A checkpoint of another config (or one that cannot be read, such as the plain-pickle files of an older
selpres) is never resumed and never overwritten in silence: it is
moved aside with a warning, and ``results.json`` names where it went (:meth:`Checkpoints.resume`).
"""

from __future__ import annotations

import io
import logging
import os
import pickle
import time
from dataclasses import dataclass, field
from pathlib import Path

import orjson
import torch

from selpres.storage import (
    CHECKPOINT,
    CHECKPOINT_ALT,
    HISTORY,
    HISTORY_PICKLE,
    atomic_write,
    naming,
    one_line,
    why_unreadable,
)

log = logging.getLogger("selpres")
HISTORY_FORMAT = "jsonl"  # of history.jsonl; a checkpoint without a format (an older selpres) is set aside
PICKLE_FORMAT = "pickle"  # history.pkl of a selpres before issue 26: read without admitting any class
FORMATS = {HISTORY_FORMAT: HISTORY, PICKLE_FORMAT: HISTORY_PICKLE}  # format -> the log's file name
KEYS = ("epoch", "presentations", "seconds", "engine", "diverged_at", "history_bytes", "selection_presentations")


class HistoryUnreadable(ValueError):
    """The history log does not hold the records its checkpoint counts (the message says why)."""


class _NoGlobals(pickle.Unpickler):
    """An unpickler for the old ``history.pkl``: its records (dicts, lists, numbers, strings, None) pickle with no
    reference to a global, and every payload that runs code needs one (a class, ``os.system``): refused."""

    def find_class(self, module, name):
        raise pickle.UnpicklingError(f"it names {module}.{name}, which no history record holds (refused, not run)")


def _plain(value):
    """orjson's fallback for a number type of its own (a numpy scalar): the Python number."""
    if isinstance(value, float | int):
        return float(value) if isinstance(value, float) else int(value)
    raise TypeError(f"a history record holds {type(value).__name__}")


def encode(records) -> bytes:
    """History records as JSON lines (non-finite numbers never reach here: records hold them as None)."""
    return b"".join(orjson.dumps(rec, default=_plain) + b"\n" for rec in records)


def read_history(path: Path, nbytes: int, fmt: str) -> list[dict]:
    """The records in the first ``nbytes`` of the log at ``path`` (``fmt``: jsonl, or the old pickle), or
    HistoryUnreadable saying why."""
    try:
        with open(path, "rb") as f:
            data = f.read(nbytes)
    except OSError as e:
        raise HistoryUnreadable(f"cannot be read ({e.strerror or e})") from None
    if len(data) < nbytes:
        raise HistoryUnreadable(f"holds {len(data):,} bytes where its checkpoint counts {nbytes:,} (cut short)")
    records = []
    if fmt == HISTORY_FORMAT:
        *lines, tail = data.split(b"\n")
        for i, line in enumerate(lines, 1):
            try:
                records.append(_record(orjson.loads(line), i))
            except orjson.JSONDecodeError as e:
                raise HistoryUnreadable(f"its line {i} is not JSON ({e})") from None
        if tail:
            raise HistoryUnreadable(f"its record {len(lines) + 1} is cut short")
    else:
        buf = io.BytesIO(data)
        while buf.tell() < nbytes:
            try:
                rec = _NoGlobals(buf).load()
            except Exception as e:  # any damage: a planted global, a cut or flipped byte
                why = f"its record {len(records) + 1} cannot be read ({type(e).__name__}: {e})"
                raise HistoryUnreadable(why) from None
            records.append(_record(rec, len(records) + 1))
    return records


def _record(rec, i: int) -> dict:
    if not isinstance(rec, dict) or not isinstance(rec.get("epoch"), int):
        raise HistoryUnreadable(f"its record {i} is not a history record (a {type(rec).__name__})")
    return rec


def dumps(state) -> bytes:
    """``state`` as ``torch.save`` writes it (read back with :func:`read`)."""
    buf = io.BytesIO()
    torch.save(state, buf)
    return buf.getvalue()


def read(path: Path):
    """A checkpoint written by :meth:`Checkpoints.save`: tensors and plain Python values only
    (``weights_only``: a checkpoint file cannot run code)."""
    return torch.load(path, weights_only=True)


@dataclass
class Progress:
    """Where a job stands: exactly what a resume restores."""

    history: list[dict]  # one record per scored epoch (epoch -1 = the untrained network)
    diverged_at: list[dict | None]  # per replica: None, or the epoch/presentations where it diverged
    epoch: int = 0  # epochs done
    presentations: int = 0  # the cost axis: training presentations plus selection's charge
    selection_presentations: int = 0  # forward passes charged for choosing, per replica (rounded mean)
    seconds: dict = field(default_factory=dict)  # accumulated seconds per phase of the loop
    resumed_from: int | None = None  # the epoch a resume started from
    stale_checkpoint: str | None = None  # where a checkpoint of another config was moved

    @classmethod
    def fresh(cls, replicas: int) -> Progress:
        return cls([], [None] * replicas)

    @property
    def all_diverged(self) -> bool:
        return all(d is not None for d in self.diverged_at)


def _layout_differs(ours, saved, at: str = "engine") -> str | None:
    """Where a saved engine state is not laid out as this engine's (tensor shapes and dtypes, list lengths, of the
    entries both hold)."""
    if isinstance(ours, torch.Tensor):
        if not isinstance(saved, torch.Tensor) or (ours.shape, ours.dtype) != (saved.shape, saved.dtype):
            got = (tuple(saved.shape), saved.dtype) if isinstance(saved, torch.Tensor) else type(saved).__name__
            return f"{at} is {got}, this job's {(tuple(ours.shape), ours.dtype)}"
        return None
    if isinstance(ours, dict):  # entries made on the first update (an optimizer's moments) may be absent here
        if not isinstance(saved, dict):
            return f"{at} is a {type(saved).__name__}"
        return next((w for k in ours if k in saved and (w := _layout_differs(ours[k], saved[k], f"{at}.{k}"))), None)
    if isinstance(ours, list | tuple) and ours:
        if not isinstance(saved, list | tuple) or len(saved) != len(ours):
            return f"{at} holds another number of entries"
        return next((w for i, x in enumerate(ours) if (w := _layout_differs(x, saved[i], f"{at}[{i}]"))), None)
    return None


class Checkpoints:
    """``checkpoint.pt`` / ``checkpoint.alt.pt`` + ``history.jsonl`` in a job folder, for one job identity (its
    config hash).

    Saves alternate between the two names, each written to a temporary file and renamed onto a name freed
    just before, while the other name keeps the newest checkpoint, so a kill at any moment leaves one whole
    checkpoint (a resume takes the newer). Renaming over an existing file took 0.1-0.3 ms on this machine's
    ext4 disk (one-off timings), where an R = 1 job checkpoints every 2.7 ms; onto a free name ~0.01 ms.
    """

    def __init__(self, folder: Path, config_hash: str, parts: dict | None = None):
        self.parts = dict(parts or {})  # name -> an object with state_dict/load_state_dict, saved with the engine
        self.paths, self.history_path, self.hash = (
            (folder / CHECKPOINT, folder / CHECKPOINT_ALT),
            folder / HISTORY,
            config_hash,
        )
        self.logs = (self.history_path, folder / HISTORY_PICKLE)  # the log, and an older selpres's
        self._saved = 0  # history records already in the file
        self._next = 0  # the name the next save takes (the other holds the newest checkpoint)

    @staticmethod
    def present(folder: Path) -> bool:
        """Whether ``folder`` holds a checkpoint to resume from."""
        return any((folder / name).exists() for name in (CHECKPOINT, CHECKPOINT_ALT))

    def leftover(self) -> bool:
        """Whether the folder holds checkpoint files of this job only (every checkpoint reads with its hash;
        a history log alone is the last file a finished job removes): what a re-run of the finished job may
        remove."""
        present = [p for p in self.paths if p.exists()]
        if not present and not any(p.exists() for p in self.logs):
            return False
        for path in present:
            try:
                if read(path).get("config_hash") != self.hash:
                    return False
            except Exception:  # unreadable: not known to be this job's, left alone
                return False
        return True

    def resume(self, engine, replicas: int) -> Progress:
        """The saved progress (engine state loaded) from the newest checkpoint of this job here whose history
        reads, else a fresh start. A file that cannot be read is set aside and the other one resumed (a crash
        can leave the newer file empty: saves do not fsync); a checkpoint of another config, or a history that
        no checkpoint of this job can be resumed from, sets everything aside, the history log included. Nothing is
        resumed or deleted in silence."""
        found, bad, foreign = [], [], False
        for slot, path in enumerate(self.paths):
            if not path.exists():
                continue
            try:
                ck = read(path)
            except FileNotFoundError:  # gone since the check (a racing cleanup): not there, nothing to set aside
                continue
            except Exception as exc:  # any unreadable file is set aside, never resumed (said in one line)
                bad.append((path, why_unreadable(path, exc)))
                continue
            if not isinstance(ck, dict):
                bad.append((path, f"is not a checkpoint (a {type(ck).__name__})"))
            elif ck.get("config_hash") == self.hash and ck.get("history_format") in FORMATS:
                if all(k in ck for k in KEYS):
                    found.append((ck["epoch"], slot, ck))
                else:
                    bad.append((path, f"lacks {', '.join(k for k in KEYS if k not in ck)}"))
            else:
                hashes = f"hash {ck.get('config_hash')}, this job {self.hash}"
                bad.append((path, f"belongs to another config or an older selpres ({hashes})"))
                foreign = True
        chosen, unreadable = None, []
        if not foreign:
            for epoch, slot, ck in sorted(found, key=lambda f: f[:2], reverse=True):
                log_path = self.paths[0].parent / FORMATS[ck["history_format"]]
                try:
                    chosen = slot, ck, read_history(log_path, ck["history_bytes"], ck["history_format"])
                    break
                except HistoryUnreadable as e:
                    unreadable.append(f"{log_path.name} {e} (for the checkpoint of epoch {epoch})")
        if chosen is None and (bad or unreadable):  # nothing of this job to resume: its history goes aside too
            aside = [*self.paths, *self.logs]
        else:
            aside = [path for path, _ in bad]
        moved = self.move_aside(aside)
        for path, why in bad:
            log.warning("%s %s; moved it to %s", path, why, moved[path].name)
        stale = str(moved[bad[0][0]]) if bad else None
        if chosen is None:
            if unreadable:
                where = ", ".join(p.name for p in moved.values())
                folder = self.paths[0].parent
                log.warning("%s: %s; moved them aside (%s), started afresh", folder, "; ".join(unreadable), where)
                stale = stale or str(next(iter(moved.values()), ""))
            elif bad:
                log.warning("%s: no checkpoint of this job left to resume; started afresh", self.paths[0].parent)
            progress = Progress.fresh(replicas)
            progress.stale_checkpoint = stale
            return progress
        slot, ck, history = chosen
        if unreadable:
            log.warning("%s: %s; resumed the checkpoint of epoch %d", self.paths[0].parent, unreadable[0], ck["epoch"])
        fresh = dumps(self._states(engine))  # a copy to put back if the saved state does not fit
        try:
            if why := _layout_differs(engine.state_dict(), ck["engine"]):
                raise ValueError(why)
            saved = ck.get("parts", {})  # (none: a checkpoint of a selpres before the selector's state was kept)
            if set(saved) != set(self.parts):
                raise ValueError(f"it holds the states of {sorted(saved) or 'no part'}, this job {sorted(self.parts)}")
            self._load(engine, {"engine": ck["engine"], "parts": saved})
        except Exception as e:  # a hand-edited file with this job's hash: set aside, never a crash on every re-run
            self._load(engine, torch.load(io.BytesIO(fresh), weights_only=True))
            moved = self.move_aside([*self.paths, *self.logs])
            where = ", ".join(p.name for p in moved.values())
            log.warning("%s: its engine state does not fit this job (%s: %s); moved the job's files aside (%s), "
                        "started afresh", self.paths[slot], type(e).__name__, one_line(str(e)), where)  # fmt: skip
            progress = Progress.fresh(replicas)
            progress.stale_checkpoint = str(moved[self.paths[slot]])
            return progress
        self._next = 1 - slot
        if ck["history_format"] == HISTORY_FORMAT:
            os.truncate(self.history_path, ck["history_bytes"])  # drop records appended after this checkpoint
            self._saved = len(history)
        else:  # an older selpres's history.pkl: the next save writes every record to history.jsonl
            self._saved = 0
        log.info("resuming from %s at epoch %d", self.paths[slot], ck["epoch"])
        return Progress(
            history,
            ck["diverged_at"],
            epoch=ck["epoch"],
            presentations=ck["presentations"],
            selection_presentations=ck["selection_presentations"],
            seconds=ck["seconds"],
            resumed_from=ck["epoch"],
            stale_checkpoint=stale,
        )

    def save(self, engine, progress: Progress) -> None:
        """Append the new history records, then write the checkpoint atomically (write, then rename) in place
        of the older one: the rename commits the records (a resume reads no further than its checkpoint says)."""
        with naming(self.history_path), open(self.history_path, "ab" if self._saved else "wb") as f:
            f.write(encode(progress.history[self._saved :]))
            size = f.tell()
        self._saved = len(progress.history)
        state = {
            "config_hash": self.hash,
            "epoch": progress.epoch,
            "presentations": progress.presentations,
            "seconds": progress.seconds,
            "engine": engine.state_dict(),
            "diverged_at": progress.diverged_at,
            "history_bytes": size,
            "history_format": HISTORY_FORMAT,
            "selection_presentations": progress.selection_presentations,
            "parts": {name: part.state_dict() for name, part in self.parts.items()},
        }
        data = dumps(state)
        target = self.paths[self._next]
        target.unlink(missing_ok=True)  # the older of the two: the other name holds the newest checkpoint
        atomic_write(target, lambda f: f.write(data))
        self._next = 1 - self._next

    def _states(self, engine) -> dict:
        return {"engine": engine.state_dict(), "parts": {name: p.state_dict() for name, p in self.parts.items()}}

    def _load(self, engine, states: dict) -> None:
        engine.load_state_dict(states["engine"])
        for name, part in self.parts.items():
            part.load_state_dict(states["parts"][name])

    def move_aside(self, paths: list[Path]) -> dict[Path, Path]:
        """Rename those of ``paths`` that exist to ``<name>.stale-<time>.<suffix>``; returns old -> new."""
        stamp = time.strftime("%Y%m%d-%H%M%S")
        moved = {}
        for path in paths:
            if path.exists():
                name, _, suffix = path.name.partition(".")
                moved[path] = path.with_name(f"{name}.stale-{stamp}.{suffix}")
                path.rename(moved[path])
        return moved

    def discard(self) -> None:
        """A finished (or deliberately restarted) job needs none of the files."""
        for path in (*self.paths, *self.logs):
            path.unlink(missing_ok=True)
