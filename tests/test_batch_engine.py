"""BatchEngine against R separate runs of the idiomatic BPN + optimizer, and its resume contract."""

from __future__ import annotations

import io

import pytest
import torch
import torch.nn.functional as F

import selpres.engines.batch as batch_engine
from selpres.engines.batch import BatchEngine
from selpres.engines.model import BPN, init_replica_params, load_into
from selpres.engines.online import TorchEngine
from selpres.engines.optim import DeltaBarDelta, QuickProp
from selpres.errors import ConfigError
from selpres.run.checkpoint import dumps

SIZES = (6, 5, 2)
R, N, M, EPOCHS = 3, 40, 25, 5

# (config name, flat hparams, the same optimizer built directly from its class: the reference)
OPTIMIZERS = [
    ("sgd", {"lr": 0.5, "momentum": 0.9}, lambda p: torch.optim.SGD(p, lr=0.5, momentum=0.9)),
    (
        "quickprop",
        {"lr": 0.3, "mu": 1.75, "weight_decay": 1e-3},
        lambda p: QuickProp(p, lr=0.3, mu=1.75, weight_decay=1e-3),
    ),
    (
        "delta_bar_delta",
        {"lr": 0.3, "kappa": 0.1, "phi": 0.3, "theta": 0.7, "momentum": 0.5},
        lambda p: DeltaBarDelta(p, lr=0.3, kappa=0.1, phi=0.3, theta=0.7, momentum=0.5),
    ),
    (
        "rprop",
        {"lr": 0.05, "eta_minus": 0.5, "eta_plus": 1.2, "step_min": 1e-6, "step_max": 50.0},
        lambda p: torch.optim.Rprop(p, lr=0.05, etas=(0.5, 1.2), step_sizes=(1e-6, 50.0)),
    ),
    (
        "adam",
        {"lr": 0.02, "beta1": 0.9, "beta2": 0.999, "eps": 1e-8},
        lambda p: torch.optim.Adam(p, lr=0.02, betas=(0.9, 0.999), eps=1e-8),
    ),
]
IDS = [o[0] for o in OPTIMIZERS]


@pytest.fixture(scope="module")
def problem():
    g = torch.Generator().manual_seed(7)
    X = torch.rand(N, SIZES[0], generator=g, dtype=torch.float64)
    Y = 0.1 + 0.8 * torch.rand(N, SIZES[-1], generator=g, dtype=torch.float64)
    # each replica its own subset per epoch; the last epoch repeats patterns (a repeat counts twice)
    orders = [torch.stack([torch.randperm(N, generator=g)[:M] for _ in range(R)]) for _ in range(EPOCHS - 1)]
    orders.append(torch.randint(0, N, (R, M), generator=g))
    return X, Y, orders, init_replica_params(SIZES, [11, 12, 13])


def _reference(factory, params, X, Y, orders, offset, reduction):
    """One BPN and one optimizer per replica, autograd on the epoch's error, one step per epoch. The
    offset is written independently of offset_sigmoid: sigmoid(z) + offset * (z - z.detach())."""
    finals, losses = [], []
    for r in range(R):
        model = load_into(BPN(SIZES), params, r)
        opt = factory(list(model.parameters()))
        per_epoch = []
        for order in orders:
            x, t = X[order[r]], Y[order[r]]
            for layer in model.layers:
                z = layer(x)
                x = torch.sigmoid(z) + offset * (z - z.detach())
            mse = F.mse_loss(x, t)
            loss = mse if reduction == "mean" else 0.5 * (x - t).square().sum()
            opt.zero_grad()
            loss.backward()
            opt.step()
            per_epoch.append(mse.item())
        finals.append([p.detach().clone() for p in model.flat_params()])
        losses.append(per_epoch)
    return [torch.stack(g) for g in zip(*finals)], torch.tensor(losses, dtype=torch.float64).T


@pytest.mark.parametrize("name, hparams, factory", OPTIMIZERS, ids=IDS)
@pytest.mark.parametrize("offset, reduction", [(0.0, "sum"), (0.1, "mean")])
def test_replica_batched_equals_separate_runs(problem, name, hparams, factory, offset, reduction):
    X, Y, orders, params = problem
    eng = BatchEngine(SIZES, params, name, hparams, sigmoid_prime_offset=offset, reduction=reduction)
    losses = torch.stack([eng.train_epoch(X, Y, order) for order in orders])
    ref_params, ref_losses = _reference(factory, params, X, Y, orders, offset, reduction)
    for got, exp in zip(eng.params(), ref_params):
        torch.testing.assert_close(got, exp, rtol=0, atol=1e-12)
    torch.testing.assert_close(losses, ref_losses, rtol=0, atol=1e-12)
    assert not torch.equal(eng.params()[0], params[0])  # it did train


def test_batch_sgd_equals_torch_engine_with_the_epoch_as_batch(problem):
    """An independent engine: TorchEngine (hand-written backward) with batch_size = m is batch SGD."""
    X, Y, orders, params = problem
    ours = BatchEngine(SIZES, params, "sgd", {"lr": 0.5, "momentum": 0.9}, reduction="mean")
    theirs = TorchEngine(SIZES, params, 0.5, 0.9, M)
    for order in orders:
        torch.testing.assert_close(ours.train_epoch(X, Y, order), theirs.train_epoch(X, Y, order), rtol=0, atol=1e-14)
    for a, b in zip(ours.params(), theirs.params()):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-13)


@pytest.mark.parametrize("name, hparams, factory", OPTIMIZERS, ids=IDS)
def test_state_dict_round_trip_resumes_identically(problem, name, hparams, factory):
    X, Y, orders, params = problem
    whole = BatchEngine(SIZES, params, name, hparams, sigmoid_prime_offset=0.1)
    for order in orders:
        whole.train_epoch(X, Y, order)
    first = BatchEngine(SIZES, params, name, hparams, sigmoid_prime_offset=0.1)
    for order in orders[:3]:
        first.train_epoch(X, Y, order)
    saved = dumps(first.state_dict())  # as a checkpoint travels
    for order in orders[3:]:
        first.train_epoch(X, Y, order)  # training on must not change what was saved
    other = init_replica_params(SIZES, [99, 98, 97])
    resumed = BatchEngine(SIZES, other, name, hparams, sigmoid_prime_offset=0.1)
    resumed.load_state_dict(torch.load(io.BytesIO(saved), weights_only=True))
    for order in orders[3:]:
        resumed.train_epoch(X, Y, order)
    for a, b in zip(resumed.params(), whole.params()):
        assert torch.equal(a, b)


def test_state_of_another_optimizer_is_refused(problem):
    _, _, _, params = problem
    state = BatchEngine(SIZES, params, "adam", {"lr": 0.01}).state_dict()
    with pytest.raises(ValueError, match="'adam'.*'quickprop'"):
        BatchEngine(SIZES, params, "quickprop", {"lr": 0.1}).load_state_dict(state)


def test_predict_is_each_replicas_bpn(problem):
    X, Y, orders, params = problem
    eng = BatchEngine(SIZES, params, "rprop", {"lr": 0.05})
    eng.train_epoch(X, Y, orders[0])
    out = eng.predict(X)
    assert out.shape == (R, N, SIZES[-1])
    trained = eng.params()
    for r in range(R):
        with torch.no_grad():
            torch.testing.assert_close(out[r], load_into(BPN(SIZES), trained, r)(X), rtol=0, atol=1e-14)


def test_chunking_and_a_diverged_replica_leave_the_others_alone(problem, monkeypatch):
    """Replicas are trained in chunks to bound memory: a chunk of one replica gives the same numbers to
    rounding; a replica whose weights are NaN does not leak into its neighbours."""
    X, Y, orders, params = problem
    whole = BatchEngine(SIZES, params, "quickprop", {"lr": 0.3})
    for order in orders:
        whole.train_epoch(X, Y, order)
    broken = [t.clone() for t in params]
    broken[0][0, 0, 0] = float("nan")
    monkeypatch.setattr(batch_engine, "CHUNK", M)  # one replica per chunk
    chunked = BatchEngine(SIZES, broken, "quickprop", {"lr": 0.3})
    for order in orders:
        losses = chunked.train_epoch(X, Y, order)
    assert torch.isnan(losses[0]) and torch.isfinite(losses[1:]).all()
    for a, b in zip(chunked.params(), whole.params()):
        assert torch.isnan(a[0]).all()  # NaN reached every weight of replica 0 ...
        torch.testing.assert_close(a[1:], b[1:], rtol=0, atol=1e-14)  # ... and none of the others


def test_empty_epoch_changes_nothing(problem):
    X, Y, _, params = problem
    eng = BatchEngine(SIZES, params, "quickprop", {"lr": 0.3})
    losses = eng.train_epoch(X, Y, torch.zeros(R, 0, dtype=torch.int64))
    assert torch.isnan(losses).all()
    assert all(torch.equal(a, b) for a, b in zip(eng.params(), params))


@pytest.mark.parametrize(
    "kwargs, key",
    [
        ({"reduction": "avg"}, "optim.reduction"),
        ({"sigmoid_prime_offset": -0.1}, "optim.sigmoid_prime_offset"),
    ],
)
def test_bad_engine_options_name_their_key(problem, kwargs, key):
    _, _, _, params = problem
    with pytest.raises(ConfigError) as err:
        BatchEngine(SIZES, params, "quickprop", {"lr": 0.3}, **kwargs)
    assert err.value.key == key
