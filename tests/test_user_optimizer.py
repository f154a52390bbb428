"""A user's own optimizer from the command line, by the ecosystem's convention (Hydra's ``_target_``): torch's
NAdam, and examples/extending/mylion.py's Lion, a class selpres has never seen, on mini-batches."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
import torch

from conftest import REPO

EXTENDING = REPO / "examples" / "extending"
JOB = ["replicas=2", "schedule=conventional", "schedule.epochs=[2]", "logging.tensorboard=false", "threads=1"]


def train(tmp_path, *overrides: str):
    """``PYTHONPATH=examples/extending python train.py <overrides>`` as a user runs it."""
    path = os.pathsep.join([str(EXTENDING), os.environ.get("PYTHONPATH", "")])
    env = {**{k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}, "PYTHONPATH": path}
    out = tmp_path / "job"
    done = subprocess.run(
        [sys.executable, "train.py", *JOB, *overrides, f"hydra.run.dir={out}"],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    res = json.loads((out / "results.json").read_text()) if (out / "results.json").is_file() else None
    return done, res


LION = ["optim._target_=mylion.Lion", "optim.lr=3e-4", "optim.batch_size=32", "model.activation=relu"]


def test_lion_by_its_import_path_runs_and_is_recorded(tmp_path):
    done, res = train(tmp_path, *LION, "~optim.momentum")  # optim=paper's momentum is not Lion's: dropped by hand
    assert done.returncode == 0, done.stderr[-3000:]
    assert res["optimizer"] == "mylion.Lion" and res["engine"] == "minibatch" and res["status"] == "complete"
    assert res["config"]["optim"]["_target_"] == "mylion.Lion" and "momentum" not in res["config"]["optim"]


def test_a_key_of_another_optimizers_file_is_refused_naming_the_key_the_class_and_the_file(tmp_path):
    """``optim._target_`` over the default ``optim=paper``: paper.yaml's momentum is a key Lion does not take, so the
    job is refused, as Hydra's instantiate refuses it, saying where the key came from and how to drop it."""
    done, res = train(tmp_path, *LION)
    assert done.returncode == 2 and res is None and "Traceback" not in done.stderr
    line = done.stderr.strip().splitlines()[-1]
    assert line == (
        "error: optim.momentum=0.9 is not allowed: expected no value: mylion.Lion does not take it (its keys: lr, "
        "beta1, beta2, weight_decay); optim=paper's file sets it: drop it with '~optim.momentum', or pick a group "
        "file for this class"
    )


def test_a_value_another_optimizers_file_hands_the_class_is_said(tmp_path):
    """``optim=adam optim._target_=mylion.Lion``: adam.yaml's beta2 0.999 is a key Lion takes (its own default 0.99):
    it runs with it, but never in silence."""
    done, res = train(tmp_path, "optim=adam", "optim._target_=mylion.Lion", "~optim.eps", "optim.batch_size=32")
    assert done.returncode == 0, done.stderr[-3000:]
    assert "optim=adam's file hands mylion.Lion lr=0.001 (its default: 0.0001), beta2=0.999 (its default: 0.99)" in (
        done.stdout + done.stderr
    )
    assert res["config"]["optim"]["beta2"] == 0.999


def test_torchs_nadam_by_its_import_path(tmp_path):
    done, res = train(
        tmp_path,
        "optim._target_=torch.optim.NAdam",
        "~optim.momentum",
        "optim.lr=0.003",
        "optim.batch_size=32",
        "model.activation=relu",
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert res["optimizer"] == "torch.optim.nadam.NAdam" and res["engine"] == "minibatch"


@pytest.mark.parametrize(
    "overrides, message",
    [
        (["optim._target_=mylion.Lion", "~optim.momentum", "+optim.gamma=1"], "optim.gamma=1 is not allowed"),
        (["optim._target_=mylion.Lion", "~optim.momentum", "optim.lr=-1"], "Invalid learning rate"),
        (["optim._target_=mylion.Nope"], "it has no 'Nope'"),
        (["optim._target_=torch.optim.LBFGS"], "expected an elementwise rule"),
        (["optim._target_=mylion.Lion", "optim.batch_size=0", "optim.momentum=null"], None),  # batch mode runs
        (["+optim.name=adam"], "optim._target_=adam"),  # the old spelling names the new one
    ],
)
def test_bad_choices_are_one_line_naming_the_key(tmp_path, overrides, message):
    done, res = train(tmp_path, *overrides)
    if message is None:
        assert done.returncode == 0, done.stderr[-3000:]
        assert res["engine"] == "batch" and res["optimizer"] == "mylion.Lion"
        return
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr, done.stderr[-2000:]
    assert res is None


def test_lion_steps_as_published():
    """Two steps by hand: c = b1 m + (1-b1) g, w -= lr (sign(c) + wd w), m = b2 m + (1-b2) g."""
    sys.path.insert(0, str(EXTENDING))
    try:
        from mylion import Lion
    finally:
        sys.path.remove(str(EXTENDING))
    w = torch.tensor([1.0, -2.0, 0.5], dtype=torch.float64)
    opt = Lion([w], lr=0.1, beta1=0.9, beta2=0.99, weight_decay=0.5)
    w.grad = torch.tensor([0.3, -0.2, 0.0], dtype=torch.float64)
    opt.step()  # m = 0: c = 0.1 g, sign(c) = sign(g); w = w * 0.95 - 0.1 sign(g)
    assert w.tolist() == pytest.approx([0.95 - 0.1, -1.9 + 0.1, 0.475])
    # m = 0.01 g1 = [0.003, -0.002, 0]; g2 = [-0.01, -0.01, 0.2]: c = 0.9 m + 0.1 g2 = [0.0017, -0.0028, 0.02]
    w.grad = torch.tensor([-0.01, -0.01, 0.2], dtype=torch.float64)
    opt.step()
    assert w.tolist() == pytest.approx([0.8075 - 0.1, -1.71 + 0.1, 0.45125 - 0.1])  # w = 0.95 [0.85, -1.8, 0.475] - ...
