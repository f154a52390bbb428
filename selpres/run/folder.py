"""What a job folder holds, read and put back for :mod:`selpres.run.job`, which decides what to do with it.

A folder as a run found it (:class:`Before`: what a refusal may remove is only what this run made, told by inode,
so a file moved aside is still the user's); Hydra's record of the job (``.hydra/``, written once the folder is
held: :func:`write_record`); the finished job a folder holds, and how its config differs from this one
(:func:`finished`); a failed job's ``results.json`` (:func:`write_failure`); the checkpoint a kill left beside a
finished job (:func:`leftovers`); the job's log file (:func:`open_log`, :func:`to_log`, :func:`close_log`).
"""

from __future__ import annotations

import copy
import json
import logging
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from omegaconf import DictConfig, OmegaConf, read_write

from selpres.errors import ConfigError
from selpres.run import cli, lock
from selpres.storage import CHECKPOINT, CHECKPOINT_ALT, RESULTS, atomic_write, flatten, write_json

log = logging.getLogger("selpres")
RECORD = ".hydra"  # Hydra's record of a job (hydra.output_subdir is null: selpres writes it, see write_record)
LOG = "train.log"
MIN_FREE = 1 << 20  # bytes free a job folder needs: Hydra's record (~9 KB), its log and results (tens of KB)


class Unusable(ConfigError):
    """A folder a job cannot use (too little space, Hydra's record cannot be written): refused before any work."""

    def __init__(self, why: str):
        self.key, self.value, self.allowed = "hydra.run.dir", None, why
        ValueError.__init__(self, why)

    def __reduce__(self):
        return type(self), (str(self),)


@dataclass
class Before:
    """A job folder as this run found it, so that a refusal removes what the run made and nothing else."""

    created: Path | None  # the topmost folder this run created (None: the folder existed)
    inodes: set[int] = field(default_factory=set)  # of its entries: one moved aside keeps its inode, and stays
    record: dict[str, bytes] = field(default_factory=dict)  # .hydra/* contents this run rewrites
    log_size: int | None = None  # train.log's size (this run appends to it)

    @staticmethod
    def missing(folder: Path) -> Path | None:
        """The topmost folder of ``folder``'s path that does not exist yet (None: it exists)."""
        if folder.exists():
            return None
        created = folder
        while not created.parent.exists():
            created = created.parent
        return created

    @classmethod
    def look(cls, folder: Path, created: Path | None) -> Before:
        """``created``: what :meth:`missing` said before Hydra made the folder; still this run's only if nobody
        has written there since (the lock file is this run's)."""
        entries = [p for p in folder.iterdir() if p.name != lock.LOCK] if folder.is_dir() else []
        if created is not None and not entries:
            return cls(created)
        hydra = folder / RECORD
        files = {p.name: p.read_bytes() for p in hydra.iterdir() if p.is_file()} if hydra.is_dir() else {}
        size = (folder / LOG).stat().st_size if (folder / LOG).exists() else None
        return cls(None, {p.lstat().st_ino for p in entries}, files, size)

    def undo(self, folder: Path) -> None:
        """Remove what this run created and put back what it overwrote; never touch anything else (what cannot be
        put back, in a folder that turned read-only meanwhile, stays, and is said)."""
        close_log(folder)  # nothing logged later (a library's exit message) writes there again
        if self.created is not None:  # the job's folder, then the folders above it this run made, if still empty
            shutil.rmtree(folder, ignore_errors=True)
            if folder != self.created:
                remove_empty(folder.parent, self.created)
            return
        try:
            for entry in folder.iterdir():
                if entry.name != lock.LOCK and entry.lstat().st_ino not in self.inodes:
                    shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
            for name, data in self.record.items():
                atomic_write(folder / RECORD / name, lambda f, data=data: f.write(data))
            if self.log_size is not None and (folder / LOG).exists():
                os.truncate(folder / LOG, self.log_size)
        except OSError as e:
            log.warning("could not put %s back as it was: %s", folder, e)


def remove_empty(folder: Path, created: Path | None) -> None:
    """Remove the folders Hydra made for a job that never held them, if still empty (nobody's files are lost)."""
    if created is None:
        return
    d = folder
    while True:
        try:
            d.rmdir()
        except OSError:
            return
        if d == created:
            return
        d = d.parent


def check_space(folder: Path) -> None:
    try:
        st = os.statvfs(folder)
    except OSError:
        return
    if (free := st.f_bavail * st.f_frsize) < MIN_FREE:
        raise Unusable(f"{folder} has {free:,} bytes free; a job needs at least {MIN_FREE:,} for Hydra's record "
                       "(.hydra/), its log and its results: nothing was written")  # fmt: skip


def write_record(folder: Path, cfg: DictConfig, hydra_cfg: DictConfig, overrides) -> None:
    """Hydra's record of the job (``.hydra/config.yaml``, ``hydra.yaml``, ``overrides.yaml``), as Hydra writes it
    itself; selpres writes it once the folder is held (``hydra.output_subdir: null`` in ``configs/train.yaml``)."""
    hydra_cfg = copy.deepcopy(hydra_cfg)
    with read_write(hydra_cfg.hydra):
        hydra_cfg.hydra.output_subdir = RECORD
    for name, node in (("config.yaml", cfg), ("hydra.yaml", hydra_cfg), ("overrides.yaml", overrides)):
        text = OmegaConf.to_yaml(node).encode()
        try:
            atomic_write(folder / RECORD / name, lambda f, text=text: f.write(text))
        except OSError as e:
            why = f"cannot write Hydra's record {folder / RECORD / name} ({e.strerror or e}): nothing was kept"
            raise Unusable(why) from None


def finished(folder: Path, cfg: DictConfig) -> tuple[dict, str] | None:
    """The finished job in ``folder``, if any: (its results, how its config differs from this one; '' when it is
    this job). One it no longer counts as (the engines that ran it are not those this config now runs on, a file
    that lacks what a finished job holds) is None: it is run again, and says so."""
    from selpres.run.resolve import engine_kind, kind_of
    from selpres.run.results import job_hash

    try:
        res = json.loads((folder / RESULTS).read_bytes())
    except (OSError, ValueError):  # absent, unreadable, not UTF-8, not JSON: not a finished job (it is redone)
        return None
    if not isinstance(res, dict) or res.get("status") not in ("complete", "diverged"):
        return None
    if res.get("config_hash") != job_hash(cfg):
        return res, differences(res.get("config"), cfg)
    try:  # what the command line reads of a finished job (a hand-edited or cut file: the job is redone)
        cli.summary_table(res), objective(res)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as e:
        log.warning("%s lacks what a finished job holds (%s: %s): running it again", folder / RESULTS,
                    type(e).__name__, e)  # fmt: skip
        return None
    ran, now = kind_of(res.get("engine")), engine_kind(cfg)
    if ran != now:  # a routing change (issue 22) makes a finished result another update's
        log.warning("%s ran on the %s engines; this config now runs on the %s ones: running it again",
                    folder / RESULTS, ran, now)  # fmt: skip
        return None
    return res, ""


def differences(old, cfg: DictConfig, most: int = 6) -> str:
    """The keys whose values differ between a finished job's recorded config and this one's, ``key: old → new``."""
    from selpres.run.specs import NOT_IDENTITY, recorded

    if not isinstance(old, dict):
        return "its results.json records no config"
    a, b = (flatten({k: v for k, v in c.items() if k not in NOT_IDENTITY}) for c in (old, recorded(cfg)))
    show = lambda c, k: json.dumps(c[k]) if k in c else "(none)"  # noqa: E731
    diff = [f"{k}: {show(a, k)} → {show(b, k)}" for k in sorted({*a, *b}) if k not in a or k not in b or a[k] != b[k]]
    if not diff:
        return "the same keys, but the files its task read (data, robot) have changed since"
    return ", ".join(diff[:most]) + (f" and {len(diff) - most} more" if len(diff) > most else "")


def objective(res: dict) -> float:
    """What a sweeper (Optuna) minimises: the mean held-out RMS in Nm."""
    m = res["summary"]["heldout_rms_nm_overall"]["mean"]
    return float("inf") if m is None else m


def write_failure(folder: Path, cfg: DictConfig, error: str, kind: str) -> None:
    """A failed job's results.json: enough for the report to list it in its place (where it can be written)."""
    record = {
        "status": "failed",
        "error": error,
        "kind": kind,
        "schedule": {"name": cfg.schedule.name},
        "topology": cfg.topology.layers,
        "replicas": cfg.replicas,
        # the seeds listed only when few: a refused replicas=1000000000 must not build 10^9 of them
        "seeds": [cfg.seed + r for r in range(cfg.replicas)] if 0 < cfg.replicas <= 10_000 else None,
        "seed_range": [cfg.seed, cfg.seed + cfg.replicas - 1],
    }
    try:
        write_json(folder / RESULTS, record)
    except OSError:  # the disk that failed the job cannot take this record either: the job's line says why
        pass


def leftovers(folder: Path, cfg: DictConfig) -> None:
    """A kill during the final writes of a finished job (results.json is written before the checkpoint is
    removed) leaves this job's checkpoint files next to its results: removed on the re-run that finds it done."""
    from selpres.run.checkpoint import Checkpoints
    from selpres.run.results import job_hash

    ckpts = Checkpoints(folder, job_hash(cfg))
    if ckpts.leftover():
        ckpts.discard()
        log.info("removed the checkpoint a kill left in the finished job %s", folder)


def checkpointed(folder: Path) -> bool:
    """Whether ``folder`` holds a checkpoint (without loading torch: a Ctrl-C may have cut its import short)."""
    return any((folder / name).exists() for name in (CHECKPOINT, CHECKPOINT_ALT))


def newest_epoch(folder: Path) -> int | str:
    """The epoch of the newest checkpoint in ``folder`` (``?`` where none reads, or torch cannot be loaded)."""
    epochs = []
    for name in (CHECKPOINT, CHECKPOINT_ALT):
        try:
            from selpres.run.checkpoint import read

            epochs.append(int(read(folder / name)["epoch"]))
        except Exception:  # absent or unreadable: the other one is the checkpoint
            pass
    return max(epochs, default="?")


def _log_handlers(folder: Path | None = None) -> list[logging.FileHandler]:
    """Hydra's file handler of the job (``train.log``), in ``folder`` if given."""
    return [
        h for h in logging.getLogger().handlers
        if isinstance(h, logging.FileHandler) and (folder is None or Path(h.baseFilename).parent == folder)
    ]  # fmt: skip


def open_log(folder: Path) -> None:
    """Open the job's log once the folder is held (Hydra opens it at the first record: ``delay: true``), so that a
    job whose disk fills later still has the file it reports into."""
    for handler in _log_handlers(folder):
        if handler.stream is None:
            try:
                handler.stream = handler._open()
            except OSError:  # the folder cannot take it: what the log would have said is on the console
                pass


def to_log(text: str) -> None:
    """``text`` into the job's log file (Hydra's file handler), not onto the console; where it cannot be written
    (the disk that failed the job), nothing: the console has the job's line, and no logging traceback."""
    record = logging.LogRecord("selpres", logging.ERROR, __file__, 0, text, None, None)
    quiet, logging.raiseExceptions = logging.raiseExceptions, False
    try:
        for handler in _log_handlers():
            handler.handle(record)
    finally:
        logging.raiseExceptions = quiet


def close_log(folder: Path) -> None:
    """Stop logging into ``folder`` (Hydra's file handler of this job)."""
    for handler in _log_handlers(folder):
        logging.getLogger().removeHandler(handler)
        handler.close()
