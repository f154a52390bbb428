"""The network's forward pass for many replicas against one nn.Module per replica."""

from __future__ import annotations

import pytest
import torch

from selpres.engines import model
from selpres.engines.model import BPN, forward_replicas, init_replica_params, load_into


def _per_replica(sizes, params, X):
    with torch.no_grad():
        return torch.stack([load_into(BPN(sizes), params, r)(X) for r in range(params[0].shape[0])])


@pytest.mark.parametrize("sizes", [(6, 13, 2), (6, 8, 8, 2), (3, 1, 1)], ids=lambda s: "-".join(map(str, s)))
@pytest.mark.parametrize(
    "blocks",
    [(1, 7, 7), (3, 7, 3), (1 << 20, 7, 1), (1, 2, 2)],
    ids=["blocks-of-1", "3-3-1", "one-block", "cap-2-blocks"],
)
def test_forward_replicas_matches_one_module_per_replica(monkeypatch, sizes, blocks):
    """R = 7 in blocks of 1, of 3 (3 + 3 + 1), in one, and in blocks of 4 when at most 2 are allowed."""
    R, N = 7, 11
    per_block, max_blocks, calls = blocks
    monkeypatch.setattr(model, "_BLOCK_ACTIVATIONS", per_block * N * max(sizes[1:]))
    monkeypatch.setattr(model, "_MAX_BLOCKS", max_blocks)
    seen = []
    real = model._forward_block
    monkeypatch.setattr(model, "_forward_block", lambda p, x: seen.append(p[0].shape[0]) or real(p, x))
    params = init_replica_params(sizes, list(range(R)))
    X = torch.rand(N, sizes[0], generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    got = forward_replicas(params, X)
    assert len(seen) == calls and sum(seen) == R
    assert got.shape == (R, N, sizes[-1]) and got.dtype == torch.float64
    assert (got - _per_replica(sizes, params, X)).abs().max().item() <= 1e-15


def test_forward_replicas_by_hand():
    """A 1-1-1 net worked out by hand: sigmoid(w2 * sigmoid(w1 * x + b1) + b2)."""
    params = [torch.tensor([[[2.0]]]), torch.tensor([[-1.0]]), torch.tensor([[[3.0]]]), torch.tensor([[0.5]])]
    x = torch.tensor([[0.5]], dtype=torch.float64)
    h = 1 / (1 + torch.exp(torch.tensor(-(2.0 * 0.5 - 1.0), dtype=torch.float64)))  # sigmoid(0) = 0.5
    y = 1 / (1 + torch.exp(-(3.0 * h + 0.5)))  # sigmoid(2.0)
    assert h.item() == 0.5
    got = forward_replicas([p.to(torch.float64) for p in params], x)
    assert got.shape == (1, 1, 1) and abs(got.item() - y.item()) <= 1e-16
    assert abs(got.item() - 0.8807970779778823) <= 1e-15  # 1 / (1 + e^-2)


def test_forward_replicas_keeps_autograd():
    """torch.func gradients through forward_replicas (the reference tests take them) still work."""
    sizes = (6, 5, 2)
    params = [p[0] for p in init_replica_params(sizes, [3])]
    X = torch.rand(4, 6, dtype=torch.float64)

    def loss(p):
        return forward_replicas([q.unsqueeze(0) for q in p], X).square().sum()

    grads = torch.func.grad(loss)(params)
    net = BPN(sizes)
    with torch.no_grad():
        for dst, src in zip(net.flat_params(), params):
            dst.copy_(src)
    net(X).square().sum().backward()
    for g, p in zip(grads, net.flat_params()):
        assert (g - p.grad).abs().max().item() <= 1e-14


def test_squared_errors_of_by_hand():
    """Two replicas, three patterns, two outputs, numbers summed by hand."""
    out = torch.tensor(
        [[[0.5, 0.2], [0.1, 0.9], [0.3, 0.3]], [[0.0, 0.0], [1.0, 1.0], [0.5, 0.5]]], dtype=torch.float64
    )
    Y = torch.tensor([[0.25, 0.2], [0.1, 0.4], [0.8, 0.3]], dtype=torch.float64)
    # replica 0: 0.25^2 + 0 + 0.5^2 = 0.3125, 0 + 0.5^2 + 0 = 0.25
    # replica 1: 0.25^2 + 0.9^2 + 0.3^2 = 0.9625, 0.2^2 + 0.6^2 + 0.2^2 = 0.44
    got = model.squared_errors_of(out, Y)
    expected = torch.tensor([[0.3125, 0.25], [0.9625, 0.44]], dtype=torch.float64)
    assert got.shape == (2, 2) and (got - expected).abs().max().item() <= 1e-15


def test_replicas_finite_flags_nan_and_inf_in_any_tensor():
    params = init_replica_params((6, 4, 2), list(range(4)))
    assert model.replicas_finite(params).tolist() == [True] * 4
    params[0][1, 3, 5] = float("nan")
    params[3][2, 1] = float("-inf")
    params[1][0, 0] = 1e308  # huge is still finite
    assert model.replicas_finite(params).tolist() == [True, False, False, True]


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
@pytest.mark.parametrize("sizes", [(6, 13, 2), (6, 5, 5, 2), (18, 40, 6), (3, 1, 1)])
def test_initial_weights_are_nn_linears_draws_tensor_by_tensor(sizes, dtype):
    """Each replica's weights are what drawing weight then bias, layer by layer, from its own generator
    gives, scaled to U(-1/sqrt(fan_in), 1/sqrt(fan_in)) as nn.Linear's default init (the definition)."""
    seeds = [0, 1, 7, 123456]
    got = init_replica_params(sizes, seeds, dtype)
    for r, seed in enumerate(seeds):
        gen = torch.Generator().manual_seed(seed)
        for k, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            bound = 1.0 / fan_in**0.5
            w = (torch.rand(fan_out, fan_in, generator=gen, dtype=dtype) * 2 - 1) * bound
            b = (torch.rand(fan_out, generator=gen, dtype=dtype) * 2 - 1) * bound
            assert torch.equal(got[2 * k][r], w) and torch.equal(got[2 * k + 1][r], b)
            assert got[2 * k].dtype == dtype and float(got[2 * k].abs().max()) <= bound
