"""Checkpoints: what a killed job needs to resume exactly, written so that its cost stays flat.

A checkpoint is the engine's state (weights, momentum buffers), the epoch reached (shuffles are
counter-based, so a fixed priority order needs nothing more), the samplers' orders where they were chosen
during training (``loss_high``/``loss_low`` ask the network at each enlargement, ``reselect`` redraws;
None otherwise), the presentations (selection's share too) and seconds so far, and which replicas diverged.
The logged history is not re-encoded each time: its records are appended once to ``history.pkl`` (pickled:
a record holds a number per replica for each curve, and JSON's shortest float repr took 2 ms a record at R =
1000, pickle 0.05) and the checkpoint remembers how many bytes of that file belong to it, so a kill between
the append and the checkpoint's atomic rename loses nothing and duplicates nothing. results.json holds the
same records as JSON, once, at the end.

The checkpoint itself is written by ``torch.save`` and read with ``weights_only=True``. (A hand-written pickler
saved ~0.2 ms a checkpoint at R = 1, a few ms a job: no command a user runs shows it, so the library is used.)
A checkpoint of another config (or one that cannot be read, such as the plain-pickle files of an older
selpres) is never resumed and never overwritten in silence: it is
moved aside with a warning, and ``results.json`` names where it went (:meth:`Checkpoints.resume`).
"""

from __future__ import annotations

import io
import logging
import pickle
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch

from selpres.storage import CHECKPOINT, CHECKPOINT_ALT, HISTORY, atomic_write, naming

log = logging.getLogger("selpres")
HISTORY_FORMAT = "pickle"  # of history.pkl; a checkpoint without it (an older selpres) is set aside, not resumed


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
    selection_presentations: int = 0  # selection's charge (selpres.presentation.selection), per replica
    orders: torch.Tensor | None = None  # [R, n] the samplers' orders once chosen during training
    seconds: dict = field(default_factory=dict)  # accumulated seconds per phase of the loop
    resumed_from: int | None = None  # the epoch a resume started from
    stale_checkpoint: str | None = None  # where a checkpoint of another config was moved

    @classmethod
    def fresh(cls, replicas: int) -> Progress:
        return cls([], [None] * replicas)

    @property
    def all_diverged(self) -> bool:
        return all(d is not None for d in self.diverged_at)


class Checkpoints:
    """``checkpoint.pt`` / ``checkpoint.alt.pt`` + ``history.pkl`` in a job folder, for one job identity (its
    config hash).

    Saves alternate between the two names, each written to a temporary file and renamed onto a name freed
    just before, while the other name keeps the newest checkpoint, so a kill at any moment leaves one whole
    checkpoint (a resume takes the newer). Renaming over an existing file took 0.1-0.3 ms on this machine's
    ext4 disk (one-off timings), where an R = 1 job checkpoints every 2.7 ms; onto a free name ~0.01 ms.
    """

    def __init__(self, folder: Path, config_hash: str):
        self.paths, self.history_path, self.hash = (
            (folder / CHECKPOINT, folder / CHECKPOINT_ALT),
            folder / HISTORY,
            config_hash,
        )
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
        if not present and not self.history_path.exists():
            return False
        for path in present:
            try:
                if read(path).get("config_hash") != self.hash:
                    return False
            except Exception:  # unreadable: not known to be this job's, left alone
                return False
        return True

    def resume(self, engine, replicas: int) -> Progress:
        """The saved progress (engine state loaded) from the newer readable checkpoint of this job here, else a
        fresh start. A file that cannot be read is set aside and the other one resumed (a crash can leave the
        newer file empty: saves do not fsync); a checkpoint of another config sets everything aside, the
        history log included (it is not this job's). Nothing is resumed or deleted in silence."""
        found, bad, foreign = [], [], False
        for slot, path in enumerate(self.paths):
            if not path.exists():
                continue
            try:
                ck = read(path)
            except Exception as exc:  # any unreadable file is set aside, never resumed
                bad.append((path, f"cannot be read ({type(exc).__name__}: {exc})"))
                continue
            if ck.get("config_hash") == self.hash and ck.get("history_format") == HISTORY_FORMAT:
                found.append((ck["epoch"], slot, ck))
            else:
                hashes = f"hash {ck.get('config_hash')}, this job {self.hash}"
                bad.append((path, f"belongs to another config or an older selpres ({hashes})"))
                foreign = True
        if foreign or (bad and not found):  # nothing of this job to resume: its history log goes aside too
            found, aside = [], [*self.paths, self.history_path]
        else:
            aside = [path for path, _ in bad]
        moved = self.move_aside(aside)
        for path, why in bad:
            log.warning("%s %s; moved it to %s", path, why, moved[path].name)
        stale = str(moved[bad[0][0]]) if bad else None
        if not found:
            if bad:
                log.warning("%s: no checkpoint of this job left to resume; started afresh", self.paths[0].parent)
            progress = Progress.fresh(replicas)
            progress.stale_checkpoint = stale
            return progress
        _, slot, ck = max(found, key=lambda f: f[:2])
        self._next = 1 - slot
        engine.load_state_dict(ck["engine"])
        with open(self.history_path, "r+b") as f:
            f.truncate(ck["history_bytes"])  # drop records appended after this checkpoint
            log_bytes = io.BytesIO(f.read())
        history = []
        while log_bytes.tell() < ck["history_bytes"]:
            history.append(pickle.load(log_bytes))
        self._saved = len(history)
        log.info("resuming from %s at epoch %d", self.paths[slot], ck["epoch"])
        return Progress(
            history,
            ck["diverged_at"],
            epoch=ck["epoch"],
            presentations=ck["presentations"],
            selection_presentations=ck["selection_presentations"],
            orders=ck["orders"],
            seconds=ck["seconds"],
            resumed_from=ck["epoch"],
            stale_checkpoint=stale,
        )

    def save(self, engine, progress: Progress) -> None:
        """Append the new history records, then write the checkpoint atomically (write, then rename) in place
        of the older one."""
        with naming(self.history_path), open(self.history_path, "ab" if self._saved else "wb") as f:
            f.writelines(pickle.dumps(rec, protocol=pickle.HIGHEST_PROTOCOL) for rec in progress.history[self._saved :])
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
            "orders": progress.orders,
        }
        data = dumps(state)
        target = self.paths[self._next]
        target.unlink(missing_ok=True)  # the older of the two: the other name holds the newest checkpoint
        atomic_write(target, lambda f: f.write(data))
        self._next = 1 - self._next

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
        for path in (*self.paths, self.history_path):
            path.unlink(missing_ok=True)
