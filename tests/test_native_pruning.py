"""Pruned epochs (per-replica counts, weighted patterns, per-pattern losses) on the online engines: the native
kernel and the torch engine against the reference engine, identities that need no engine to check them, and which
engine a pruning job gets."""

from __future__ import annotations

import pytest
import torch

from selpres.engines.minibatch import MiniBatchEngine
from selpres.engines.model import init_replica_params

from conftest import cfg_of, online_engine, requires_native

LR, MOM, TOL = 0.15, 0.9, 1e-12  # TOL: the engine-agreement tolerance of tests/test_engine.py
NATIVE = pytest.param("native", marks=requires_native)
SIZES = (6, 5, 3)  # three outputs: the loss's 2 / nout is not 1 (at nout = 2 a ½Σe² loss would pass too)
R, N = 6, 40  # six replicas: one interleaved pair of lane groups, two padding lanes
COUNTS = torch.tensor([N, 0, 7, N - 1, 13, 1])  # uneven: all, none, a few, all but one, one


def _data(seed=0):
    g = torch.Generator().manual_seed(seed)
    X = torch.rand(N, SIZES[0], generator=g, dtype=torch.float64)
    return X, 0.1 + 0.8 * torch.rand(N, SIZES[-1], generator=g, dtype=torch.float64)


def _epochs(k=3, seed=5):
    """k pruned epochs: each replica's own shuffle, the uneven counts, weights in [0.5, 2]."""
    g = torch.Generator().manual_seed(seed)
    return [
        (
            torch.stack([torch.randperm(N, generator=g) for _ in range(R)]),
            0.5 + 1.5 * torch.rand(R, N, generator=g, dtype=torch.float64),
        )
        for _ in range(k)
    ]


def _engine(name, B, lr=LR, mom=MOM):
    params = init_replica_params(SIZES, list(range(10, 10 + R)))
    if name == "minibatch":  # sgd, sigmoid, constant rate, mean reduction: the online engines' update
        return MiniBatchEngine(SIZES, params, "sgd", {"lr": lr, "momentum": mom}, B, reduction="mean")
    return online_engine(name, SIZES, params, lr, mom, B, threads=1)


def _run(name, B, weighted=True, **kw):
    eng = _engine(name, B, **kw)
    X, Y = _data()
    seen = []
    for order, w in _epochs():
        loss = eng.train_epoch(X, Y, order, weights=w if weighted else None, counts=COUNTS)
        seen.append((loss, eng.last_losses.clone()))
    return eng, seen


def _close(a, b):
    """Equal where both are numbers (within TOL), NaN at the same places."""
    assert a.shape == b.shape and torch.equal(a.isnan(), b.isnan())
    assert (a - b).nan_to_num(0.0).abs().max().item() <= TOL


_references: dict = {}


@pytest.mark.parametrize("B", [1, 3])
@pytest.mark.parametrize("name", ["torch", NATIVE, "minibatch"])
def test_pruned_epochs_match_the_reference_engine(name, B):
    """Weights, momenta, the epochs' losses and every presented pattern's loss, as the reference computes them
    (one nn.Module and torch.optim.SGD per replica, the weighted mse by autograd)."""
    if B not in _references:
        _references[B] = _run("reference", B)
    ref, ref_seen = _references[B]
    eng, seen = _run(name, B)
    for got, want in zip(eng.params(), ref.params()):
        _close(got, want)
    if name != "minibatch":  # (its momenta live in its optimizer; its weights above follow from them)
        for got, want in zip(eng.state_dict()["momentum"], ref.state_dict()["momentum"]):
            _close(got, want)
    for (loss, per), (ref_loss, ref_per) in zip(seen, ref_seen):
        _close(loss, ref_loss)
        _close(per, ref_per)
        assert per[1].isnan().all() and per[4, :13].isfinite().all() and per[4, 13:].isnan().all()
    start = init_replica_params(SIZES, list(range(10, 10 + R)))
    assert max((p - q).abs().max().item() for p, q in zip(eng.params(), start)) > 1e-3  # it trained


@pytest.mark.parametrize("B", [1, 3])
@pytest.mark.parametrize("name", ["reference", "torch", NATIVE])
def test_a_weight_of_two_is_twice_the_learning_rate(name, B):
    """The update is linear in the gradient: weight 2 on every pattern at lr moves the weights as weight 1 at 2 lr,
    with momenta twice as large (buf' = mom buf + 2g = 2 (mom buf/2 + g)), from zero momenta."""
    X, Y = _data()
    doubled, halved = _engine(name, B), _engine(name, B, lr=2 * LR)
    for order, _ in _epochs():
        doubled.train_epoch(X, Y, order, weights=torch.full((R, N), 2.0, dtype=torch.float64), counts=COUNTS)
        halved.train_epoch(X, Y, order, counts=COUNTS)
    a, b = doubled.state_dict(), halved.state_dict()
    for got, want in zip(a["params"], b["params"]):
        _close(got, want)
    for got, want in zip(a["momentum"], b["momentum"]):
        _close(got, 2 * want)
    assert max((p - q).abs().max().item() for p, q in zip(a["params"], _engine(name, B).params())) > 1e-3


@pytest.mark.parametrize("name", ["reference", "torch", NATIVE])
def test_a_replica_with_count_zero_keeps_its_weights_and_momenta(name):
    X, Y = _data()
    eng = _engine(name, 1)
    (order, w), *_ = _epochs(1)
    eng.train_epoch(X, Y, order)  # a plain epoch first: momenta not zero
    before = eng.state_dict()
    loss = eng.train_epoch(X, Y, order, weights=w, counts=COUNTS)
    after = eng.state_dict()
    for key in ("params", "momentum"):
        for p, q in zip(before[key], after[key]):
            assert torch.equal(p[1], q[1])  # replica 1 presented nothing: bit for bit as it was
            assert not torch.equal(p[0], q[0])
    assert loss[1].isnan() and eng.last_losses[1].isnan().all() and loss[0].isfinite()


@requires_native
@pytest.mark.parametrize("B", [1, 3])
def test_a_full_unweighted_pruned_epoch_is_the_plain_epoch_bit_for_bit(B):
    """counts = m and no weights through the kernel's pruned path: the numbers of the usual epoch exactly."""
    X, Y = _data()
    plain, pruned = _engine("native", B), _engine("native", B)
    for order, _ in _epochs():
        want = plain.train_epoch(X, Y, order)
        got = pruned.train_epoch(X, Y, order, counts=torch.full((R,), N))
        assert torch.equal(got, want)
        assert pruned.last_losses.isfinite().all()
    a, b = plain.state_dict(), pruned.state_dict()
    assert all(torch.equal(p, q) for p, q in zip(a["params"] + a["momentum"], b["params"] + b["momentum"]))


@requires_native
def test_pruned_epochs_do_not_depend_on_threads(monkeypatch):
    """Two threads (one lane group each) against one (the two groups interleaved): bit for bit, since the counts,
    weights and losses are indexed by the replica, not by the thread's chunk."""
    from selpres.native import library

    monkeypatch.setattr(library, "MIN_THREAD_WORK", 1)  # every call this small on the pool
    X, Y = _data()
    states = []
    for threads in (1, 2):
        eng = online_engine("native", SIZES, init_replica_params(SIZES, list(range(10, 10 + R))), LR, MOM, 1, threads)
        for order, w in _epochs():
            loss = eng.train_epoch(X, Y, order, weights=w, counts=COUNTS)
        st = eng.state_dict()
        states.append([*st["params"], *st["momentum"], eng.last_losses, loss])
    assert all(torch.equal(a.view(torch.int64), b.view(torch.int64)) for a, b in zip(*states))  # bits, NaN too
    assert eng._k.threads_for(10, 2) == 2  # (the pool was used)


def test_bad_counts_and_weights_are_rejected():
    eng = _engine("torch", 1)
    X, Y = _data()
    order = torch.zeros(R, 4, dtype=torch.int64)
    with pytest.raises(ValueError, match="weights must be"):
        eng.train_epoch(X, Y, order, weights=torch.ones(R, 5, dtype=torch.float64))
    with pytest.raises(ValueError, match="counts must be"):
        eng.train_epoch(X, Y, order, counts=torch.ones(R + 1, dtype=torch.int64))


# ---------------------------------------------------------------- which engine a pruning job gets
@requires_native
@pytest.mark.parametrize("schedule", ["infobatch", "selective_backprop", "seta"])
def test_a_paper_regime_pruning_job_runs_on_the_native_kernel_and_agrees_with_the_reference(schedule):
    """Sigmoid units, online SGD at a constant rate: the native kernel (recorded, no fallback), stopped at its
    budget, with the reference engine's numbers (the same patterns chosen, the same updates)."""
    from selpres.run.train import train

    runs = {}
    for engine in ("native", "reference"):
        cfg = cfg_of(
            f"schedule={schedule}", "schedule.epochs=null", "schedule.budget=3000", "replicas=2", f"engine={engine}"
        )
        runs[engine] = train(cfg)
    res = runs["native"]
    assert res["engine"] == "native" and res["engine_fallback"] is None
    for cost in res["cost"]["per_replica"]["spent"]:
        assert 3000 - (1 + 1 / 3) < cost <= 3000 + 1e-9
    ref = runs["reference"]
    assert ref["engine"] == "reference"
    assert res["cost"]["per_replica"]["trained"] == ref["cost"]["per_replica"]["trained"]
    for k, v in res["summary"].items():
        assert v["mean"] == pytest.approx(ref["summary"][k]["mean"], rel=1e-9, abs=1e-12), k
