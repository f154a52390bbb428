"""Sweep workers stop when their sweep is gone.

A joblib (loky) worker of ``-m hydra/launcher=local2`` keeps training when the sweep's own process is
killed: reparented to PID 1 it finishes its job while the user re-runs the sweep, a second writer on the
same folders. The sweep's process records who it is in the environment its workers inherit
(:func:`record_sweep_parent`, from ``selpres.run.job.FolderNote.on_multirun_start``); a worker's job watches that
process (:func:`watch`: a daemon thread polling once a second) and the training loop, at the end of every epoch,
stops once it is gone, writing a checkpoint first, so the re-run resumes every such job.

Why not ``prctl(PR_SET_PDEATHSIG)``: it fires when the *thread* that forked the worker exits, and a loky
worker is forked by its executor's manager thread, not by the sweep's main thread; and it is Linux only. The
recorded process is identified by its PID and its start time (``/proc/<pid>/stat``), so a reused PID does
not count as the sweep, and by the host name: a SLURM job (hydra/launcher=slurm) runs elsewhere and is
meant to outlive the process that submitted it, so it is not watched.
"""

from __future__ import annotations

import logging
import os
import socket
import threading

ENV = "SELPRES_SWEEP_PARENT"
POLL_SECONDS = 1.0
log = logging.getLogger("selpres")


class SweepGone(Exception):
    """The sweep that launched this job is gone; the job stopped (its checkpoint kept)."""


def _start_time(pid: int) -> str:
    """The process's start time in clock ticks since boot ('' where /proc cannot tell)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return ""


def record_sweep_parent() -> None:
    """Called in the sweep's own process before its launcher starts workers (they inherit os.environ)."""
    pid = os.getpid()
    os.environ[ENV] = f"{socket.gethostname()}:{pid}:{_start_time(pid)}"


def sweep_parent() -> tuple[int, str] | None:
    """(PID, start time) of the sweep process when this job runs in another process on this host, else None."""
    parts = os.environ.get(ENV, "").rsplit(":", 2)
    if len(parts) != 3 or not parts[1].isdigit():
        return None
    host, pid, start = parts[0], int(parts[1]), parts[2]
    if host != socket.gethostname() or pid == os.getpid():
        return None
    return pid, start


def alive(pid: int, start: str) -> bool:
    """Whether the process ``pid`` that started at ``start`` still exists (a zombie counts as gone)."""
    if start:
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            return fields[19] == start and fields[0] != "Z"
        except (OSError, IndexError):
            return False
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        return True


_GONE = threading.Event()
_WATCHED: tuple[int, str] | None = None


def watch() -> tuple[int, str] | None:
    """Start watching this job's sweep process (once per process); returns what is watched, or None."""
    global _WATCHED
    parent = sweep_parent()
    if parent is None or _WATCHED == parent:
        return parent
    _WATCHED = parent
    if not alive(*parent):
        _GONE.set()
        return parent

    def poll() -> None:
        while not _GONE.wait(POLL_SECONDS):
            if not alive(*parent):
                _GONE.set()

    threading.Thread(target=poll, name="selpres-sweep-watch", daemon=True).start()
    return parent


def gone() -> bool:
    """Whether the watched sweep process is gone (cheap: the training loop asks every epoch)."""
    return _GONE.is_set()
