"""Issue 39: a disk fault at any place a job writes ends in one line naming the file and the cause, exit 2, the
previous checkpoint intact and resumable by the same command, and no partial file under a final name; a fault at
the data cache leaves the job running without it, said in its log and in results.json.

The fault-injection layer (:class:`Disk`) fails the writes of one file, in this process, as the kernel and the
libraries fail them, so the code under test meets the exceptions a user's disk raises, by the same path:

* ENOSPC (disk full) and EDQUOT (over quota): the file's raw writes fail as CPython's ``FileIO.write`` reports a
  failed ``write(2)``, ``OSError(errno, strerror)`` without a file name, under Python's own ``BufferedWriter`` (so
  the error surfaces where buffering puts it: in a ``write``, a ``flush`` or a ``close``). Where torch writes
  (``weights.pt``, a cache entry) its stream writer meets that OSError and reports torch's own ``RuntimeError``
  (``unexpected pos``), as it does on a full disk. The disk stays full (or over quota) once it failed: every later
  write into that folder fails too, the job's own failure record included.
* EFBIG: a real ``RLIMIT_FSIZE`` set around the file's writes, so the kernel refuses them.
* EROFS (a folder remounted read-only): the open fails as ``open(2)`` reports it, naming the file; the folder stays
  read-only.
* vanished: the file's folder is removed between selpres's check (``mkdir``, a name freed) and the open, so the open
  fails with the real ENOENT.

Jobs run in this process through the console script's entry (``selpres.run.main.main``, as ``python train.py``),
so the outcome is the one a user gets; the re-run without the fault must end with the numbers of a run that met
none. The real full disk (a tmpfs) and a real file-size limit on a whole process are in tests/test_faults_disk.py.
"""

from __future__ import annotations

import builtins
import contextlib
import errno
import gc
import io
import json
import os
import re
import resource
import shutil
import signal
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import torch

from conftest import numbers

pytestmark = pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="the layer finds a file by /proc/self/fd")

STICKY = {"ENOSPC", "EDQUOT", "EROFS"}  # the disk stays full, over quota or read-only once it failed
AT_OPEN = {"EROFS", "vanished"}  # faults of the open; the others fail the writes
CODES = {"ENOSPC": errno.ENOSPC, "EDQUOT": errno.EDQUOT, "EFBIG": errno.EFBIG, "EROFS": errno.EROFS,
         "vanished": errno.ENOENT}  # fmt: skip


def final_name(path: str | Path) -> str:
    """The file a write is for: a temp file of :func:`selpres.storage.atomic_write` (``.NAME.XXXXXXXX.tmp``, the
    random part from mkstemp's letters, digits and ``_``) is for NAME."""
    name = os.path.basename(str(path))
    m = re.fullmatch(r"\.(.+)\.[a-z0-9_]{8}\.tmp", name)
    return m.group(1) if m else name


class _FailingRaw(io.RawIOBase):
    """A real file's raw stream whose writes meet the disk's fault (the rest: the real file's)."""

    def __init__(self, raw: io.FileIO, disk: Disk, path: str):
        self.raw, self.disk, self.path, self.written = raw, disk, path, 0
        self.budget = 0 if disk.fired else disk.budget  # a disk that failed has no room left

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return self.raw.seekable()

    def seek(self, pos: int, whence: int = 0) -> int:
        return self.raw.seek(pos, whence)

    def tell(self) -> int:
        return self.raw.tell()

    def fileno(self) -> int:
        return self.raw.fileno()

    def write(self, b) -> int:
        n = self.disk.write(self, bytes(b))
        self.written += n
        return n

    def close(self) -> None:
        if not self.closed:
            self.raw.close()
        super().close()


@dataclass
class Disk:
    """The disk under the files ``wants(final name)`` picks fails with ``fault`` at the open after ``skip`` opens
    for writing of such files, once ``budget`` bytes of that file are written (write faults). ``fired``: the
    paths that met it; ``newest``: the newest checkpoint epoch in the folder when it fired."""

    fault: str
    wants: Callable[[str], bool]
    skip: int = 0
    budget: int = 0
    fired: list[str] = field(default_factory=list)
    newest: int | None = None
    dead: Path | None = None  # the folder whose disk stays full or read-only

    def meets(self, path: str) -> bool:
        """Whether this open for writing of ``path`` meets the fault (counting the opens it lets pass)."""
        if self.dead is not None and Path(path).parent == self.dead:
            return True
        if self.fired or not self.wants(final_name(path)):  # one disk fails, once (and stays failed if STICKY)
            return False
        if self.skip > 0:
            self.skip -= 1
            return False
        return True

    def fire(self, path: str) -> OSError:
        """Note that ``path`` met the fault (the folder's newest checkpoint then); the OSError a syscall raises."""
        if not self.fired:
            self.newest = newest_epoch(Path(path).parent)
        self.fired.append(path)
        if self.fault in STICKY:
            self.dead = Path(path).parent
        code = CODES[self.fault]
        return OSError(code, os.strerror(code))

    def opening(self, path: str) -> None:
        """Before the real open of ``path`` (that meets the fault): a read-only folder refuses it, as open(2)
        does, naming it; a vanished folder is removed, so the real open fails."""
        if self.fault == "EROFS":
            e = self.fire(path)
            raise OSError(e.errno, e.strerror, path)
        self.fire(path)
        shutil.rmtree(Path(path).parent, ignore_errors=True)

    def write(self, raw: _FailingRaw, b: bytes) -> int:
        room = raw.budget - raw.written
        if self.fault == "EFBIG":  # the kernel refuses what passes the file-size limit (SIGXFSZ: ignored)
            soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
            resource.setrlimit(resource.RLIMIT_FSIZE, (raw.tell() + max(room, 0), hard))
            try:
                return raw.raw.write(b)
            except OSError as e:
                if e.errno == errno.EFBIG:
                    self.fire(raw.path)
                raise
            finally:
                resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        if room <= 0:
            raise self.fire(raw.path)
        return raw.raw.write(b[:room])  # the part that fits, as write(2) returns a short count

    @contextlib.contextmanager
    def mounted(self):
        """The layer in place: ``open``, ``os.fdopen`` and ``tempfile.mkstemp`` (how selpres opens what it
        writes) meet the fault for the files it picks and are the real ones for every other."""
        real_open, real_fdopen, real_mkstemp = builtins.open, os.fdopen, tempfile.mkstemp
        assert signal.getsignal(signal.SIGXFSZ) == signal.SIG_IGN  # as Python sets it: EFBIG, not a signal

        def writer(raw: io.FileIO, path: str, buffering: int):
            return io.BufferedWriter(
                _FailingRaw(raw, self, path), buffering if buffering > 1 else io.DEFAULT_BUFFER_SIZE
            )

        def writing(mode: str) -> bool:
            return any(c in mode for c in "wax+")

        def fake_open(
            file, mode="r", buffering=-1, encoding=None, errors=None, newline=None, closefd=True, opener=None
        ):
            if isinstance(file, (str, os.PathLike)) and writing(mode) and self.meets(os.fspath(file)):
                path = os.path.abspath(os.fspath(file))
                if self.fault in AT_OPEN:
                    self.opening(path)
                else:
                    raw = writer(io.FileIO(path, mode.replace("b", "").replace("t", "")), path, buffering)
                    return raw if "b" in mode else io.TextIOWrapper(raw, encoding or "utf-8", errors, newline)
            return real_open(file, mode, buffering, encoding, errors, newline, closefd, opener)

        def fake_fdopen(fd, mode="r", buffering=-1, *args, **kwargs):
            if isinstance(fd, int) and "b" in mode and writing(mode) and self.fault not in AT_OPEN:
                path = os.readlink(f"/proc/self/fd/{fd}")
                if self.meets(path):
                    return writer(io.FileIO(fd, mode.replace("b", "")), path, buffering)
            return real_fdopen(fd, mode, buffering, *args, **kwargs)

        def fake_mkstemp(suffix=None, prefix=None, dir=None, text=False):
            if self.fault in AT_OPEN and dir is not None and prefix is not None:
                path = os.path.join(os.path.abspath(dir), f"{prefix}abcd1234{suffix or ''}")
                if self.meets(path):
                    self.opening(path)
            return real_mkstemp(suffix, prefix, dir, text)

        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(builtins, "open", fake_open)
            mp.setattr(os, "fdopen", fake_fdopen)
            mp.setattr(tempfile, "mkstemp", fake_mkstemp)
            yield self


def newest_epoch(folder: Path) -> int | None:
    """The epoch of the newest readable checkpoint in ``folder`` (None: none)."""
    from selpres.run.checkpoint import read
    from selpres.storage import CHECKPOINT, CHECKPOINT_ALT

    epochs = []
    for name in (CHECKPOINT, CHECKPOINT_ALT):
        try:
            epochs.append(read(folder / name)["epoch"])
        except Exception:
            pass
    return max(epochs, default=None)


# ------------------------------------------------------------------------------------- a job, as a user runs it
JOB = [
    "data.heldout=300",
    "eval.heldout_curve=300",
    "logging.progress=false",
    "checkpoint.every=1",
    "schedule.epochs=[1,1,1,1,1]",
    "replicas=16",
]  # fmt: skip  (16 replicas: weights.pt 18 KB, past the buffer)


@dataclass
class Ran:
    code: int
    err: list[str]  # stderr's non-empty lines
    out: str


def train(folder: Path, *extra: str) -> Ran:
    """``python train.py JOB... hydra.run.dir=folder`` in this process (``extra`` starting with ``-m``: a sweep,
    whose overrides name its folder); what it printed and its exit status. What the entry changes for the process
    (signal handlers, the frozen garbage generation) is put back."""
    from selpres.run import main

    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1)}
    argv, out, err = sys.argv, io.StringIO(), io.StringIO()
    sweep = extra[:1] == ("-m",)
    sys.argv = (
        ["train.py", *extra[:1], *JOB, *extra[1:]] if sweep else ["train.py", *JOB, *extra, f"hydra.run.dir={folder}"]
    )
    code = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            main.main()
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else int(e.code is not None)
    finally:
        sys.argv = argv
        gc.unfreeze()
        for s, h in handlers.items():
            signal.signal(s, h)
    return Ran(code, [ln for ln in err.getvalue().splitlines() if ln.strip()], out.getvalue())


def clean_numbers(tmp_path_factory) -> dict:
    """The numbers of the job when nothing fails."""
    folder = tmp_path_factory.mktemp("clean") / "job"
    ran = train(folder)
    assert ran.code == 0, ran.err
    return numbers(json.loads((folder / "results.json").read_text()))


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return clean_numbers(tmp_path_factory)


def whole(folder: Path) -> None:
    """No temp file left, and every file under a final name reads whole: results.json as JSON, weights.pt and the
    checkpoints with torch's weights-only load (history.jsonl is append-only: a resume reads its checkpoint's part)."""
    from selpres.run.checkpoint import read

    assert not list(folder.glob(".*.tmp")), sorted(p.name for p in folder.iterdir())
    if (folder / "results.json").exists():
        assert json.loads((folder / "results.json").read_text())["status"] in ("complete", "diverged", "failed")
    if (folder / "weights.pt").exists():
        assert "params" in torch.load(folder / "weights.pt", weights_only=True)
    for name in ("checkpoint.pt", "checkpoint.alt.pt"):
        if (folder / name).exists():
            assert read(folder / name)["epoch"] >= 0


# ------------------------------------------------------------------------------------------- the fault table
def _is(*names: str) -> Callable[[str], bool]:
    return lambda n: n in names


# site -> (its files, opens let pass, bytes of the file written before the disk fails). A few KB into a file larger than
# the 8 KB buffer the disk fills inside a large write, as on a real disk: the kernel writes what fits, the next write
# fails and the buffer is left empty, so torch's RuntimeError is what leaves torch.save (weights.pt at 2 KB, a cache
# entry at 4 KB: test_wherever_the_disk_fills_... tries every point); history.jsonl's appends are smaller than the
# buffer and fail when it is flushed.
SITES: dict[str, tuple[Callable[[str], bool], int, int]] = {
    "weights.pt": (_is("weights.pt"), 0, 2048),
    "checkpoint pair": (_is("checkpoint.pt", "checkpoint.alt.pt"), 2, 4096),  # the third save
    "history.jsonl": (_is("history.jsonl"), 2, 0),  # the third append
    "results.json": (_is("results.json"), 0, 4096),
    "TensorBoard events": (lambda n: n.startswith("events.out.tfevents."), 0, 4096),  # a flush at a checkpoint
    "data cache": (lambda n: n.endswith(".task.pt"), 0, 4096),
}
FAULTS = ("ENOSPC", "EDQUOT", "EFBIG", "EROFS", "vanished")
TORCH_WRITES = ("weights.pt", "data cache")  # written by torch.save: a failed write leaves torch as its RuntimeError
CAUSES = {"ENOSPC": "disk full (ENOSPC)", "EDQUOT": "over quota (EDQUOT)", "EFBIG": "file-size limit (EFBIG)",
          "EROFS": "read-only folder (EROFS)", "vanished": "folder removed before the open (ENOENT)"}  # fmt: skip


def outcome(site: str, fault: str) -> str:
    """What a user gets when ``fault`` meets ``site`` (the docs' table; each case's test checks it)."""
    if site == "data cache":
        return "runs on without the cache (exit 0); `data.cache: not written: …` and one warning in the log"
    if fault == "vanished":
        return "exit 2, one line; the folder was removed, any checkpoint with it: the same command runs the job afresh"
    if site == "TensorBoard events" and fault in AT_OPEN:  # its only open is at set-up, before any checkpoint
        return "exit 2, one line; nothing to resume yet: the same command starts afresh"
    return "exit 2, one line; the last checkpoint intact: the same command resumes it"


SHORT = {  # an outcome's name in the docs' table
    "exit 2, one line; the last checkpoint intact: the same command resumes it": "resumes",
    "exit 2, one line; nothing to resume yet: the same command starts afresh": "afresh",
    "exit 2, one line; the folder was removed, any checkpoint with it: the same command runs the job afresh": "gone",
    "runs on without the cache (exit 0); `data.cache: not written: …` and one warning in the log": "runs on",
}


def fault_table() -> str:
    """The table docs/reproducibility.md shows (between its ``faults`` markers): what each fault at each write site
    gets, from :func:`outcome`, whose every cell a case of this file checks."""
    head = ["write site", *(CAUSES[f] for f in FAULTS), "torch's RuntimeError"]
    rows = [
        [f"`{site}`" if "." in site else site, *(SHORT[outcome(site, f)] for f in FAULTS),
         SHORT[outcome(site, "ENOSPC")] if site in TORCH_WRITES else "(torch does not write it)"]
        for site in SITES
    ]  # fmt: skip
    lines = [head, ["---"] * len(head), *rows]
    legend = [f"- **{name}**: {text}" for text, name in SHORT.items()]
    return "\n".join("| " + " | ".join(r) + " |" for r in lines) + "\n\n" + "\n".join(legend)


def test_the_fault_table_in_the_docs_is_the_one_these_tests_check():
    """docs/reproducibility.md's table is :func:`fault_table` (``python tests/test_faults.py`` prints it)."""
    from conftest import REPO

    text = (REPO / "docs" / "reproducibility.md").read_text()
    begin, end = "<!-- faults:begin (python tests/test_faults.py) -->\n", "\n<!-- faults:end -->"
    assert begin in text and end in text
    assert text.split(begin, 1)[1].split(end, 1)[0] == fault_table()


CASES = [(site, fault) for site in SITES for fault in FAULTS]
FAST = {"ENOSPC", "EROFS", "vanished"}  # the fast tier: the faults whose aftermath differs (full, read-only, gone)


@pytest.mark.parametrize(
    ("site", "fault"),
    [
        pytest.param(s, f, id=f"{s}-{f}".replace(" ", "_"), marks=() if f in FAST else pytest.mark.slow)
        for s, f in CASES
    ],
)
def test_a_fault_where_a_job_writes_gets_its_outcome(site, fault, clean, tmp_path, monkeypatch, request):
    wants, skip, budget = SITES[site]
    folder = tmp_path / "job"
    cache = tmp_path / "cache"
    if site == "data cache":  # a cache of this test's own, so the task is built and stored (not a hit)
        from selpres.data import task as T

        monkeypatch.setenv("SELPRES_DATA_CACHE", str(cache))
        T._task.cache_clear()
        request.addfinalizer(T._task.cache_clear)  # later jobs in this process build their own
    disk = Disk(fault, wants, skip, budget)
    from selpres import storage

    seen, real = [], storage.write_failure
    monkeypatch.setattr(storage, "write_failure", lambda e: seen.append(type(e).__name__) or real(e))
    with disk.mounted():
        ran = train(folder)
    assert disk.fired, f"the fault never met {site}"
    if site in TORCH_WRITES and fault in ("ENOSPC", "EDQUOT", "EFBIG"):  # torch's own report of it, turned to OSError
        assert "RuntimeError" in seen, seen
    target = Path(disk.fired[0])
    expected = outcome(site, fault)
    whole(folder)
    if site == "data cache":
        assert ran.code == 0 and ran.err == [], ran.err
        res = json.loads((folder / "results.json").read_text())
        said = f"not written: {target.parent / final_name(target)}: {os.strerror(CODES[fault])}"
        assert res["data"]["cache"].startswith(said), res["data"]["cache"]
        (warning,) = [ln for ln in (folder / "train.log").read_text().splitlines() if "data cache" in ln]
        assert "goes on without the cache" in warning and str(target.parent / final_name(target)) in warning
        assert not list(cache.glob("*.task.pt")) and not list(cache.glob(".*.tmp"))
        assert numbers(res) == clean
        return
    assert ran.code == 2, (ran.err, ran.out[-2000:])
    (line,) = ran.err  # one line, no traceback
    assert str(folder / final_name(target)) in line and os.strerror(CODES[fault]) in line, line
    if "resumes" in expected:
        assert disk.newest is not None and newest_epoch(folder) == disk.newest  # the previous checkpoint, intact
    else:
        assert newest_epoch(folder) is None
    again = train(folder)
    assert again.code == 0, again.err
    res = json.loads((folder / "results.json").read_text())
    assert res["resumed_from_epoch"] == (disk.newest if "resumes" in expected else None)
    assert numbers(res) == clean  # resumed (or run afresh) to the numbers of a run that met no fault
    assert len(list(folder.glob("events.out.tfevents.*.selpres"))) == 1 and not list(folder.glob("checkpoint*.pt"))
    whole(folder)


if __name__ == "__main__":  # the docs' table
    print(fault_table())
