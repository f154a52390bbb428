"""Leaky ReLU units (the modern study's remedy for dead units, issue 40) on both mini-batch engines, against
``torch.nn.LeakyReLU`` in a plain ``nn.Sequential`` trained by ``torch.optim.Adam`` (autograd), and a job on the
native kernel."""

from __future__ import annotations

import math

import pytest
import torch
from torch import nn

from selpres.engines.activations import activation
from selpres.engines.minibatch import MiniBatchEngine
from selpres.engines.model import init_replica_params
from selpres.engines.native_minibatch import NativeMiniBatchEngine
from selpres.run.train import train

from conftest import cfg_of, requires_native

SIZES, N, B = (6, 7, 2), 48, 8


def test_forward_and_derivative_are_torchs():
    z = torch.linspace(-3, 3, 61, dtype=torch.float64).requires_grad_(True)
    units = activation("leaky_relu")
    want = nn.LeakyReLU(0.01)(z)
    (grad,) = torch.autograd.grad(want.sum(), z)
    assert torch.equal(units.forward(z.detach()), want.detach())
    assert torch.equal(units.prime(z.detach(), want.detach()), grad)


def _sequential(params, r):
    net = nn.Sequential(nn.Linear(6, 7), nn.LeakyReLU(0.01), nn.Linear(7, 2)).to(torch.float64)
    with torch.no_grad():
        for p, src in zip([net[0].weight, net[0].bias, net[2].weight, net[2].bias], params):
            p.copy_(src[r])
    return net


@pytest.mark.parametrize("engine", [pytest.param(NativeMiniBatchEngine, marks=requires_native), MiniBatchEngine])
def test_an_engine_trains_leaky_units_as_torch_does(engine):
    g = torch.Generator().manual_seed(7)
    X, Y = torch.rand(N, 6, generator=g, dtype=torch.float64) - 0.5, torch.rand(N, 2, generator=g, dtype=torch.float64)
    R = 3
    params = init_replica_params(SIZES, [30 + r for r in range(R)])
    # a bias pushed far below zero: on a ReLU that unit would be dead; here it still learns (slowly)
    params[1][:, 0] = -5.0
    eng = engine(SIZES, params, "adam", {"lr": 0.02}, B, "leaky_relu", "cosine", 3.0 * N)
    orders = [torch.stack([torch.randperm(N, generator=g) for _ in range(R)]) for _ in range(3)]
    for order in orders:
        eng.train_epoch(X, Y, order)
    for r in range(R):
        net = _sequential(params, r)
        opt = torch.optim.Adam(net.parameters(), lr=0.02)
        spent = 0
        for order in orders:
            for s in range(0, N, B):
                idx = order[r, s : s + B]
                opt.param_groups[0]["lr"] = 0.02 * 0.5 * (1 + math.cos(math.pi * min(spent / (3.0 * N), 1.0)))
                loss = (net(X[idx]) - Y[idx]).square().mean(-1).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
                spent += len(idx)
        want = [net[0].weight, net[0].bias, net[2].weight, net[2].bias]
        for got, w in zip(eng.params(), want):
            torch.testing.assert_close(got[r], w.detach(), rtol=1e-11, atol=1e-13)
        assert float((eng.params()[0][r, 0] - params[0][r, 0]).abs().max()) > 0  # the pushed-down unit moved


@requires_native
def test_a_job_runs_leaky_units_on_the_native_kernel(tmp_path):
    cfg = cfg_of("schedule=conventional", "schedule.epochs=[2]", "replicas=2", "optim=adam_minibatch",
                 "model.activation=leaky_relu", "engine=native")  # fmt: skip
    res = train(cfg, tmp_path)
    assert res["engine"] == "minibatch-native"
    assert res["activation"].endswith("leaky_relu.LeakyReLU")
    assert res["stalls"]["replicas"][0]["dead"] == 0  # a leaky unit always passes some gradient
