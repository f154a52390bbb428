"""QuickProp (Fahlman 1988), a batch-mode optimizer: a per-weight secant (quadratic) step.

Sources. S. E. Fahlman, *An empirical study of learning speed in back-propagation networks*,
CMU-CS-88-162, Sept. 1988 (also "Faster-learning variations on back-propagation: an empirical study",
Proc. 1988 Connectionist Models Summer School). The update below follows Fahlman's own program
"Quickprop 1, September 1988" (Common Lisp, translated to C by T. Regier; its ``UPDATE_WEIGHTS`` and
``CLEAR_SLOPES``), which is the report's algorithm in code; the defaults mu = 1.75, decay 1e-4 and the
sigmoid-prime offset 0.1 are that program's and the report's. Restatements checked: D. R. Tveter's
*Backprop* documentation (dontveter.com/probp/prodoc/Q.html) and the JETNET 3.0 manual (Lund, 1995).

With ``S(t) = dE/dw + weight_decay * w`` (the slope, weight decay folded in as in ``CLEAR_SLOPES``),
``dw(t-1)`` the previous step and ``shrink = mu / (1 + mu)``, each weight moves by ``dw(t)``:

* ``dw(t-1) == 0`` (the first step, or a weight whose last step was exactly zero): plain gradient
  descent, ``dw(t) = -lr * S(t)``.
* otherwise the sum of two terms:

  - the gradient-descent term ``-lr * S(t)``, added only while the slope still points the way the last
    step went (``S(t) < 0`` after a positive step, ``S(t) > 0`` after a negative one) -- Fahlman's sign
    rule: once the minimum has been crossed, the quadratic term alone is used;
  - the quadratic term ``S(t) / (S(t-1) - S(t)) * dw(t-1)`` (the secant to the parabola's minimum), or
    ``mu * dw(t-1)`` when that would be larger than ``mu`` times the last step, infinite, or uphill:
    Fahlman tests this as ``S(t) < shrink * S(t-1)`` after a positive step (``>`` after a negative one).

Every nonzero step of this rule goes downhill on its own slope (sign(dw(t)) = -sign(S(t))), so after a
positive step S(t-1) < 0 and ``S(t) == S(t-1)`` falls in the ``mu`` branch: the secant's division by
zero cannot arise from the rule's own steps. It can from a state set from outside (a loaded or edited
checkpoint), where Fahlman's program would divide by zero; here the quadratic term is then 0, so the
weight pauses one epoch and restarts with plain gradient descent (tested).

Batch mode: ``step()`` is called once per epoch on the gradient of the epoch's error (Fahlman sums
the slopes over all training patterns before ``UPDATE_WEIGHTS``); whether that error is a sum or a
mean is the engine's choice (:class:`selpres.engines.batch.BatchEngine`, ``reduction``); ``lr`` and
``weight_decay`` are on that scale. Not included: Fahlman's "split epsilon" (lr divided by the unit's
fan-in) and his atanh error function, options of his program rather than of the update rule; the
sigmoid-prime offset is a change of the backward pass, :func:`selpres.engines.optim._offset.offset_sigmoid`.
"""

from __future__ import annotations

import torch

from selpres.engines.optim._base import BATCH, PerWeightOptimizer, require


class QuickProp(PerWeightOptimizer):
    """Fahlman's QuickProp; call ``step()`` once per epoch with the epoch's gradient in ``.grad``.

    ``lr`` is Fahlman's epsilon, ``mu`` the maximum growth factor, ``weight_decay`` the decay term
    folded into the slope. State per weight: ``prev_step`` (dw(t-1)) and ``prev_slope`` (S(t-1)).
    """

    MODES = (BATCH,)  # a batch method: one step per epoch on the epoch's gradient

    def __init__(self, params, **hparams):
        super().__init__(params, self.hparams(**hparams))

    @staticmethod
    def hparams(lr: float = 0.55, mu: float = 1.75, weight_decay: float = 1e-4) -> dict:
        """The hyperparameters with their defaults, each checked (ConfigError naming it); config validation
        calls this alone, without building an optimizer."""
        return dict(
            lr=require("lr", lr, "a gradient-descent rate epsilon > 0 (Fahlman's program: 0.55)", lambda v: v > 0),
            mu=require("mu", mu, "a maximum growth factor mu > 0 (Fahlman: 1.75)", lambda v: v > 0),
            weight_decay=require("weight_decay", weight_decay, "a weight decay >= 0 (Fahlman: 1e-4)", lambda v: v >= 0),
        )

    def update(self, p, grad, state, group):
        if not state:
            state["prev_step"] = torch.zeros_like(p)
            state["prev_slope"] = torch.zeros_like(p)
        mu, decay = group["mu"], group["weight_decay"]
        slope = grad.add(p, alpha=decay) if decay else grad.clone()
        step = _quickprop_step(slope, state["prev_slope"], state["prev_step"], group["lr"], mu, mu / (1.0 + mu))
        p.add_(step)
        state["prev_step"] = step
        state["prev_slope"] = slope


def _quickprop_step(s, s_prev, dw, lr, mu, shrink):
    """The step dw(t) of every element (see the module docstring for the rule)."""
    pos, neg = dw > 0, dw < 0
    moved = pos | neg
    with_gradient = ~moved | (pos & (s < 0)) | (neg & (s > 0))
    at_max = (pos & (s < shrink * s_prev)) | (neg & (s > shrink * s_prev))
    denom = s_prev - s
    secant = torch.where(denom != 0, s / torch.where(denom != 0, denom, 1.0) * dw, 0.0)
    jump = torch.where(at_max, mu * dw, secant)
    return torch.where(with_gradient, -lr * s, 0.0) + torch.where(moved, jump, 0.0)


OPTIMIZER = QuickProp
