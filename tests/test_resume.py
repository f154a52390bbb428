"""Checkpoint and resume with a real SIGKILL: the resumed run's results equal an uninterrupted run's."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from selpres.run.checkpoint import read as read_checkpoint

from conftest import numbers, requires_native

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow  # subprocesses
COMMON = ["checkpoint.every=1", "data.heldout=300", "eval.heldout_curve=300", "logging.progress=false"]
ENGINES = {
    # slow enough (≈0.5 ms a presentation) to be killed mid-run
    "reference": ["engine=reference", "schedule.epochs=[1,1,2,3,3]", "replicas=1"],
    # the kernel is ~1000x faster: many replicas (two interleaved groups and a leftover) and more epochs
    "native": ["engine=native", "schedule.epochs=[2,2,4,6,200]", "replicas=61"],
    # an adaptive order: A_k depends on the network at the enlargement, so the checkpoint carries the orders
    # (killed mid stage 4, its A_4 chosen by loss; a resume that forgot it would train on the stratified one)
    "loss_high": ["engine=reference", "schedule.epochs=[1,1,2,3,3]", "replicas=2", "schedule.order=loss_high"],
    # the mini-batch engine: Adam's moments and per-replica step counts, and the cosine rate's clock
    "minibatch": ["optim=adam_minibatch", "model.activation=relu", "schedule.epochs=[2,2,4,6,60]", "replicas=4"],
    # pruning jobs: the policy's scores, its annealing flags and each replica's ledger are the selector's state
    # (InfoBatch and Selective Backprop stopped at a budget: the last epoch cut per replica, annealing by budget;
    # SeTa's scores choose its k-means groups; a user's policy by import path, its Annealing found by the
    # selector's state_dict; InfoBatch under mini-batch Adam: the moments and the cosine rate's clock too)
    "infobatch": [
        "engine=reference", "schedule=infobatch", "schedule.epochs=null", "schedule.budget=9000", "replicas=2"
    ],
    "selective_backprop": [
        "engine=reference", "schedule=selective_backprop", "schedule.epochs=null", "schedule.budget=7000"
    ],
    "seta": ["engine=reference", "schedule=seta", "schedule.epochs=[12]", "replicas=2"],
    "user_policy": [
        "engine=reference",
        "schedule=infobatch",
        "schedule.pruning._target_=my_pruning.UniformPruning",
        "schedule.epochs=null",
        "schedule.budget=9000",
    ],
    # a user's own selector (examples/extending/my_selector.py) on the paper's stages: its scores are its state
    "user_selector": [
        "engine=reference", "schedule.pruning={_target_:my_selector.LossWeighted}", "schedule.epochs=[1,1,2,3,3]"
    ],
    "infobatch_adam": [
        "optim=adam_minibatch", "model.activation=relu", "schedule=infobatch", "schedule.epochs=[150]", "replicas=4"
    ],
}  # fmt: skip
EPOCHS = {"reference": 10, "native": 214, "loss_high": 10, "minibatch": 74, "infobatch": 19, "seta": 12}
EPOCHS.update(selective_backprop=math.ceil(7000 / (1002 / 3)) + 1, user_policy=19, infobatch_adam=150, user_selector=10)


def run(out: Path, args: list[str], wait: bool = True, **env: str) -> subprocess.Popen:
    """``python train.py COMMON args`` into ``out`` (the user plug-ins of examples/extending and the tests' own on its
    path; ``env``: variables to set for it)."""
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"} | env
    path = [str(ROOT / "examples" / "extending"), str(ROOT / "tests"), env.get("PYTHONPATH")]
    env["PYTHONPATH"] = os.pathsep.join(filter(None, path))
    p = subprocess.Popen(
        [sys.executable, "train.py", *COMMON, *args, f"hydra.run.dir={out}"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    if wait:
        p.wait(timeout=300)
        assert p.returncode == 0, p.stdout.read()
    return p


def newest_checkpoint(folder: Path) -> tuple[Path | None, int]:
    """The checkpoint a resume should take (the later of the two alternating files) and its epoch (-1: none)."""
    best: tuple[Path | None, int] = (None, -1)
    for path in (folder / "checkpoint.pt", folder / "checkpoint.alt.pt"):
        try:
            epoch = read_checkpoint(path)["epoch"]
        except Exception:  # absent (never half-written: the rename is atomic)
            continue
        if epoch > best[1]:
            best = (path, epoch)
    return best


@pytest.mark.parametrize(
    "engine",
    [
        pytest.param("reference"),
        pytest.param("native", marks=requires_native),
        pytest.param("loss_high"),
        pytest.param("minibatch"),
        pytest.param("infobatch"),
        pytest.param("selective_backprop"),
        pytest.param("seta"),
        pytest.param("user_policy"),
        pytest.param("user_selector"),
        pytest.param("infobatch_adam"),
    ],
)
def test_sigkill_then_same_command_resumes_exactly(tmp_path, engine):
    args = ENGINES[engine]
    killed = tmp_path / "killed"
    p = run(killed, args, wait=False)
    deadline = time.time() + 240
    while time.time() < deadline:  # wait until a mid-run checkpoint (past stage 3's first epoch) exists
        if newest_checkpoint(killed)[1] >= 5:
            break
        time.sleep(0.05)
    p.send_signal(signal.SIGKILL)
    p.wait()
    assert p.returncode == -signal.SIGKILL
    assert not (killed / "results.json").exists(), "the run finished before it could be killed"
    ckpt, epoch_at_kill = newest_checkpoint(killed)
    assert 5 <= epoch_at_kill < EPOCHS[engine]

    resumed = run(killed, args)
    assert f"resuming from {ckpt} at epoch {epoch_at_kill}" in resumed.stdout.read()
    straight = tmp_path / "straight"
    run(straight, args)

    a = json.loads((killed / "results.json").read_text())
    b = json.loads((straight / "results.json").read_text())
    assert numbers(a) == numbers(b)  # the curves without their wall seconds
    for key in ("presentations_done", "selection_presentations", "cost", "selector"):
        assert a[key] == b[key], key
    assert a["resumed_from_epoch"] == epoch_at_kill and b["resumed_from_epoch"] is None
    wa = torch.load(killed / "weights.pt")["params"]
    wb = torch.load(straight / "weights.pt")["params"]
    assert all(torch.equal(x, y) for x, y in zip(wa, wb))
    assert not list(killed.glob("checkpoint*.pt"))  # a finished run keeps results, not its checkpoints
