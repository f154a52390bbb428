"""The learning rate's clock (issue 40): ``cosine`` runs on the cost spent, ``cosine_epochs`` on the epochs (epoch e
of N starts at e / N, as SeTa's authors re-position their schedule every epoch). Both engines against a PyTorch
user's loop that sets the rate per step, what a job records, and the schedules the epochs' clock refuses."""

from __future__ import annotations

import math

import pytest
import torch

from selpres.engines.minibatch import MiniBatchEngine
from selpres.engines.model import BPN, init_replica_params, load_into
from selpres.engines.native_minibatch import NativeMiniBatchEngine
from selpres.errors import ConfigError
from selpres.run.resolve import resolve
from selpres.run.train import train

from conftest import cfg_of, numbers, requires_native

SIZES, N, B, EPOCHS = (6, 5, 2), 40, 4, 4


def _epochs(R: int):
    """A whole epoch, then pruned ones (each replica its own count of the 40): what SeTa's full-length run does."""
    g = torch.Generator().manual_seed(3)
    X, Y = torch.rand(N, 6, generator=g, dtype=torch.float64), torch.rand(N, 2, generator=g, dtype=torch.float64)
    out = [(torch.stack([torch.randperm(N, generator=g) for _ in range(R)]), None)]
    for _ in range(EPOCHS - 1):
        counts = torch.randint(10, N - 5, (R,), generator=g)
        out.append((torch.stack([torch.randperm(N, generator=g) for _ in range(R)]), counts))
    return X, Y, out


def _user_loop(params, r, X, Y, epochs, clock: str):
    """Replica r as a PyTorch user trains it: Adam, the cosine rate set before every step from the clock: presentations
    so far (``cost``), or e n + the presentations of epoch e so far (``epochs``); horizon EPOCHS n either way."""
    model = load_into(BPN(SIZES, activation="relu"), params, r)
    opt = torch.optim.Adam(model.parameters(), lr=0.01)
    spent = 0
    for e, (order, counts) in enumerate(epochs):
        if clock == "epochs":
            spent = e * N
        c = N if counts is None else int(counts[r])
        for s in range(0, c, B):
            idx = order[r, s : min(s + B, c)]
            opt.param_groups[0]["lr"] = 0.01 * 0.5 * (1 + math.cos(math.pi * min(spent / (EPOCHS * N), 1.0)))
            loss = (model(X[idx]) - Y[idx]).square().mean(-1).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            spent += len(idx)
    return [p.detach() for p in model.flat_params()]


@requires_native
@pytest.mark.parametrize("schedule, clock", [("cosine", "cost"), ("cosine_epochs", "epochs")])
def test_both_engines_follow_their_clock_on_pruned_epochs(schedule, clock):
    R = 5
    X, Y, epochs = _epochs(R)
    params = init_replica_params(SIZES, [20 + r for r in range(R)])
    engines = [
        cls(SIZES, params, "adam", {"lr": 0.01}, B, "relu", schedule, float(EPOCHS * N))
        for cls in (NativeMiniBatchEngine, MiniBatchEngine)
    ]
    for order, counts in epochs:
        for e in engines:
            e.train_epoch(X, Y, order, counts=counts)
    for r in range(R):
        want = _user_loop(params, r, X, Y, epochs, clock)
        other = _user_loop(params, r, X, Y, epochs, "cost" if clock == "epochs" else "epochs")
        for eng in engines:
            got = [p[r] for p in eng.params()]
            assert all(torch.allclose(a, b, rtol=1e-11, atol=1e-13) for a, b in zip(got, want))
            assert not all(torch.allclose(a, b, rtol=1e-6, atol=1e-9) for a, b in zip(got, other))  # the clocks differ


@requires_native
def test_on_whole_epochs_the_two_clocks_are_the_same_numbers(tmp_path):
    """Conventional training presents n every epoch: the epochs' clock is the cost's, bit for bit, on either engine
    (and the kernel runs the cost's clock as before: its rate input is unchanged)."""
    base = [
        "schedule=conventional",
        "schedule.epochs=[4]",
        "replicas=3",
        "optim=adam_minibatch",
        "model.activation=relu",
    ]
    for engine in ("native", "torch"):
        a = train(cfg_of(*base, f"engine={engine}"), tmp_path / f"cost-{engine}")
        b = train(cfg_of(*base, f"engine={engine}", "optim.lr_schedule=cosine_epochs"), tmp_path / f"ep-{engine}")
        assert a["engine"] == b["engine"]
        assert numbers(a)["replica_results"] == numbers(b)["replica_results"]


@requires_native
def test_a_pruned_job_runs_on_the_epochs_clock_and_its_numbers_differ(tmp_path):
    """A SeTa job for N epochs on both clocks: the same choices at epoch 0, then other rates (it pruned, so the clocks
    part), recorded as the config that ran."""
    from selpres.run.problem import job_engine, prepare

    base = ["schedule=seta", "schedule.epochs=[4]", "replicas=2", "optim=adam_minibatch", "model.activation=relu"]
    runs = {s: train(cfg_of(*base, f"optim.lr_schedule={s}"), tmp_path / s) for s in ("cosine", "cosine_epochs")}
    assert runs["cosine_epochs"]["config"]["optim"]["lr_schedule"] == "cosine_epochs"
    assert all(c < 4 * 1002 for c in runs["cosine_epochs"]["cost"]["per_replica"]["spent"])  # it pruned
    assert numbers(runs["cosine"])["replica_results"] != numbers(runs["cosine_epochs"])["replica_results"]
    job = resolve(cfg_of(*base, "optim.lr_schedule=cosine_epochs"))
    eng = job_engine(job, prepare(job))
    assert eng.lr_schedule == "cosine_epochs" and eng.horizon == 4 * 1002  # the horizon: N full epochs of n


@pytest.mark.parametrize(
    "overrides",
    [
        ["schedule=selective"],  # several stages
        ["schedule=seta", "schedule.epochs=null", "schedule.budget=30000"],  # a budget: its epochs not known
        ["schedule=conventional", "schedule.sizes=[500]"],  # a subset of U
    ],
)
def test_the_epochs_clock_refuses_what_it_cannot_position(overrides):
    cfg = cfg_of(*overrides, "optim=adam_minibatch", "model.activation=relu", "optim.lr_schedule=cosine_epochs")
    with pytest.raises(ConfigError) as e:
        resolve(cfg)
    assert e.value.key == "optim.lr_schedule" and "schedule.epochs=[N]" in str(e.value)


def test_a_checkpoint_keeps_the_epochs_count():
    params = init_replica_params(SIZES, [1, 2])
    X, Y, epochs = _epochs(2)
    for cls in (MiniBatchEngine, NativeMiniBatchEngine):
        try:
            e = cls(SIZES, params, "adam", {"lr": 0.01}, B, "relu", "cosine_epochs", float(EPOCHS * N))
        except Exception:  # the kernel cannot run here
            continue
        for order, counts in epochs[:2]:
            e.train_epoch(X, Y, order, counts=counts)
        again = cls(SIZES, params, "adam", {"lr": 0.01}, B, "relu", "cosine_epochs", float(EPOCHS * N))
        again.load_state_dict(e.state_dict())
        assert again.epochs == 2
        order, counts = epochs[2]
        e.train_epoch(X, Y, order, counts=counts)
        again.train_epoch(X, Y, order, counts=counts)
        assert all(torch.equal(a, b) for a, b in zip(e.params(), again.params()))
