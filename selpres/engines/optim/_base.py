"""Shared pieces of the optimizers: parameter checks, the modes a rule runs in, and the per-weight step loop."""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch.optim import Optimizer

from selpres.errors import ConfigError

# How a rule may be run (a class's ``MODES``): ``online`` = the online engines' rule (one pattern a step, the
# native kernel; SGD with momentum only), ``minibatch`` = stepped on every mini-batch (``optim.batch_size`` >= 1,
# selpres.engines.minibatch), ``batch`` = once per epoch on the epoch's gradient (``optim.batch_size`` = 0,
# selpres.engines.batch). A class without ``MODES`` (a user's own, torch's) runs in mini-batch and batch mode.
ONLINE, MINIBATCH, BATCH = "online", "minibatch", "batch"
DEFAULT_MODES = (MINIBATCH, BATCH)


def require(key: str, value, allowed: str, ok: Callable[[float], bool]) -> float:
    """``value`` as a float when it is a finite real number with ``ok(value)``; else :class:`ConfigError`.

    ``key`` is the constructor's parameter name (``mu``, ``kappa``, ...); the training config prefixes
    it with its group (``optim.mu``) through :func:`selpres.engines.optim.check_hparams`.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(key, value, f"a number: {allowed}")
    v = float(value)
    if not math.isfinite(v) or not ok(v):
        raise ConfigError(key, value, allowed)
    return v


def rate(value, allowed: str = "a learning rate > 0") -> float:
    """``lr``, checked."""
    return require("lr", value, allowed, lambda v: v > 0)


def unit(key: str, value, allowed: str) -> float:
    """A value in [0, 1): a momentum, a decay rate."""
    return require(key, value, allowed, lambda v: 0 <= v < 1)


def nonneg(key: str, value, allowed: str) -> float:
    return require(key, value, allowed, lambda v: v >= 0)


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
