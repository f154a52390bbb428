"""AdamW (Loshchilov & Hutter, "Decoupled weight decay regularization", ICLR 2019): ``torch.optim.AdamW``.

Adam's rule with the weight decay decoupled from the gradient: ``w *= 1 - lr * weight_decay`` first.
"""

from __future__ import annotations

import torch

from selpres.engines.optim._base import BATCH, MINIBATCH
from selpres.engines.optim.adam import adam_hparams


class AdamW(torch.optim.AdamW):
    """``torch.optim.AdamW`` from the config's flat keys (see :meth:`hparams`)."""

    MODES = (MINIBATCH, BATCH)

    def __init__(self, params, **hparams):
        super().__init__(params, **self.hparams(**hparams))

    @staticmethod
    def hparams(
        lr: float = 1e-3, beta1: float = 0.9, beta2: float = 0.999, eps: float = 1e-8, weight_decay=0.01
    ) -> dict:
        """The keyword arguments with their defaults (torch's weight decay 0.01), checked."""
        return adam_hparams(lr, beta1, beta2, eps, weight_decay)


OPTIMIZER = AdamW
