"""Large sets staged for the SGD kernel (selpres.native.staging): the same numbers as the unstaged path bit
for bit, the reference engine's within rounding, and a changed set never trained from a stale copy."""

from __future__ import annotations

import pytest
import torch

from selpres.engines.model import init_replica_params
from selpres.native import staging

from conftest import online_engine, requires_native

pytestmark = requires_native


def _set(sizes, n, seed=0):
    g = torch.Generator().manual_seed(seed)
    X = torch.rand(n, sizes[0], dtype=torch.float64, generator=g)
    Y = 0.1 + 0.8 * torch.rand(n, sizes[-1], dtype=torch.float64, generator=g)
    return X, Y, g


def _train(name, sizes, R, X, Y, orders, batch_size=1, threads=2):
    eng = online_engine(name, sizes, init_replica_params(sizes, list(range(R))), 0.15, 0.9, batch_size, threads=threads)
    losses = [eng.train_epoch(X, Y, o) for o in orders]
    return eng, losses, eng.params()


@pytest.mark.parametrize(
    "sizes, R, batch_size",
    [((6, 13, 2), 5, 1), ((18, 40, 6), 8, 1), ((9, 4, 9), 3, 1), ((6, 5, 5, 1), 12, 4)],
    ids=["6-13-2 R5", "18-40-6 R8", "9-4-9 (rows padded to 24)", "6-5-5-1 batch 4"],
)
def test_staged_set_gives_the_unstaged_numbers_bit_for_bit(monkeypatch, sizes, R, batch_size):
    X, Y, g = _set(sizes, 3000)
    orders = [torch.randint(3000, (R, 2000), generator=g) for _ in range(3)]
    monkeypatch.setattr(staging, "STAGE_BYTES", 1 << 62)  # the path before staging
    plain, plain_losses, plain_params = _train("native", sizes, R, X, Y, orders, batch_size)
    assert plain._staged is None
    monkeypatch.setattr(staging, "STAGE_BYTES", 0)  # every set staged
    staged, staged_losses, staged_params = _train("native", sizes, R, X, Y, orders, batch_size)
    assert staged._staged is not None and staged._staged.rows.shape[1] % staging.LINE_DOUBLES == 0
    assert staged._staged.rows.data_ptr() % 64 == 0  # rows start on cache lines
    assert all(torch.equal(a, b) for a, b in zip(plain_losses, staged_losses))
    assert all(torch.equal(a, b) for a, b in zip(plain_params, staged_params))
    # and the independent implementation (torch autograd, per pattern) agrees within rounding
    _, ref_losses, ref_params = _train("reference", sizes, R, X, Y, orders[:1], batch_size)
    _, one_losses, one_params = _train("native", sizes, R, X, Y, orders[:1], batch_size)
    assert (ref_losses[0] - one_losses[0]).abs().max() <= 1e-12
    assert max((a - b).abs().max().item() for a, b in zip(ref_params, one_params)) <= 1e-10


def test_a_changed_set_is_staged_again(monkeypatch):
    """In place through torch (version counter), through numpy (no counter: the sampled rows), or another
    tensor: each epoch trains on the set as it is then, as a fresh unstaged engine does."""
    sizes, R = (6, 4, 2), 4
    X, Y, g = _set(sizes, 500)
    orders = [torch.randint(500, (R, 400), generator=g) for _ in range(4)]
    sets = [(X.clone(), Y.clone())]
    X2 = X.clone()
    X2.mul_(0.5)  # epoch 1: changed in place by torch
    sets.append((X2, Y))
    X3 = X2.clone()
    X3.numpy()[0, 0] = 0.25  # epoch 2: changed through numpy, in a row the check samples (the first)
    sets.append((X3, Y))
    sets.append((torch.rand(500, 6, dtype=torch.float64, generator=g), Y))  # epoch 3: another set
    monkeypatch.setattr(staging, "STAGE_BYTES", 1 << 62)
    want = online_engine("native", sizes, init_replica_params(sizes, list(range(R))), 0.15, 0.9, 1)
    want_losses = [want.train_epoch(x, y, o) for (x, y), o in zip(sets, orders)]
    monkeypatch.setattr(staging, "STAGE_BYTES", 0)
    eng = online_engine("native", sizes, init_replica_params(sizes, list(range(R))), 0.15, 0.9, 1)
    Xlive = X.clone()
    seen = []
    for k, o in enumerate(orders):
        if k == 1:
            Xlive.mul_(0.5)
        if k == 2:
            Xlive.numpy()[0, 0] = 0.25
        x = sets[3][0] if k == 3 else Xlive
        loss = eng.train_epoch(x, Y, o)
        seen.append(eng._staged)
        assert torch.equal(loss, want_losses[k]), k
    assert len({id(s) for s in seen}) == 4  # staged afresh every time the set changed
    assert all(torch.equal(a, b) for a, b in zip(eng.params(), want.params()))
    # an unchanged set is staged once: the next epochs reuse the rows
    eng.train_epoch(sets[3][0], Y, orders[0])
    assert eng._staged is seen[-1]


def test_small_sets_are_not_staged():
    sizes = (6, 13, 2)
    X, Y, g = _set(sizes, 1002)  # Table 1's set: 64 KB, far under STAGE_BYTES
    assert (X.numel() + Y.numel()) * 8 < staging.STAGE_BYTES
    eng, _, _ = _train("native", sizes, 4, X, Y, [torch.randint(1002, (4, 100), generator=g)])
    assert eng._staged is None


def test_a_float32_set_is_staged_once_and_trains_as_its_float64_copy(monkeypatch):
    sizes, R = (6, 13, 2), 4
    X, Y, g = _set(sizes, 2000)
    X32, Y32 = X.float(), Y.float()
    orders = [torch.randint(2000, (R, 500), generator=g) for _ in range(2)]
    monkeypatch.setattr(staging, "STAGE_BYTES", 0)
    eng = online_engine("native", sizes, init_replica_params(sizes, list(range(R))), 0.15, 0.9, 1)
    first = eng.train_epoch(X32, Y32, orders[0])
    staged = eng._staged
    second = eng.train_epoch(X32, Y32, orders[1])
    assert eng._staged is staged  # not copied again
    monkeypatch.setattr(staging, "STAGE_BYTES", 1 << 62)
    want = online_engine("native", sizes, init_replica_params(sizes, list(range(R))), 0.15, 0.9, 1)
    w1, w2 = (want.train_epoch(X32.double(), Y32.double(), o) for o in orders)
    assert torch.equal(first, w1) and torch.equal(second, w2)
    assert all(torch.equal(a, b) for a, b in zip(eng.params(), want.params()))
