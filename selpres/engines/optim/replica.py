"""Mini-batch SGD, Adam and AdamW over the stacked parameters of R replicas, each replica stepped on its own.

``torch.optim.Adam`` over a stacked ``[R, ...]`` tensor steps every replica at once with one step count.
Under data pruning (:mod:`selpres.presentation.pruning`) replicas keep different numbers of patterns, so in
a mini-batch some replicas have nothing left to present and must not step (Adam's moments would still move
the weights on a zero gradient), and each has its own learning rate (its own place on the cosine
schedule). These optimizers take, at every ``step``, a per-replica learning rate ``lr`` [R] and a mask
``active`` [R] (None: all): an inactive replica's weights, moments and step count stay as they were. On the
active ones they apply the published rules as torch implements them (tested against one ``torch.optim.SGD``
/ ``Adam`` / ``AdamW`` per replica, ``tests/test_minibatch.py``):

* ``sgd``: ``g += wd * p; buf = momentum * buf + g; p -= lr * buf`` (no dampening, no Nesterov);
* ``adam`` (Kingma & Ba 2015; L2 weight decay added to the gradient) and ``adamw`` (Loshchilov & Hutter
  2019; decoupled: ``p *= 1 - lr * wd`` first): ``m = b1 m + (1-b1) g``, ``v = b2 v + (1-b2) g²``,
  ``p -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)`` with t the replica's own step count.

The engine keeps all of a replica's weights in one row of a flat [R, P] tensor, so a step is a dozen
tensor operations whatever the depth (each op costs ~10 us of dispatch at these sizes).
"""

from __future__ import annotations

import torch

RULES = ("sgd", "adam", "adamw")


def _col(x: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """[R] -> [R, 1, ...] broadcastable against a stacked parameter ``like``."""
    return x.reshape(-1, *([1] * (like.dim() - 1)))


class ReplicaOptimizer(torch.optim.Optimizer):
    """``rule`` in :data:`RULES` over stacked replica parameters; ``step(lr=[R], active=[R] bool or None)``."""

    def __init__(self, params, rule: str, momentum=0.0, beta1=0.9, beta2=0.999, eps=1e-8, weight_decay=0.0):
        if rule not in RULES:
            raise ValueError(f"rule {rule!r}: one of {RULES}")
        defaults = dict(momentum=momentum, beta1=beta1, beta2=beta2, eps=eps, weight_decay=weight_decay)
        super().__init__(params, defaults)
        self.rule = rule

    @torch.no_grad()
    def step(self, lr: torch.Tensor, active: torch.Tensor | None = None):  # noqa: D102 (see the class)
        for group in self.param_groups:
            for p in group["params"]:
                if p.grad is not None:
                    self._update(p, group, lr, active)

    def _update(self, p, group, lr, active):
        st, g, wd = self.state[p], p.grad, group["weight_decay"]
        a = _col(lr.to(p.dtype), p)
        mask = None if active is None else _col(active, p)
        if self.rule == "sgd":
            if wd:
                g = g + wd * p
            buf = st.get("momentum_buffer")
            if buf is None:
                buf = st["momentum_buffer"] = torch.zeros_like(p)
            new_buf = buf * group["momentum"] + g
            new_p = p - a * new_buf
            if mask is not None:
                new_buf, new_p = torch.where(mask, new_buf, buf), torch.where(mask, new_p, p)
            buf.copy_(new_buf)
            p.copy_(new_p)
            return
        if "step" not in st:
            st["step"] = torch.zeros(p.shape[0], dtype=torch.float64)
            st["exp_avg"] = torch.zeros_like(p)
            st["exp_avg_sq"] = torch.zeros_like(p)
        st["step"] += 1.0 if active is None else active.to(torch.float64)
        t = _col(st["step"].clamp(min=1), p)
        b1, b2 = group["beta1"], group["beta2"]
        if self.rule == "adam" and wd:
            g = g + wd * p
        m = st["exp_avg"] * b1 + g * (1 - b1)
        v = st["exp_avg_sq"] * b2 + g * g * (1 - b2)
        denom = (v.sqrt() / (1 - torch.pow(b2, t)).sqrt()).add_(group["eps"])
        base = p * (1 - a * wd) if self.rule == "adamw" else p
        new_p = base - (a / (1 - torch.pow(b1, t))) * m / denom
        if mask is not None:
            m, v, new_p = (
                torch.where(mask, x, old) for x, old in ((m, st["exp_avg"]), (v, st["exp_avg_sq"]), (new_p, p))
            )
        st["exp_avg"].copy_(m)
        st["exp_avg_sq"].copy_(v)
        p.copy_(new_p)
