"""The mini-batch engine against the idiomatic loop: one BPN + one torch.optim optimizer per replica, autograd."""

from __future__ import annotations

import math

import pytest
import torch

from selpres.engines.minibatch import MiniBatchEngine, lr_factor
from selpres.engines.model import BPN, init_replica_params, load_into

SIZES = (6, 5, 4, 2)


def _reference(params, r, rule, hp, activation):
    model = load_into(BPN(SIZES, activation=activation), params, r)
    lr = hp["lr"]
    if rule == "sgd":
        opt = torch.optim.SGD(model.parameters(), lr=lr, momentum=hp["momentum"])
    elif rule == "adam":
        opt = torch.optim.Adam(model.parameters(), lr=lr, weight_decay=hp["weight_decay"])
    else:
        opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=hp["weight_decay"])
    return model, opt


@pytest.mark.parametrize("activation", ["sigmoid", "tanh", "relu", "silu"])
@pytest.mark.parametrize("rule", ["sgd", "adam", "adamw"])
def test_engine_equals_autograd_with_torch_optim_per_replica(activation, rule):
    torch.manual_seed(0)
    R, n, m, B = 3, 40, 11, 4
    X, Y = torch.rand(n, 6, dtype=torch.float64), torch.rand(n, 2, dtype=torch.float64)
    params = init_replica_params(SIZES, [1, 2, 3])
    hp = {"lr": 0.05, "momentum": 0.9} if rule == "sgd" else {"lr": 0.01, "weight_decay": 0.01}
    horizon = 2 * m
    eng = MiniBatchEngine(SIZES, params, rule, dict(hp), B, activation, "cosine", horizon)
    counts = torch.tensor([11, 7, 4])  # replicas present different numbers of patterns (pruning)
    g = torch.Generator().manual_seed(5)
    orders = [torch.randint(0, n, (R, m), generator=g) for _ in range(2)]
    weights = [1 + torch.rand(R, m, generator=g, dtype=torch.float64) for _ in range(2)]
    for order, w in zip(orders, weights):
        eng.train_epoch(X, Y, order, weights=w, counts=counts)
    for r in range(R):
        model, opt = _reference(params, r, rule, hp, activation)
        spent = 0
        for order, w in zip(orders, weights):
            for s in range(0, int(counts[r]), B):
                idx = order[r, s : min(s + B, int(counts[r]))]
                for group in opt.param_groups:
                    group["lr"] = hp["lr"] * 0.5 * (1 + math.cos(math.pi * min(spent / horizon, 1.0)))
                per = (model(X[idx]) - Y[idx]).square().mean(-1)
                loss = (w[r, s : s + len(idx)] * per).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
                spent += len(idx)
        for got, want in zip(eng.params(), model.flat_params()):
            torch.testing.assert_close(got[r], want.detach(), rtol=0, atol=1e-12)
    assert eng.spent.tolist() == [2.0 * c for c in counts.tolist()]


def test_predict_matches_bpn_and_the_default_net_is_unchanged():
    params = init_replica_params(SIZES, [4, 5])
    X = torch.rand(9, 6, dtype=torch.float64)
    for act in ("sigmoid", "relu"):
        eng = MiniBatchEngine(SIZES, params, "adam", {"lr": 1e-3}, 2, act)
        want = load_into(BPN(SIZES, activation=act), params, 1)(X)
        torch.testing.assert_close(eng.predict(X)[1], want.detach(), rtol=0, atol=1e-14)
    sig = load_into(BPN(SIZES), params, 0)
    h = X
    for layer in sig.layers:  # the paper's net: a sigmoid after every layer, the output's included
        h = torch.sigmoid(layer(h))
    assert torch.equal(sig(X), h)


def test_cosine_reaches_zero_at_the_runs_own_budget():
    f = lr_factor("cosine", torch.tensor([0.0, 50.0, 100.0, 150.0], dtype=torch.float64), 100.0)
    assert f.tolist() == pytest.approx([1.0, 0.5, 0.0, 0.0], abs=1e-15)
    assert lr_factor("constant", torch.zeros(2, dtype=torch.float64), 1.0).tolist() == [1.0, 1.0]


MINIBATCH = ("minibatch-native", "minibatch")  # the native kernel where it builds, else the torch engine (said why)


@pytest.mark.parametrize(
    "overrides, engine",
    [
        (["optim=sgd"], ("native", "torch")),  # sigmoid, constant rate: the online engines (native if built)
        (["optim=sgd", "model.activation=tanh"], MINIBATCH),
        (["optim=adamw"], MINIBATCH),
        (["optim=adam", "optim.batch_size=32"], MINIBATCH),
        (["optim=adam"], ("batch",)),  # configs/optim/adam.yaml stays batch mode
    ],
)
def test_which_engine_runs_and_the_recorded_reason(overrides, engine):
    from selpres.run.problem import job_engine, prepare
    from selpres.run.resolve import resolve

    from conftest import cfg_of

    cfg = cfg_of(*overrides, "replicas=2")
    job = resolve(cfg)
    eng = job_engine(job, prepare(job))
    assert eng.name in engine
    if eng.name == "minibatch":  # engine=fast fell back from the native kernel: it says why (no compiler here ...)
        assert eng.fallback_reason  # the kernel's own reason, whole
    elif eng.name != "torch":  # (torch: the online engines' own fallback, said as such)
        assert eng.fallback_reason is None
