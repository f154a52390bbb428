"""The paper's back-propagation network: fully connected layers of sigmoid units.

A topology is written as in the paper, ``6-13-2``: input width, hidden widths, output width.
Every layer (hidden *and* output) uses the logistic sigmoid, as in Rumelhart et al.'s BPN, so
targets must be scaled into (0, 1) (see :mod:`selpres.data.paper`). ``model.activation`` (issue 22)
offers today's hidden units too: ``tanh``, ``relu``, ``silu``; with those the output layer is linear (the
usual regression head: a sigmoid output would squash what a ReLU net is chosen for), with ``sigmoid`` it
stays the paper's sigmoid, so the default network is unchanged.

Weights of R independent replicas are carried as a flat list ``[W1, b1, W2, b2, ...]`` of tensors with
a leading replica dimension (``W_l``: ``[R, out, in]``, ``b_l``: ``[R, out]``). That list is the common
currency between engines, evaluation, checkpoints and tests.
"""

from __future__ import annotations

import functools
import math
import re

import torch
from torch import nn

from selpres.engines.activations import activation as units

_TOPOLOGY_RE = re.compile(r"^\d+(-\d+)+$")


class TopologyError(ValueError):
    """A topology string that cannot describe the network; ``allowed`` says what would."""

    def __init__(self, topology: str, allowed: str):
        self.topology, self.allowed = topology, allowed
        super().__init__(f"topology={topology!r} is not allowed: expected {allowed}")

    def __reduce__(self):
        return type(self), (self.topology, self.allowed)


def parse_topology(topology: str) -> tuple[int, ...]:
    """``"6-13-2"`` -> ``(6, 13, 2)`` (whether it fits a task: ``selpres.run.checks.check_topology``)."""
    text = str(topology).strip()
    if not _TOPOLOGY_RE.match(text):
        raise TopologyError(topology, "layer widths joined by '-', e.g. '6-13-2' or '6-8-8-2'")
    sizes = tuple(int(s) for s in text.split("-"))
    if len(sizes) < 2:
        raise TopologyError(topology, "at least an input and an output layer")
    if any(s <= 0 for s in sizes):
        raise TopologyError(topology, "positive layer widths (no layer of width 0)")
    return sizes


class BPN(nn.Module):
    """Multilayer perceptron (sigmoid: the paper's BPN): the idiomatic ``nn.Module`` that defines correct
    results. ``activation``: the hidden units (:data:`selpres.engines.activations.ACTIVATIONS`: a built-in name
    or a class by its import path)."""

    def __init__(self, sizes: tuple[int, ...] | str, dtype: torch.dtype = torch.float64, activation: str = "sigmoid"):
        super().__init__()
        self.act = units(activation)  # ConfigError naming model.activation
        self.sizes = parse_topology(sizes) if isinstance(sizes, str) else tuple(sizes)
        self.activation = activation
        self.layers = nn.ModuleList(nn.Linear(i, o, dtype=dtype) for i, o in zip(self.sizes[:-1], self.sizes[1:]))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if getattr(self.act, "SIGMOID_OUTPUT", False):  # the paper's net, exactly as before
            for layer in self.layers:
                x = torch.sigmoid(layer(x))
            return x
        f = self.act.forward
        for layer in self.layers[:-1]:
            x = f(layer(x))
        return self.layers[-1](x)

    def flat_params(self) -> list[torch.Tensor]:
        """``[W1, b1, W2, b2, ...]`` in the replica list's order (without the replica dim)."""
        out = []
        for layer in self.layers:
            out += [layer.weight, layer.bias]
        return out


def init_replica_params(
    sizes: tuple[int, ...], seeds: list[int], dtype: torch.dtype = torch.float64
) -> list[torch.Tensor]:
    """Initial weights for one replica per seed, drawn from ``nn.Linear``'s default distribution.

    ``nn.Linear`` draws weight and bias from U(-1/sqrt(fan_in), 1/sqrt(fan_in)); here each replica
    draws from its own ``torch.Generator`` so that replica r of a many-seed job is bit-identical to a
    single run with seed ``seeds[r]``, whatever R is.
    """
    layers = list(zip(sizes[:-1], sizes[1:]))  # (fan_in, fan_out)
    shapes = [shape for fan_in, fan_out in layers for shape in ((fan_out, fan_in), (fan_out,))]
    # nn.Linear: kaiming_uniform_(a=sqrt(5)) and its bias both draw from U(-1/sqrt(fan_in), +)
    bounds = [1.0 / fan_in**0.5 for fan_in, _ in layers for _ in "wb"]
    counts = [math.prod(shape) for shape in shapes]
    # one draw of all a replica's parameters: the generator fills them in the order the per-tensor draws
    # (weight, then bias, layer by layer) would, so the numbers are the same (tests/test_model.py), and
    # 1000 replicas take 5 ms instead of 38
    u = torch.stack(
        [torch.rand(sum(counts), generator=torch.Generator().manual_seed(int(s)), dtype=dtype) for s in seeds]
    )
    return [
        (part.reshape(len(seeds), *shape) * 2 - 1) * bound
        for shape, part, bound in zip(shapes, u.split(counts, dim=1), bounds)
    ]


def load_into(model: BPN, params: list[torch.Tensor], replica: int) -> BPN:
    """Copy replica ``replica`` of a replica list into ``model`` (in place)."""
    with torch.no_grad():
        for p, src in zip(model.flat_params(), params):
            p.copy_(src[replica])
    return model


# Replicas are evaluated in blocks whose widest layer holds about this many activations (8 MB of float64),
# so a block's intermediate results stay in cache between the product and the sigmoid; but in at most
# _MAX_BLOCKS blocks: each block is a few parallel regions of torch's thread pool, and where the cores
# are oversubscribed each region may wait a scheduler time slice (100 blocks at 2 threads then cost
# more than the single pass they replace).
_BLOCK_ACTIVATIONS = 1 << 20
_MAX_BLOCKS = 8


def _forward_block(params: list[torch.Tensor], x: torch.Tensor, activation: str = "sigmoid") -> torch.Tensor:
    """Every layer is one batched product over the replicas (``x`` broadcast, not copied), then an
    in-place sigmoid: [R, N, in] -> [R, N, out] with no transposes (other activations: linear output)."""
    h = x.expand(params[0].shape[0], *x.shape)
    act = units(activation)
    if getattr(act, "SIGMOID_OUTPUT", False):
        for w, b in zip(params[0::2], params[1::2]):
            h = torch.baddbmm(b.unsqueeze(1), h, w.transpose(1, 2)).sigmoid_()
        return h
    f, last = act.forward, len(params) // 2 - 1
    for k, (w, b) in enumerate(zip(params[0::2], params[1::2])):
        h = torch.baddbmm(b.unsqueeze(1), h, w.transpose(1, 2))
        h = h if k == last else f(h)
    return h


def forward_replicas(params: list[torch.Tensor], x: torch.Tensor, activation: str = "sigmoid") -> torch.Tensor:
    """Outputs of all R replicas on the same inputs: ``x`` [N, in] -> [R, N, out].

    Evaluation of many replicas (R = 1000 on 2,000 patterns) is bound by memory traffic, not arithmetic:
    one pass over all replicas (with a transposing copy) streams ~200 MB of hidden activations through
    memory several times. Blocks of replicas without that copy, sized to the cache where that takes
    few blocks, do the same operations per replica without that traffic: the results equal :class:`BPN`
    to ~1e-16 (tests/test_model.py).
    """
    R, N = params[0].shape[0], x.shape[0]
    widest = max(w.shape[1] for w in params[0::2])
    block = max(1, _BLOCK_ACTIVATIONS // max(1, N * widest), -(-R // _MAX_BLOCKS))
    fwd = _forward_block if activation == "sigmoid" else functools.partial(_forward_block, activation=activation)
    if block >= R:
        return fwd(params, x)
    out = torch.empty(R, N, params[-1].shape[-1], dtype=params[-1].dtype)
    for r0 in range(0, R, block):
        out[r0 : r0 + block] = fwd([p[r0 : r0 + block] for p in params], x)
    return out


def squared_errors_of(outputs: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """Per replica and output, the sum over patterns of (output - target)^2: [R, N, out] and [N, out] ->
    [R, out] float64. What an engine's ``squared_errors`` returns, from outputs already computed (RMS
    errors in any unit follow from these sums; see :meth:`selpres.engines.online.NativeEngine.squared_errors`)."""
    return (outputs - targets.to(outputs)).square().sum(-2)


def replicas_finite(params: list[torch.Tensor]) -> torch.Tensor:
    """[R] bool: whether every weight and bias of replica r is finite (a diverged replica's are not)."""
    return torch.stack([torch.isfinite(p).flatten(1).all(1) for p in params]).all(0)
