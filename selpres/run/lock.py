"""One writer per job folder: an advisory lock the operating system holds for the process.

Two processes that train into one folder interleave their history and checkpoints (each "resumes" the
other's in-flight checkpoint), so a job holds its folder's lock (:func:`holding`) before it reads or writes
anything there (:mod:`selpres.run.job` takes it before even Hydra's record is written), and a second process on
the same folder is told who holds it instead (:class:`FolderBusy`).

The lock is ``fcntl.flock`` on ``.selpres.lock`` in the job folder (stdlib; ``filelock`` would buy the same
``flock`` on Linux plus Windows support, which the native kernel and the rest of selpres do not have): the
kernel drops it when its holder's last descriptor closes, so a holder killed with SIGKILL frees the folder at
once and the same command resumes with no stale lock to clear. The holder writes its PID into the file so
the loser can name it (/proc/locks would too, on Linux only). The file is removed by its holder at the end;
a contender re-checks after locking that the name still points at the file it locked, so removing it cannot
let two processes both believe they hold the folder.
"""

from __future__ import annotations

import fcntl
import os
from contextlib import contextmanager
from pathlib import Path

from selpres.run import stop

LOCK = ".selpres.lock"


class FolderBusy(RuntimeError):
    """The job folder is held by another live process (named by its PID when it has written it)."""

    def __init__(self, folder, pid: str):
        self.folder, self.pid = str(folder), pid
        holder = f"process {pid}" if pid else "another process"
        super().__init__(f"{self.folder} is in use by {holder} (one writer per job folder); nothing was touched")

    def __reduce__(self):
        return type(self), (self.folder, self.pid)


def _holder(fd: int) -> str:
    """The PID its holder wrote on the lock file's first line ('' if none yet)."""
    data = os.pread(fd, 64, 0)
    return data.partition(b"\n")[0].decode(errors="replace").strip()


class FolderLock:
    """``FolderLock.take(folder)``: the held lock (``created``: whether this call made the lock file), or
    FolderBusy. ``release()`` removes the file and drops the lock."""

    def __init__(self, folder: Path, fd: int, created: bool):
        self.folder, self.path, self._fd, self.created = folder, folder / LOCK, fd, created

    @classmethod
    def take(cls, folder: str | Path) -> FolderLock:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / LOCK
        for _ in range(100):  # a holder removing the file between our open and our lock: try again
            created = False
            try:
                fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644)
                created = True
            except FileExistsError:
                try:
                    fd = os.open(path, os.O_RDWR | os.O_CLOEXEC)
                except FileNotFoundError:
                    continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                pid = _holder(fd)
                os.close(fd)
                raise FolderBusy(folder, pid) from None
            try:
                same = os.stat(path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if not same:  # we locked a file its holder has just removed
                os.close(fd)
                continue
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            except OSError:  # a full disk: leave no empty lock file of ours behind
                if created:
                    os.unlink(path)
                os.close(fd)
                raise
            return cls(folder, fd, created)
        raise FolderBusy(folder, "")

    def release(self) -> None:
        if self._fd < 0:
            return
        try:
            if os.path.exists(self.path) and os.stat(self.path).st_ino == os.fstat(self._fd).st_ino:
                os.unlink(self.path)
        except OSError:  # a read-only folder: the lock file stays, the lock itself goes with the descriptor
            pass
        os.close(self._fd)
        self._fd = -1


_HELD: dict[Path, FolderLock] = {}


def _key(folder: str | Path) -> Path:
    """One name per folder in this process (``a/../D`` and ``D`` alike): a second flock of the same file by
    the same process would conflict with the first."""
    return Path(os.path.abspath(folder))


@contextmanager
def holding(folder: str | Path | None):
    """The lock of ``folder`` for the duration (None: no folder, no lock), or :class:`FolderBusy`: the one place a
    job folder's lock is taken and released. A folder this process holds already (a job's folder, which
    :func:`selpres.run.train.train` is then given) is not taken again, nor released at the inner exit. Taking and
    releasing are not cut by a signal (it is answered after them: :mod:`selpres.run.stop`)."""
    if folder is None or _key(folder) in _HELD:
        yield
        return
    key = _key(folder)
    with stop.deferred():
        _HELD[key] = FolderLock.take(key)
    try:
        yield
    finally:
        with stop.deferred():
            _HELD.pop(key).release()
