"""Fahlman's sigmoid-prime offset: a backward pass that cannot stall on the sigmoid's flat spots.

Where a unit saturates, sigma'(x) = sigma(x) (1 - sigma(x)) approaches 0 and so does every gradient
through it: the "flat spots" the paper's section 2 describes. Fahlman (CMU-CS-88-162; his program's
``ACTIVATION_PRIME``: ``SigmoidPrimeOffset + value * (1 - value)``, offset 0.1) adds a constant to
sigma' in the backward pass only. The forward pass is unchanged, so the result is no longer the exact
gradient of the error; it belongs to the backward pass, not to an optimizer, and any optimizer can use it.
"""

from __future__ import annotations

import torch

from selpres.engines.optim._base import require


class _OffsetSigmoid(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x, offset):
        y = torch.sigmoid(x)
        ctx.save_for_backward(y)
        ctx.offset = offset
        return y

    @staticmethod
    def backward(ctx, grad_out):
        (y,) = ctx.saved_tensors
        return grad_out * (y * (1 - y) + ctx.offset), None


def offset_sigmoid(x: torch.Tensor, offset: float = 0.1) -> torch.Tensor:
    """``sigmoid(x)`` whose backward uses ``sigma'(x) + offset`` (``offset = 0``: plain ``torch.sigmoid``)."""
    offset = require("sigmoid_prime_offset", offset, "an offset >= 0 added to sigma' (Fahlman: 0.1)", lambda v: v >= 0)
    if offset == 0:
        return torch.sigmoid(x)
    return _OffsetSigmoid.apply(x, offset)
