"""The guard around ``python train.py``: the run folder's lock taken and its contents noted before Hydra writes
there (:class:`OutputGuard`, a Hydra callback), and what a refused or interrupted run removes — only what it
created (:class:`Before`). Light on purpose: ``train.py`` imports it before Hydra starts, and ``--help`` must not
pay for torch.
"""

from __future__ import annotations

import os
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from selpres.run import lock, orphan, stop
from selpres.run.config import retired, unread


@dataclass
class Before:
    """A run folder as it was before Hydra wrote into it."""

    created: Path | None  # the topmost folder this run creates (None: the run folder existed)
    entries: set[str] = field(default_factory=set)  # names in the run folder
    hydra_files: dict[str, bytes] = field(default_factory=dict)  # .hydra/* contents Hydra will overwrite
    log_size: int | None = None  # train.log's size (Hydra appends to it)

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
    def look(cls, folder: Path, created: Path | None = None, new_lock: bool = False) -> Before:
        """``created``: what :meth:`missing` said before the lock was taken (the lock makes the folder);
        ``new_lock``: the lock file is this run's (removed with the rest on undo)."""
        if created is not None:
            return cls(created)
        hydra = folder / ".hydra"
        files = {p.name: p.read_bytes() for p in hydra.iterdir() if p.is_file()} if hydra.is_dir() else {}
        log_file = folder / "train.log"
        entries = {p.name for p in folder.iterdir()} - ({lock.LOCK} if new_lock else set())
        return cls(None, entries, files, log_file.stat().st_size if log_file.exists() else None)

    def undo(self, folder: Path) -> None:
        """Remove what the run created and restore what Hydra overwrote; never touch anything else."""
        if self.created is not None:
            shutil.rmtree(self.created, ignore_errors=True)
            return
        for entry in folder.iterdir():
            if entry.name not in self.entries:
                shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
        for name, data in self.hydra_files.items():
            (folder / ".hydra" / name).write_bytes(data)
        if self.log_size is not None and (folder / "train.log").exists():
            os.truncate(folder / "train.log", self.log_size)


_BEFORE: dict[Path, Before] = {}
MIN_FREE = 1 << 20  # bytes free a run folder needs: Hydra's record (~9 KB) and log, results.json (tens of KB)
_JOB_STARTED = False  # run_job began: from then on it handles Ctrl-C itself (see guarded)


def job_started() -> None:
    """Called by run_job: from here on a Ctrl-C is the job's to handle (a checkpoint may be worth keeping)."""
    global _JOB_STARTED
    _JOB_STARTED = True


class OutputGuard(Callback):
    """Hydra callback (configs/train.yaml): takes the run folder's lock and looks at the folder before Hydra
    creates or writes into it; in a sweep, records the sweep's process for its workers to watch."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        HydraConfig.instance().set_config(config)  # resolves ${hydra:job.override_dirname} as run_job will
        folder = Path(os.path.abspath(str(OmegaConf.select(config, "hydra.run.dir"))))  # as Hydra names it
        created = Before.missing(folder)
        try:
            held = lock.hold(folder)
        except lock.FolderBusy as e:  # the loser touches nothing: no undo (the folder is the holder's)
            print(f"error: {e}", file=sys.stderr)
            sys.exit(2)
        except OSError as e:
            if created is not None:  # the folders this run made before the write failed
                shutil.rmtree(created, ignore_errors=True)
            print(f"error: cannot write into {folder} ({e.strerror or e}): nothing was written", file=sys.stderr)
            sys.exit(2)
        _BEFORE[folder] = Before.look(folder, created, held.created)
        try:
            st = os.statvfs(folder)
        except OSError:
            return
        if (free := st.f_bavail * st.f_frsize) < MIN_FREE:
            refuse(f"{folder} has {free:,} bytes free; a job needs at least {MIN_FREE:,} for Hydra's record (.hydra/), "
                   "its log and its results: nothing was written")  # fmt: skip
        _save_config_refusing()

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        orphan.record_sweep_parent()


def refuse(line: str) -> NoReturn:
    """Before the job runs: one line, exit 2, and every folder this run looked at as it was."""
    for folder, before in _BEFORE.items():
        before.undo(folder)
    print(f"error: {line}", file=sys.stderr)
    sys.exit(2)


def _save_config_refusing() -> None:
    """Hydra writes ``.hydra/*.yaml`` after this callback and before the job, where an OSError (a disk that
    filled meanwhile, a file-size limit) would end in its traceback: it becomes :func:`refuse`'s one line. (The
    module's ``_save_config`` is what its ``run_job`` calls; Hydra 1.3 has no hook between the two.)"""
    import hydra.core.utils as hydra_utils

    save = hydra_utils._save_config
    if getattr(save, "selpres_refusing", False):
        return

    def refusing(cfg, filename: str, output_dir: Path) -> None:
        try:
            save(cfg, filename, output_dir)
        except OSError as e:
            refuse(f"cannot write Hydra's record {Path(output_dir) / filename} ({e.strerror or e}): nothing was kept")

    refusing.selpres_refusing = True
    hydra_utils._save_config = refusing


def undo(out: Path) -> None:
    """Remove what this run created in ``out`` (nothing, if the callback did not look at it first)."""
    before = _BEFORE.get(Path(os.path.abspath(out)))
    if before is not None:  # unknown (train.py run without the callback): remove nothing
        before.undo(out)


def guarded(main) -> None:
    """``python train.py``'s outermost frame: a Ctrl-C outside the job (while Hydra composes, creates the
    folder, writes ``.hydra/``) prints one line and exits 130, a SIGTERM or SIGUSR1 143 (selpres.run.stop),
    removing only what this run created. A retired spelling (``schedule.prune_ratio=0.3``) is refused in one line
    naming the new one, before anything is written."""
    refusal = retired(sys.argv[1:]) or unread(sys.argv[1:])  # before a sweep launches: +schedule.p=1,2
    if refusal is not None:
        print(f"error: {refusal}", file=sys.stderr)
        sys.exit(2)
    stop.install()
    try:
        main()
    except KeyboardInterrupt:
        if not _JOB_STARTED:  # inside run_job the job decides (a checkpoint may be worth keeping)
            for folder, before in _BEFORE.items():
                before.undo(folder)
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    except stop.Terminated as e:  # before the job's own handling (selpres.run.cli): only what this run created goes
        if not _JOB_STARTED:
            for folder, before in _BEFORE.items():
                before.undo(folder)
        print(f"error: {e} before the job started: nothing was kept", file=sys.stderr)
        sys.exit(stop.STATUS)
