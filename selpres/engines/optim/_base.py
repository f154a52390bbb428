"""Shared pieces of the optimizers: parameter checks and the per-weight step loop."""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch.optim import Optimizer

from selpres.errors import ConfigError


def require(key: str, value, allowed: str, ok: Callable[[float], bool]) -> float:
    """``value`` as a float when it is a finite real number with ``ok(value)``; else :class:`ConfigError`.

    ``key`` is the constructor's parameter name (``mu``, ``kappa``, ...); the training config prefixes
    it with its group (``optim.mu``) through :func:`selpres.engines.optim.make_optimizer`.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(key, value, f"a number: {allowed}")
    v = float(value)
    if not math.isfinite(v) or not ok(v):
        raise ConfigError(key, value, allowed)
    return v


class PerWeightOptimizer(Optimizer):
    """A rule that moves every weight from its own gradient and state: ``step()`` calls
    ``update(p, grad, state, group)`` for each parameter with a gradient (the torch conventions)."""

    def update(self, p: torch.Tensor, grad: torch.Tensor, state: dict, group: dict) -> None:
        raise NotImplementedError

    @torch.no_grad()
    def step(self, closure=None):
        loss = None
        if closure is not None:
            with torch.enable_grad():
                loss = closure()
        for group in self.param_groups:
            for p in group["params"]:
                if p.grad is not None:
                    self.update(p, p.grad, self.state[p], group)
        return loss
