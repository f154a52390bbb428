"""Adam (Kingma & Ba 2015, ICLR): ``torch.optim.Adam``, L2 weight decay added to the gradient.

``m = b1 m + (1-b1) g``, ``v = b2 v + (1-b2) g²``, ``w -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)``
as torch implements it. In batch mode (``optim.batch_size`` 0) one step per epoch; on mini-batches the
mini-batch engine steps it on the replicas' stacked weights (an elementwise rule: per replica).
"""

from __future__ import annotations

import torch

from selpres.engines.optim._base import BATCH, MINIBATCH, nonneg, rate, require, unit


def adam_hparams(lr, beta1, beta2, eps, weight_decay) -> dict:
    """Adam's and AdamW's keys checked, as torch's keyword arguments."""
    return dict(
        lr=rate(lr, "a step size > 0 (Kingma & Ba: 0.001)"),
        betas=(
            unit("beta1", beta1, "a decay rate in [0, 1) (0.9)"),
            unit("beta2", beta2, "a decay rate in [0, 1) (0.999)"),
        ),
        eps=require("eps", eps, "a denominator offset > 0 (1e-8)", lambda v: v > 0),
        weight_decay=nonneg("weight_decay", weight_decay, "a weight decay >= 0"),
    )


class Adam(torch.optim.Adam):
    """``torch.optim.Adam`` from the config's flat keys (see :meth:`hparams`)."""

    MODES = (MINIBATCH, BATCH)

    def __init__(self, params, **hparams):
        super().__init__(params, **self.hparams(**hparams))

    @staticmethod
    def hparams(
        lr: float = 1e-3, beta1: float = 0.9, beta2: float = 0.999, eps: float = 1e-8, weight_decay=0.0
    ) -> dict:
        """The keyword arguments with their defaults, checked; config validation calls this alone."""
        return adam_hparams(lr, beta1, beta2, eps, weight_decay)


OPTIMIZER = Adam
