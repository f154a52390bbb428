"""``python train.py``: a real run, skipping a finished job, and one-line config errors (subprocesses)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REPO

TINY = ["schedule.epochs=[1,1,1,1,1]", "data.heldout=200", "eval.heldout_curve=200", "engine=fast"]
TIMEOUT = 180


def _env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("HYDRA_FULL_ERROR", "OC_CAUSE")}
    env["PYTHONWARNINGS"] = "ignore"
    return env


def _cmd(run_dir: Path, *overrides: str) -> list[str]:
    return [sys.executable, "train.py", *overrides, f"hydra.run.dir={run_dir}"]


def _run(run_dir: Path, *overrides: str) -> subprocess.CompletedProcess:
    return subprocess.run(_cmd(run_dir, *overrides), cwd=REPO, env=_env(), capture_output=True, text=True, timeout=TIMEOUT)


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("cli") / "run"
    proc = _run(run_dir, *TINY)
    return proc, run_dir


def test_smoke_run_writes_results_tensorboard_and_summary(smoke):
    proc, run_dir = smoke
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "Traceback" not in out
    res = json.loads((run_dir / "results.json").read_text())
    assert res["status"] == "complete"
    # 50 + 100 + 400 + 800 + 1002 patterns, one epoch each
    assert res["presentations_done"] == 2352 == res["schedule"]["presentations"]
    assert res["schedule"]["sizes"] == [50, 100, 400, 800, 1002]
    trained = [c for c in res["curves"] if c["epoch"] >= 0]  # (epoch -1, if present, scores the initial weights)
    assert [c["size"] for c in trained] == [50, 100, 400, 800, 1002]
    assert [c["presentations"] for c in trained] == [50, 150, 550, 1350, 2352]
    assert res["summary"]["heldout_rms_nm_overall"]["mean"] > 0
    assert list((run_dir / "tb").rglob("events.out.tfevents.*")), "no TensorBoard event files"
    assert (run_dir / ".hydra" / "config.yaml").exists()
    assert not (run_dir / "checkpoint.pt").exists()  # removed once the job finished
    # the summary table and one progress line per stage
    for text in ("schedule", "cost T/t", "2,352", "held-out RMS", "test-10 RMS", str(run_dir / "results.json")):
        assert text in proc.stdout, text
    assert sum(line.startswith("stage ") for line in proc.stdout.splitlines()) == 5


def test_same_command_again_is_skipped(smoke):
    first, run_dir = smoke
    assert first.returncode == 0
    results = run_dir / "results.json"
    before = results.read_bytes(), results.stat().st_mtime_ns, (run_dir / "weights.pt").stat().st_mtime_ns
    events = sorted((run_dir / "tb").rglob("*"))
    proc = _run(run_dir, *TINY)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "already done" in proc.stdout
    assert "held-out RMS" in proc.stdout  # still shows the table
    assert not any(line.startswith("stage ") for line in proc.stdout.splitlines())  # did not train
    assert (results.read_bytes(), results.stat().st_mtime_ns, (run_dir / "weights.pt").stat().st_mtime_ns) == before
    assert sorted((run_dir / "tb").rglob("*")) == events


def test_summary_table_for_a_budget_below_one_epoch(smoke):
    """schedule=matched with a budget < n has no full epoch, only a partial one: the summary table must
    still render it (a crash there would turn a finished job into a 'failed' results.json)."""
    from selpres.schedule import build_schedule
    from selpres.train import summary_table

    _, run_dir = smoke
    res = json.loads((run_dir / "results.json").read_text())
    res["schedule"] = {"name": "matched", "order": "stratified", **build_schedule([1.0], None, 1002, 500).describe()}
    text = summary_table(res)
    assert "500 presentations" in text and "ratio 1.000" in text


# (override, key the message must name, exit code: 2 = ConfigError from the job, else any non-zero)
BAD = [
    ("topology.layers=6-x-2", "topology.layers", 2),
    ("optim.lr=-1", "optim.lr", 2),
    ("optim.momentum=1.5", "optim.momentum", 2),
    ("schedule.sizes=[100,50,1002]", "schedule.sizes", 2),
    ("schedule.epochs=[0,1,1,1,1]", "schedule.epochs", 2),
    ("optim.lrr=1", "optim.lrr", None),  # typed schema: Hydra refuses before the job starts
    ("optim.lr=abc", "optim.lr", None),
    ("data.theta.step=0.3", "data.theta", 2),  # 0..0.5 is not a whole number of 0.3 steps
]


def test_bad_inputs_fail_cleanly(tmp_path):
    """Each bad input: non-zero exit, a message naming the key, no traceback, no job folder left behind.
    The subprocesses run concurrently (each is mostly interpreter start-up)."""
    procs = []
    for i, (override, key, code) in enumerate(BAD):
        run_dir = tmp_path / f"bad{i}" / "run"
        p = subprocess.Popen(_cmd(run_dir, *TINY, override), cwd=REPO, env=_env(),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append((override, key, code, run_dir, p))
    failures = []
    deadline = time.monotonic() + TIMEOUT
    for override, key, code, run_dir, p in procs:
        try:
            stdout, stderr = p.communicate(timeout=max(1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            stdout, stderr = p.communicate()
            failures.append(f"{override}: hung")
            continue
        out = stdout + stderr
        problems = []
        if p.returncode == 0:
            problems.append("exit code 0")
        elif code is not None and p.returncode != code:
            problems.append(f"exit code {p.returncode}, expected {code}")
        if key not in out:
            problems.append(f"message does not name {key}")
        if "Traceback" in out:
            problems.append("traceback printed")
        if run_dir.exists():
            problems.append(f"left {sorted(f.name for f in run_dir.iterdir())} in the run dir")
        if code == 2 and not any(line.startswith("error: ") and key in line for line in stderr.splitlines()):
            problems.append("no one-line 'error: <key>=...' on stderr")
        if problems:
            failures.append(f"{override}: {'; '.join(problems)}\n    output: {out.strip()[-400:]!r}")
    assert not failures, "\n".join(failures)


def test_overwrite_starts_afresh_instead_of_resuming_a_stale_checkpoint(tmp_path):
    run_dir = tmp_path / "run"
    assert _run(run_dir, *TINY).returncode == 0
    (run_dir / "checkpoint.pt").write_bytes(b"left over by an older, killed run")
    proc = _run(run_dir, *TINY, "overwrite=true")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "resuming" not in proc.stdout and sum(line.startswith("stage ") for line in proc.stdout.splitlines()) == 5
    assert not (run_dir / "checkpoint.pt").exists()
