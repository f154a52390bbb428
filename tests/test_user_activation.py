"""A user's own hidden units from the command line, by import path: examples/extending/scaled_tanh.py's LeCun tanh,
a class selpres has never seen. The job runs it on the mini-batch engine and records its path, and its weights are
those of a plain autograd network with the same units, trained by torch.optim.SGD on the same data."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
import torch

from conftest import REPO, compose

EXTENDING = REPO / "examples" / "extending"
UNITS = "scaled_tanh.ScaledTanh"
# whole-set mini-batches (batch_size >= n = 1002): each epoch is one step on the mean loss of all patterns, whatever
# order the sampler presents them in, so the hand-built run below needs no order; mean: the mse of torch's mse_loss
JOB = [
    f"model.activation={UNITS}",
    "optim.batch_size=2000",
    "optim.reduction=mean",
    "schedule=conventional",
    "schedule.epochs=[3]",
    "topology=6-4-2",
    "replicas=2",
    "data.heldout=300",
    "eval.heldout_curve=300",
]


@pytest.fixture
def extending(monkeypatch):
    monkeypatch.syspath_prepend(str(EXTENDING))


def test_the_derivative_is_autograds(extending):
    from selpres.engines.activations import activation

    act = activation(UNITS)
    z = torch.linspace(-5, 5, 101, dtype=torch.float64).add(0.017).requires_grad_(True)
    a = act.forward(z)
    (want,) = torch.autograd.grad(a.sum(), z)
    torch.testing.assert_close(act.prime(z.detach(), a.detach()), want, rtol=0, atol=1e-14)
    torch.testing.assert_close(act.forward(torch.tensor([1.0, -1.0], dtype=torch.float64)).abs(),
                               torch.ones(2, dtype=torch.float64), rtol=0, atol=2e-4)  # fmt: skip  # f(±1) ≈ ±1


def by_hand() -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """The job's nets trained without selpres's engines: its initial weights and scaled exemplar set (from
    ``prepare``), then per replica an autograd net of 1.7159 tanh(2z/3) units and a linear output, three full-batch
    steps of torch.optim.SGD (lr 0.15, momentum 0.9) on mse_loss. Returns (trained, initial) weights."""
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    prob = prepare(resolve(compose(*JOB)))
    X, Y = prob.X.to(torch.float64), prob.Y.to(torch.float64)
    out = [torch.empty_like(p) for p in prob.init_params]
    for r in range(2):
        W0, b0, W1, b1 = (p[r].clone().requires_grad_(True) for p in prob.init_params)
        opt = torch.optim.SGD([W0, b0, W1, b1], lr=0.15, momentum=0.9)
        for _ in range(3):
            h = 1.7159 * torch.tanh(2.0 / 3.0 * (X @ W0.T + b0))
            loss = torch.nn.functional.mse_loss(h @ W1.T + b1, Y)
            opt.zero_grad()
            loss.backward()
            opt.step()
        for t, p in zip(out, (W0, b0, W1, b1)):
            t[r] = p.detach()
    return out, prob.init_params


def test_a_users_units_run_from_the_command_line_as_autograd_trains_them(extending, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    env["PYTHONPATH"] = os.pathsep.join([str(EXTENDING), env.get("PYTHONPATH", "")])
    out = tmp_path / "job"
    done = subprocess.run(
        [sys.executable, "train.py", *JOB, "logging.tensorboard=false", "threads=1", f"hydra.run.dir={out}"],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    res = json.loads((out / "results.json").read_text())
    assert res["status"] == "complete" and res["activation"] == UNITS and res["engine"] == "minibatch"
    assert res["config"]["model"]["activation"] == UNITS
    trained = torch.load(out / "weights.pt", weights_only=True)
    assert trained["activation"] == UNITS
    want, init = by_hand()
    for got, w, w0 in zip(trained["params"], want, init):
        torch.testing.assert_close(got, w, rtol=0, atol=1e-12)
        assert (got - w0).abs().max() > 1e-3  # it trained


def test_a_unit_class_without_the_two_methods_is_one_line(extending, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    env["PYTHONPATH"] = os.pathsep.join([str(EXTENDING), env.get("PYTHONPATH", "")])
    done = subprocess.run(
        [sys.executable, "train.py", "model.activation=scaled_tanh.torch", f"hydra.run.dir={tmp_path / 'bad'}"],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    assert "error: model.activation='scaled_tanh.torch' is not allowed: expected a class with static" in done.stderr
    assert not (tmp_path / "bad").exists()
