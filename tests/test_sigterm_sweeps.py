"""Issue 26 in a sweep: a SIGTERM to a job's own process (a launcher's worker, where ``train.py``'s handlers never
ran; SLURM's preemption and ``scontrol requeue`` signal the job's processes) checkpoints at the end of the epoch
under way and the job ends in one line; the same sweep command resumes it from THAT checkpoint and ends
bit-identical to an uninterrupted run. Real sweeps, real launchers (submitit's local executor, joblib/loky), a
real signal to the job's process (its PID from the job folder's lock file)."""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from test_resume import COMMON, ROOT, newest_checkpoint, run
from test_sigterm import ARGS, STAGE_ENDS

from selpres.run.lock import LOCK

from conftest import numbers

pytestmark = pytest.mark.slow  # subprocesses
JOB = [*ARGS, "threads=1", "seed=0"]  # one job: the sweep of one point


def sweep(folder: Path, launcher: str) -> subprocess.Popen:
    extra = ["hydra.launcher.timeout_min=10"] if launcher.startswith("submitit") else []
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    command = [sys.executable, "train.py", "-m", f"hydra.sweep.dir={folder}", f"hydra/launcher={launcher}"]
    command += [*COMMON, *JOB, *extra]  # run()'s settings: the same config as the straight run
    return subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    """The same job, uninterrupted, as a plain ``python train.py`` run."""
    out = tmp_path_factory.mktemp("straight")
    run(out, JOB)
    return out


@pytest.mark.parametrize("launcher", ["submitit_local", "local2"])
def test_a_sigterm_to_a_sweep_job_checkpoints_and_the_same_sweep_resumes_it_exactly(tmp_path, straight, launcher):
    folder = tmp_path / "sweep"
    p = sweep(folder, launcher)
    deadline, job = time.time() + 240, None
    while time.time() < deadline:  # stage 3 done: into stage 4
        job = next((d for d in folder.glob("*seed=0*") if d.is_dir()), None) if folder.exists() else None
        if job is not None and newest_checkpoint(job)[1] >= 4:
            break
        time.sleep(0.05)
    time.sleep(0.6)  # an epoch or so into stage 4
    pid = int((job / LOCK).read_text().split()[0])  # the job's process: the worker that holds its folder
    assert pid != p.pid
    os.kill(pid, signal.SIGTERM)
    output, _ = p.communicate(timeout=120)
    assert p.returncode == 1, output  # the sweep reports the stopped job (Hydra's one line), no traceback
    ckpt, epoch = newest_checkpoint(job)
    assert epoch not in STAGE_ENDS and 4 < epoch < max(STAGE_ENDS), (epoch, output)  # at the signal, not periodic
    command = shlex.join(["python", "train.py", *p.args[2:]])  # the sweep's own command resumes the job
    line = f"stopped by SIGTERM after epoch {epoch}: checkpoint written in {job}; resume: {command}"
    assert line in output.splitlines() and "Traceback" not in output, output
    assert line in (job / "train.log").read_text()
    assert not (job / "results.json").exists() and not (job / LOCK).exists()

    again = sweep(folder, launcher)
    output, _ = again.communicate(timeout=300)
    assert again.returncode == 0, output
    assert f"resuming from {ckpt} at epoch {epoch}" in (job / "train.log").read_text()
    a = json.loads((job / "results.json").read_text())
    b = json.loads((straight / "results.json").read_text())
    assert a["resumed_from_epoch"] == epoch
    assert numbers(a) == numbers(b)  # the curves without their wall seconds
    assert a["presentations_done"] == b["presentations_done"]
    wa, wb = torch.load(job / "weights.pt")["params"], torch.load(straight / "weights.pt")["params"]
    assert all(torch.equal(x, y) for x, y in zip(wa, wb))
