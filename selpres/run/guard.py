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
from typing import Any

from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from selpres.run import lock, orphan
from selpres.run.config import retired


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
            print(f"error: cannot write into {folder} ({e.strerror or e}): nothing was written", file=sys.stderr)
            sys.exit(2)
        _BEFORE[folder] = Before.look(folder, created, held.created)

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        orphan.record_sweep_parent()


def undo(out: Path) -> None:
    """Remove what this run created in ``out`` (nothing, if the callback did not look at it first)."""
    before = _BEFORE.get(Path(os.path.abspath(out)))
    if before is not None:  # unknown (train.py run without the callback): remove nothing
        before.undo(out)


def guarded(main) -> None:
    """``python train.py``'s outermost frame: a Ctrl-C outside the job (while Hydra composes, creates the
    folder, writes ``.hydra/``) prints one line and exits 130, removing only what this run created. A retired
    spelling (``schedule.prune_ratio=0.3``) is refused in one line naming the new one, before anything is written."""
    refusal = retired(sys.argv[1:])
    if refusal is not None:
        print(f"error: {refusal}", file=sys.stderr)
        sys.exit(2)
    try:
        main()
    except KeyboardInterrupt:
        if not _JOB_STARTED:  # inside run_job the job decides (a checkpoint may be worth keeping)
            for folder, before in _BEFORE.items():
                before.undo(folder)
        print("interrupted", file=sys.stderr)
        sys.exit(130)
