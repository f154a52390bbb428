"""Issue 26: SIGTERM and SIGUSR1 (SLURM's preemption, requeue and --signal) write a checkpoint at once and stop
with one line and status 143 (issue 39: the line names the folder, the epoch and the command that resumes); that
command resumes from THAT checkpoint, mid-stage, and ends bit-identical to an uninterrupted run. Real signals to a
real ``python train.py``."""

from __future__ import annotations

import json
import os
import shlex
import signal
import subprocess
import sys
import time

import gated_route
import pytest
import torch
from test_outcomes import says
from test_resume import COMMON, ROOT, newest_checkpoint, run

from selpres.run import outcomes

from conftest import numbers

pytestmark = pytest.mark.slow  # subprocesses
# checkpoints at stage ends only (checkpoint.every=1000): stage 4 runs epochs 5..29, 0.05-0.4 s each on the
# reference engine (machine and load), so a signal 0.6 s into it finds no periodic checkpoint newer than epoch 4
ARGS = ["engine=reference", "schedule.epochs=[1,1,2,25,3]", "replicas=1", "checkpoint.every=1000"]
STAGE_ENDS = {1, 2, 4, 29}  # epochs done at the end of stages 1-4 (where periodic checkpoints are written)
ENV = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}


@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    out = tmp_path_factory.mktemp("straight")
    run(out, ARGS)
    return out


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGUSR1])
def test_a_signal_mid_stage_checkpoints_there_and_the_rerun_resumes_it_exactly(tmp_path, straight, sig):
    out = tmp_path / "job"
    p = run(out, ARGS, wait=False)
    deadline = time.time() + 240
    while newest_checkpoint(out)[1] < 4 and time.time() < deadline:  # stage 3 done: into stage 4
        time.sleep(0.05)
    time.sleep(0.6)  # an epoch or so into stage 4
    p.send_signal(sig)
    output, _ = p.communicate(timeout=120)
    assert p.returncode == 143, output
    ckpt, epoch = newest_checkpoint(out)
    assert epoch not in STAGE_ENDS and 4 < epoch < max(STAGE_ENDS), (epoch, output)  # at the signal, not periodic
    command = shlex.join(["python", "train.py", *COMMON, *ARGS, f"hydra.run.dir={out}"])
    line = f"stopped by {sig.name} after epoch {epoch}: checkpoint written in {out}; resume: {command}"
    assert line in output.splitlines() and "Traceback" not in output, output
    assert says(outcomes.TERMINATED, line) and not (out / "results.json").exists()  # the table's row

    resumed = subprocess.run(  # the command the line names, as a user would paste it
        [sys.executable, *shlex.split(line.partition("; resume: ")[2])[1:]],
        cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    assert f"resuming from {ckpt} at epoch {epoch}" in resumed.stdout
    assert resumed.stdout.strip().splitlines()[-1] == f"results: {out / 'results.json'} (resumed from epoch {epoch})"
    a = json.loads((out / "results.json").read_text())
    b = json.loads((straight / "results.json").read_text())
    assert a["resumed_from_epoch"] == epoch
    assert numbers(a) == numbers(b)  # the curves without their wall seconds
    assert a["presentations_done"] == b["presentations_done"]
    wa, wb = torch.load(out / "weights.pt")["params"], torch.load(straight / "weights.pt")["params"]
    assert all(torch.equal(x, y) for x, y in zip(wa, wb))


@pytest.mark.parametrize("where", ["at the record", "making the data"])
def test_a_signal_during_set_up_removes_what_the_run_created(tmp_path, where):
    """Before the loop: nothing to keep, so nothing is left in a folder that existed before; one line, 143. The
    signal comes as Hydra's record appears, or while the job makes its data (tests/gated_route.py holds the job
    there until the signal is sent: a fixed delay once let a fast machine reach epoch 6 first)."""
    out = tmp_path / "job"
    out.mkdir()
    (out / "mine.txt").write_text("the user's")
    gate = tmp_path / "gate"
    gated = where == "making the data"
    p = run(out, [*ARGS, gated_route.OVERRIDE] if gated else ARGS, wait=False, **gated_route.env(gate))
    mark = gated_route.reached(gate) if gated else out / ".hydra" / "config.yaml"
    gated_route.signal_when(p, mark, signal.SIGTERM, gate if gated else None)
    output, _ = p.communicate(timeout=120)
    assert p.returncode == 143, output
    (line,) = [x for x in output.splitlines() if x.startswith("stopped by SIGTERM")]  # before or inside the set-up
    inside = f"stopped by SIGTERM during set-up: nothing of this run was kept ({out} as it was)"
    if gated:
        assert line == inside, output
    else:
        assert line in ("stopped by SIGTERM before the job started: nothing was written", inside), output
    assert sorted(x.name for x in out.iterdir()) == ["mine.txt"]
