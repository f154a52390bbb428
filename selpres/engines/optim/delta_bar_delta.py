"""Delta-Bar-Delta (Jacobs 1988), a batch-mode optimizer: one adaptive learning rate per weight.

Source. R. A. Jacobs, *Increased rates of convergence through learning rate adaptation*, Neural
Networks 1 (1988) 295-307. Restatements checked: D. R. Tveter's *Backprop* documentation
(dontveter.com/probp/prodoc/D.htm: "a[i] = (1 - t) * slope[i] + t * a[i-1]", additive increase kappa,
multiplicative decay) and G. Orr's course notes (Willamette CS-449, "should be used with batch only").
The paper under study (section 2) lists Jacobs' four heuristics and reports that the rule is "very
sensitive to small variations in the values of its parameters".

With ``delta(t) = dE/dw`` and ``delta_bar`` its exponential average, every weight has its own rate
``eps`` (initially ``lr``), and per step (one per epoch):

    eps   += kappa          if delta_bar(t-1) * delta(t) > 0   (the slope keeps its sign: speed up)
    eps   *= 1 - phi        if delta_bar(t-1) * delta(t) < 0   (the sign flipped: a minimum was jumped)
    delta_bar(t) = (1 - theta) * delta(t) + theta * delta_bar(t-1)          (delta_bar(0) = 0)
    dw(t) = -eps * delta(t) + momentum * dw(t-1)

The rate is updated before it is used (Jacobs' w(t+1) = w(t) - eps(t+1) delta(t)); at the first step
delta_bar = 0, so no rate changes. Momentum (Jacobs' "optional momentum", default 0) is Rumelhart et
al.'s form ``dw(t) = -eps delta(t) + alpha dw(t-1)`` with the per-weight rate; the stored sources did
not show Jacobs' own momentum equation, so this form is the standard one, not a quotation.

Batch mode, as Jacobs used it: ``step()`` once per epoch on the gradient of the epoch's error (its sum
or mean: the engine's ``reduction``); ``lr`` and ``kappa`` are on that gradient's scale.
"""

from __future__ import annotations

import torch

from selpres.engines.optim._base import BATCH, PerWeightOptimizer, require


class DeltaBarDelta(PerWeightOptimizer):
    """Jacobs' delta-bar-delta rule; call ``step()`` once per epoch with the epoch's gradient in ``.grad``.

    State per weight: ``eps`` (its learning rate), ``delta_bar`` and ``prev_step`` (for momentum).
    Defaults: the example settings of Tveter's documentation (initial rate 0.1, kappa 0.25, phi 0.5,
    theta 0.7), for summed errors of small problems; ``configs/optim/delta_bar_delta.yaml`` holds the
    values for this project's problem.
    """

    MODES = (BATCH,)  # a batch method: one step per epoch on the epoch's gradient

    def __init__(self, params, **hparams):
        super().__init__(params, self.hparams(**hparams))

    @staticmethod
    def hparams(
        lr: float = 0.1, kappa: float = 0.25, phi: float = 0.5, theta: float = 0.7, momentum: float = 0.0
    ) -> dict:
        """The hyperparameters with their defaults, each checked (ConfigError naming it); config validation
        calls this alone, without building an optimizer."""
        return dict(
            lr=require("lr", lr, "an initial learning rate > 0", lambda v: v > 0),
            kappa=require("kappa", kappa, "an additive rate increase kappa >= 0", lambda v: v >= 0),
            phi=require("phi", phi, "a multiplicative rate decrease phi in [0, 1)", lambda v: 0 <= v < 1),
            theta=require("theta", theta, "an averaging factor theta in [0, 1)", lambda v: 0 <= v < 1),
            momentum=require("momentum", momentum, "a momentum in [0, 1)", lambda v: 0 <= v < 1),
        )

    def update(self, p, grad, state, group):
        if not state:
            state["eps"] = torch.full_like(p, group["lr"])
            state["delta_bar"] = torch.zeros_like(p)
            state["prev_step"] = torch.zeros_like(p)
        eps, bar = state["eps"], state["delta_bar"]
        agreement = bar * grad
        eps.add_((agreement > 0).to(eps.dtype), alpha=group["kappa"])
        eps.sub_(eps * (agreement < 0), alpha=group["phi"])  # eps *= 1 - phi where the sign flipped
        bar.mul_(group["theta"]).add_(grad, alpha=1.0 - group["theta"])
        step = -eps * grad
        if group["momentum"]:
            step.add_(state["prev_step"], alpha=group["momentum"])
        p.add_(step)
        state["prev_step"] = step


OPTIMIZER = DeltaBarDelta
