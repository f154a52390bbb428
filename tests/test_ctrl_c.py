"""Issue 39: a Ctrl-C is never lost and never cuts a checkpoint. Real SIGINTs to a real ``python train.py``.

1. Across the whole set-up (point 7): a Ctrl-C once went missing (the job ran to its end, exit 0) or came out as a
   broken config (exit 1: omegaconf's clean-up replaced the interrupt with an error of its half-built node). SIGINT
   at delays spread from the moment Python runs train.py to the first epoch, with a native kernel built from an
   empty cache on the way (``SELPRES_CACHE_DIR``) and, in a few tries, the folder held by another process: every try
   ends with exit 130 and one line (or, where the folder is busy and that is found first, the busy refusal), and the
   user's folder is as it was, or resumable where the line says a checkpoint was written.
2. A second Ctrl-C while the checkpoint at the stop is being written (point 3) does not cut it: the pair rule of
   selpres.run.checkpoint holds, and the command the line names resumes from that checkpoint.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_reliability import _epochs_once_each, resumable
from test_resume import newest_checkpoint

from selpres.run.lock import FolderLock

from conftest import REPO

pytestmark = pytest.mark.slow  # subprocesses
JOB = ["data.heldout=300", "eval.heldout_curve=300", "logging.progress=false", "replicas=4", "threads=1"]
LONG = [*JOB, "schedule.epochs=[3000,3000,3000,3000,3000]", "checkpoint.every=1"]  # still running at any delay
TRIES = 14  # delays across the set-up (each try a process start: about a second of CPU here, more under load)


def start(folder: Path, args: list[str], **env) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "train.py", *args, f"hydra.run.dir={folder}"],
        cwd=REPO, env={k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"} | env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        # a background job starts with SIGINT ignored: deliver it as a terminal would, whoever runs the tests
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip


def users_folder(path: Path) -> Path:
    path.mkdir(parents=True)
    (path / "mine.txt").write_text("the user's")
    return path


def interpreter_start() -> float:
    """Seconds Python takes to start here before it runs a script's first line (its site, the editable install):
    a Ctrl-C inside it is Python's own (a KeyboardInterrupt traceback), before any of selpres runs."""
    times = []
    for _ in range(3):
        t0 = time.monotonic()
        subprocess.run([sys.executable, "-c", "pass"], cwd=REPO, check=True)
        times.append(time.monotonic() - t0)
    return max(times)


def loop_start(tmp: Path) -> float:
    """Seconds from the command to its first epoch's end (a fresh kernel build included), from one real run."""
    folder = tmp / "measure"
    p = start(folder, LONG, SELPRES_CACHE_DIR=str(tmp / "measure-cache"))
    t0 = time.monotonic()
    while newest_checkpoint(folder)[1] < 1 and p.poll() is None and time.monotonic() - t0 < 600:
        time.sleep(0.01)
    took = time.monotonic() - t0
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 130 and "checkpoint written" in err, err
    return took


def test_a_ctrl_c_anywhere_in_set_up_stops_the_job(tmp_path):
    first, last = 2 * interpreter_start(), 1.15 * loop_start(tmp_path)  # the last tries in the first epochs
    delays = [first + (last - first) * i / (TRIES - 1) for i in range(TRIES)]
    outcomes, failures = [], []
    for i, delay in enumerate(delays):
        folder = users_folder(tmp_path / f"try{i}" / "D")
        held = FolderLock.take(folder) if i in (1, 3) else None  # two early tries: the folder busy (held here)
        try:
            p = start(folder, LONG, SELPRES_CACHE_DIR=str(tmp_path / f"try{i}" / "cache"))  # an empty kernel cache
            time.sleep(delay)
            p.send_signal(signal.SIGINT)
            out, err = p.communicate(timeout=300)
        finally:
            if held is not None:
                held.release()
        lines = err.strip().splitlines()
        line = lines[-1] if lines else ""
        outcomes.append((round(delay, 2), p.returncode, line[:60]))
        busy = (
            held is not None
            and p.returncode == 2
            and line
            == (f"error: {folder} is in use by process {os.getpid()} (one writer per job folder); nothing was touched")
        )
        problems = []
        if not busy and (p.returncode != 130 or not line.startswith("stopped by SIGINT ")):
            problems.append(f"exit {p.returncode}, last line {line!r}")
        if "Traceback" in out + err or len(lines) != 1:
            problems.append(f"{len(lines)} lines on stderr")
        left = sorted(x.name for x in folder.iterdir())
        if (folder / "mine.txt").read_text() != "the user's":
            problems.append("the user's file changed")
        if "checkpoint written in" in line:
            if not resumable(folder, line, *LONG):
                problems.append(f"not resumable: {left}")
        elif left != ["mine.txt"]:
            problems.append(f"left {left}")
        if problems:
            failures.append(f"SIGINT at {delay:.2f} s: {'; '.join(problems)}\n{err[-1500:]}")
    print("\n".join(map(str, outcomes)))  # (delay, exit status, line): the sweep's record, with -s
    assert not failures, "\n".join(failures)


def test_a_second_ctrl_c_while_the_checkpoint_is_written_does_not_cut_it(tmp_path):
    """20,000 replicas make a checkpoint ~38 MB (on 100 drawn patterns, so an epoch is short): once the loop runs
    (a checkpoint an epoch), a first SIGINT asks to stop, and a second is sent once the temporary file of the
    checkpoint at the stop is there (and still there just after: its write was under way). The pair rule holds: the
    newest checkpoint is the one of the epoch the line names, it reads, and the command the line names resumes from
    it, every epoch once."""
    folder = tmp_path / "D"
    data = ["data=sampled", "data.n=100", "schedule=conventional", "schedule.epochs=[16]"]
    args = [*JOB[:3], *data, "replicas=20000", "engine=fast", "checkpoint.every=1"]
    caught, reached = False, 1  # from epoch 2 on: the loop is running
    for _ in range(4):  # the write takes milliseconds: a try that misses it is followed by a resume and another
        p = start(folder, args)
        t0 = time.monotonic()
        while newest_checkpoint(folder)[1] <= reached and p.poll() is None and time.monotonic() - t0 < 600:
            time.sleep(0.01)  # in the loop, just after a checkpoint: the next write is the one at the stop
        p.send_signal(signal.SIGINT)
        while p.poll() is None:
            temps = list(folder.glob(".checkpoint*.tmp"))
            if temps:
                p.send_signal(signal.SIGINT)
                caught = any(t.exists() for t in temps)
                break
        out, err = p.communicate(timeout=600)
        assert p.returncode == 130 and "Traceback" not in err, err
        (line,) = err.strip().splitlines()
        reached = int(re.search(r"after epoch (\d+): checkpoint written in ", line).group(1))
        assert newest_checkpoint(folder)[1] == reached and resumable(folder, line, *args), line
        if caught:
            break
    assert caught, "no second SIGINT landed during a checkpoint's write in 4 tries"
    resumed = subprocess.run(
        [sys.executable, *shlex.split(line.partition("; resume: ")[2])[1:]],
        cwd=REPO, env={k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"},
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert resumed.returncode == 0, resumed.stderr
    assert resumed.stdout.strip().splitlines()[-1].endswith(f"(resumed from epoch {reached})")
    _epochs_once_each(json.loads((folder / "results.json").read_text()))
