"""Issues 37 and 39: the one table of how a job ends (``selpres.run.outcomes.OUTCOMES``), walked. Each row is
provoked for real, as a user meets it: a real finished job, the same command again, another config into its
folder, a bad config and a command line Hydra refuses, a real second process racing for a folder, a real Ctrl-C,
the command its line names, a user's plug-in that crashes; and each ends with the row's exit status, its one line
and what the row says of results.json. The rows that need a special machine state (a memory cap, a file-size
limit, a killed sweep, a SIGTERM mid-stage) are provoked in the files :data:`ELSEWHERE` names, and the walk checks
that those tests exist. docs/usage.md prints the same table."""

from __future__ import annotations

import ast
import json
import os
import re
import shlex
import shutil
import signal
import string
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_resume import newest_checkpoint

from selpres.run import outcomes
from selpres.run.lock import LOCK

from conftest import REPO

pytestmark = pytest.mark.slow  # subprocesses
TINY = ["schedule.epochs=[1,1,1,1,1]", "data.heldout=200", "eval.heldout_curve=200"]
ENV = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
ELSEWHERE = {  # row -> the test that provokes it for real (and checks its line and status)
    "terminated": "test_sigterm.py::test_a_signal_mid_stage_checkpoints_there_and_the_rerun_resumes_it_exactly",
    "orphaned": "test_reliability.py::test_sweep_workers_stop_when_the_sweep_is_killed_and_the_rerun_matches",
    "out of memory": "test_refusals.py::test_an_allocation_that_fails_in_set_up_is_the_same_refusal",
    "write failure": "test_reliability.py::test_a_write_the_kernel_refuses_is_one_line_and_the_rerun_resumes",
}


def says(outcome: outcomes.Outcome, line: str) -> bool:
    """Whether ``line`` is ``outcome``'s line with its blanks filled in."""
    pattern = "".join(
        re.escape(text) + ("" if name is None else ".+") for text, name, *_ in string.Formatter().parse(outcome.line)
    )
    return re.fullmatch(pattern, line) is not None


def train(folder: Path, *args: str, env: dict | None = None, wait: bool = True):
    cmd = [sys.executable, "train.py", *args, f"hydra.run.dir={folder}"]
    kw = dict(cwd=REPO, env={**ENV, **(env or {})}, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if wait:
        return subprocess.run(cmd, timeout=600, **kw)
    return subprocess.Popen(cmd, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL), **kw)


def last(text: str) -> str:
    return text.strip().splitlines()[-1]


def ended(outcome: outcomes.Outcome, proc, stream: str) -> str:
    """The process ended as ``outcome``: its exit status, its last line that row's, no traceback. Returns the line."""
    out = proc.stdout + proc.stderr
    assert proc.returncode == outcome.code, out
    assert "Traceback" not in out, out
    line = last(getattr(proc, stream))
    assert says(outcome, line), line
    return line


def status(folder: Path) -> str | None:
    path = folder / "results.json"
    return json.loads(path.read_text())["status"] if path.exists() else None


def snapshot(folder: Path) -> dict:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes() if p.is_file() else "dir" for p in sorted(folder.rglob("*"))
    }


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    folder = tmp_path_factory.mktemp("done") / "D"
    return folder, train(folder, *TINY)


def test_done(finished):
    folder, proc = finished
    line = ended(outcomes.DONE, proc, "stdout")
    assert line == f"results: {folder / 'results.json'}" and status(folder) == "complete"


def test_skipped(finished, tmp_path):
    folder = tmp_path / "D"
    shutil.copytree(finished[0], folder)
    before = (folder / "results.json").read_bytes()
    line = ended(outcomes.SKIPPED, train(folder, *TINY), "stdout")
    assert line == f"already done: {folder / 'results.json'} (overwrite=true to run it again)"
    assert (folder / "results.json").read_bytes() == before


def test_protected(finished, tmp_path):
    folder = tmp_path / "D"
    shutil.copytree(finished[0], folder)
    before = snapshot(folder)
    line = ended(outcomes.PROTECTED, train(folder, *TINY, "seed=7"), "stderr")
    assert f"{folder} holds a finished job of another config (seed: 0 → 7)" in line
    assert snapshot(folder) == before and status(folder) == "complete"


@pytest.mark.parametrize(
    "bad, line",
    [
        ("optim.momentum=1.5", "error: optim.momentum=1.5 is not allowed: expected a momentum in [0, 1)"),
        ("replicas=four", "error: replicas='four' is not allowed: expected a whole number"),  # Hydra's own
    ],
)
def test_refused(tmp_path, bad, line):
    folder = tmp_path / "D"
    proc = train(folder, *TINY, bad)
    assert ended(outcomes.REFUSED, proc, "stderr") == line
    assert len(proc.stderr.strip().splitlines()) == 1 and not folder.exists()  # nothing of the run, no results


def test_busy_then_interrupted_then_resumed(tmp_path):
    """A (a real job) holds the folder; B, the same command, is refused naming A; a Ctrl-C stops A with a checkpoint
    at the stop and one line naming the folder, the epoch and the command that resumes; that command resumes."""
    folder = tmp_path / "D"
    # checkpoints at stage ends only (epochs 1-4) but for the one at the stop, which the line must name
    args = [*TINY[1:], "replicas=4", "engine=fast", "schedule.epochs=[1,1,1,1,400]", "checkpoint.every=1000"]
    a = train(folder, *args, wait=False)
    try:
        deadline = time.monotonic() + 300
        while newest_checkpoint(folder)[1] < 4 and a.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)  # into the last stage
        a.send_signal(signal.SIGSTOP)  # A holds its folder while B starts, however long that takes
        try:
            b = train(folder, *args)
        finally:
            a.send_signal(signal.SIGCONT)
        holder = int((folder / LOCK).read_text().split()[0])
        assert holder == a.pid
        line = ended(outcomes.BUSY, b, "stderr")
        assert line == f"error: {folder} is in use by process {a.pid} (one writer per job folder); nothing was touched"
        a.send_signal(signal.SIGINT)
        out, err = a.communicate(timeout=300)
    finally:
        a.kill()
    line = ended(outcomes.INTERRUPTED, subprocess.CompletedProcess(a.args, a.returncode, out, err), "stderr")
    epoch = int(re.search(r"after epoch (\d+):", line).group(1))
    command = shlex.join(["python", "train.py", *args, f"hydra.run.dir={folder}"])
    assert line == f"stopped by SIGINT after epoch {epoch}: checkpoint written in {folder}; resume: {command}"
    assert newest_checkpoint(folder)[1] == epoch and status(folder) is None  # the checkpoint AT the stop

    resumed = subprocess.run(
        [sys.executable, *shlex.split(line.partition("; resume: ")[2])[1:]],
        cwd=REPO, env=ENV, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    line = ended(outcomes.RESUMED, resumed, "stdout")
    assert line == f"results: {folder / 'results.json'} (resumed from epoch {epoch})"
    res = json.loads((folder / "results.json").read_text())
    assert res["status"] == "complete" and res["resumed_from_epoch"] == epoch


CRASH = '''
class Crash:
    """sigmoid units whose backward fails on its 40th call: a bug in a user's plug-in, mid-training."""
    calls = 0

    @staticmethod
    def forward(z):
        return z.sigmoid()

    @staticmethod
    def prime(z, a):
        Crash.calls += 1
        if Crash.calls >= 40:
            raise RuntimeError("a bug in the plug-in's backward")
        return a * (1 - a)
'''


def test_failed(tmp_path):
    (tmp_path / "crashing.py").write_text(CRASH)
    folder = tmp_path / "D"
    proc = train(folder, *TINY, "model.activation=crashing.Crash", env={"PYTHONPATH": f"{tmp_path}:{REPO}"})
    line = ended(outcomes.FAILED, proc, "stderr")
    error = "RuntimeError: a bug in the plug-in's backward"
    assert line == f"error: the job failed ({error}); the traceback is in {folder / 'train.log'}"
    assert status(folder) == "failed"
    log = (folder / "train.log").read_text()
    assert "Traceback" in log and "a bug in the plug-in's backward" in log


HERE = {  # row -> the test above that provokes it
    "done": test_done,
    "skipped": test_skipped,
    "protected": test_protected,
    "refused": test_refused,
    "busy": test_busy_then_interrupted_then_resumed,
    "interrupted": test_busy_then_interrupted_then_resumed,
    "resumed": test_busy_then_interrupted_then_resumed,
    "failed": test_failed,
}


def test_every_row_is_walked():
    """Every row of the table is provoked: by a test above (each ends in ``ended(<its row>, ...)``) or by the test
    :data:`ELSEWHERE` names, which must exist."""
    names = [o.name for o in outcomes.OUTCOMES]
    assert len(set(names)) == len(names) and set(HERE) | set(ELSEWHERE) == set(names) and not set(HERE) & set(ELSEWHERE)
    here = (REPO / "tests" / "test_outcomes.py").read_text()
    for name, test in HERE.items():
        row = next(k for k, v in vars(outcomes).items() if isinstance(v, outcomes.Outcome) and v.name == name)
        body = here[here.index(f"def {test.__name__}(") :].split("\ndef ", 1)[0]
        assert f"ended(outcomes.{row}," in body, (name, test.__name__)
    for node in ELSEWHERE.values():
        file, test = node.split("::")
        defined = {
            f.name for f in ast.walk(ast.parse((REPO / "tests" / file).read_text())) if isinstance(f, ast.FunctionDef)
        }
        assert test in defined, node


def test_docs_print_the_table():
    """docs/usage.md's table of outcomes is this table: each row's name, exit status and line, in order."""
    text = (REPO / "docs" / "usage.md").read_text()
    rows = re.findall(r"^\| \*\*(.+?)\*\* \| (\d+) \| `(.+?)` \|", text, re.MULTILINE)
    assert rows == [(o.name, str(o.code), o.line) for o in outcomes.OUTCOMES]
