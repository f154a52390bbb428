"""Multirun sweeps: a failing job leaves the others complete; re-running fills in only what is missing."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

from conftest import run_python

pytestmark = pytest.mark.slow  # subprocesses
TINY = ["schedule.epochs=[1,1,1,1,1]", "data.heldout=200", "eval.heldout_curve=200", "logging.progress=false"]


def multirun(sweep_dir: Path, *args: str) -> subprocess.CompletedProcess:
    return run_python("train.py", "-m", f"hydra.sweep.dir={sweep_dir}", *TINY, *args)


def results(sweep_dir: Path, key: str) -> dict[str, dict]:
    """Job results keyed by the swept override ``key=value`` (folders are named by all overrides)."""
    out = {}
    for p in sweep_dir.glob("*/results.json"):
        (value,) = re.findall(rf"(?:^|,){re.escape(key)}=([^,]+)", p.parent.name)
        out[f"{key}={value}"] = json.loads(p.read_text())
    return out


def job_dir(sweep_dir: Path, swept: str) -> Path:
    (match,) = [d for d in sweep_dir.iterdir() if re.search(rf"(?:^|,){re.escape(swept)}(?:,|$)", d.name)]
    return match


def test_one_failing_job_does_not_take_the_sweep_down_and_rerun_fills_in(tmp_path):
    sweep = tmp_path / "sweep"
    first = multirun(sweep, "optim.lr=0.15,-1,0.3")
    assert first.returncode != 0  # the sweep reports its failure...
    res = results(sweep, "optim.lr")
    assert res["optim.lr=0.15"]["status"] == "complete"  # ...but the jobs around it finished
    assert res["optim.lr=0.3"]["status"] == "complete"
    bad = res["optim.lr=-1"]
    assert bad["status"] == "failed" and "optim.lr" in bad["error"]
    assert "optim.lr" in (job_dir(sweep, "optim.lr=-1") / "train.log").read_text()
    done = job_dir(sweep, "optim.lr=0.15") / "results.json"
    stamp = done.stat().st_mtime_ns

    again = multirun(sweep, "optim.lr=0.15,-1,0.3")
    assert again.stdout.count("already done") == 2
    assert done.stat().st_mtime_ns == stamp  # the finished job was not redone
    assert results(sweep, "optim.lr")["optim.lr=-1"]["status"] == "failed"


def test_a_crash_leaves_its_traceback_in_the_job_log(tmp_path):
    sweep = tmp_path / "sweep"
    assert multirun(sweep, "seed=0,1").returncode == 0
    job = job_dir(sweep, "seed=1")  # make it look unfinished, with a folder where its TensorBoard event file goes
    (job / "results.json").unlink()
    (events,) = job.glob("events.out.tfevents.*")
    events.unlink()
    events.mkdir()  # a folder where a file belongs: the job crashes when it replaces its log
    out = multirun(sweep, "seed=0,1")
    assert out.returncode != 0
    res = results(sweep, "seed")
    assert res["seed=0"]["status"] == "complete"
    assert res["seed=1"]["status"] == "failed" and res["seed=1"]["kind"] == "exception"
    assert "Traceback" in (job_dir(sweep, "seed=1") / "train.log").read_text()


def test_a_checkpoint_that_cannot_be_read_is_moved_aside_not_resumed_or_lost(tmp_path):
    sweep = tmp_path / "sweep"
    assert multirun(sweep, "seed=0,1").returncode == 0
    job = job_dir(sweep, "seed=1")  # make it look killed mid-run, with a corrupt checkpoint
    (job / "results.json").unlink()
    (job / "checkpoint.pt").write_bytes(b"not a checkpoint")
    out = multirun(sweep, "seed=0,1")
    assert out.returncode == 0, out.stderr[-2000:]
    res = results(sweep, "seed")["seed=1"]
    assert res["status"] == "complete" and res["resumed_from_epoch"] is None
    (stale,) = job.glob("checkpoint.stale-*.pt")
    assert stale.read_bytes() == b"not a checkpoint" and res["stale_checkpoint"] == str(stale)
    assert "cannot be read" in (job / "train.log").read_text() and "moved it to" in out.stdout


@pytest.mark.parametrize("launcher", ["local2", "submitit_local"])
def test_parallel_launchers_run_the_sweep_and_survive_a_failing_job(tmp_path, launcher):
    sweep = tmp_path / "sweep"
    extra = ["threads=1"] + (["hydra.launcher.timeout_min=10"] if launcher == "submitit_local" else [])
    out = multirun(sweep, f"hydra/launcher={launcher}", "optim.lr=0.15,-1,0.3", *extra)
    res = results(sweep, "optim.lr")
    assert sorted(res) == ["optim.lr=-1", "optim.lr=0.15", "optim.lr=0.3"], out.stderr[-2000:]
    assert res["optim.lr=0.15"]["status"] == res["optim.lr=0.3"]["status"] == "complete"
    assert res["optim.lr=-1"]["status"] == "failed" and "optim.lr" in res["optim.lr=-1"]["error"]
