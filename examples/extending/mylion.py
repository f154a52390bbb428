"""A user's own optimizer, outside selpres: Lion (Chen et al. 2023, "Symbolic Discovery of Optimization
Algorithms", NeurIPS; Algorithm 2), as a ``torch.optim.Optimizer`` subclass.

Run it by its import path, no file of selpres edited::

    PYTHONPATH=examples/extending python train.py optim._target_=mylion.Lion '~optim.momentum' optim.lr=3e-4 \\
        optim.batch_size=32 model.activation=relu

The config's ``optim`` keys other than ``_target_`` and the engines' own (``batch_size``, ``reduction``,
``lr_schedule``, ``sigmoid_prime_offset``) are this class's keyword arguments; selpres checks them against its
signature (``+optim.gamma=1`` is refused, naming it and the class; so is the default ``optim=paper`` file's
``momentum``, which ``~optim.momentum`` drops) and records ``mylion.Lion`` in results.json. The rule is
elementwise (every weight moves by its own gradient and state), so selpres may step it on all replicas'
stacked weights at once: that is R separate optimizers.

Per weight, with gradient g and momentum m (0 at the start)::

    c = beta1 m + (1 - beta1) g
    w = w (1 - lr weight_decay) - lr sign(c)
    m = beta2 m + (1 - beta2) g
"""

from __future__ import annotations

import torch


class Lion(torch.optim.Optimizer):
    def __init__(self, params, lr: float = 1e-4, beta1: float = 0.9, beta2: float = 0.99, weight_decay: float = 0.0):
        if not lr > 0:
            raise ValueError(f"Invalid learning rate: {lr}")
        for name, beta in (("beta1", beta1), ("beta2", beta2)):
            if not 0.0 <= beta < 1.0:
                raise ValueError(f"Invalid {name}: {beta}")
        super().__init__(params, dict(lr=lr, beta1=beta1, beta2=beta2, weight_decay=weight_decay))

    @torch.no_grad()
    def step(self, closure=None):
        loss = None
        if closure is not None:
            with torch.enable_grad():
                loss = closure()
        for group in self.param_groups:
            lr, b1, b2, wd = group["lr"], group["beta1"], group["beta2"], group["weight_decay"]
            for p in group["params"]:
                if p.grad is None:
                    continue
                m = self.state[p].setdefault("exp_avg", torch.zeros_like(p))
                if wd:
                    p.mul_(1 - lr * wd)
                p.add_(torch.sign(m * b1 + p.grad * (1 - b1)), alpha=-lr)
                m.mul_(b2).add_(p.grad, alpha=1 - b2)
        return loss
