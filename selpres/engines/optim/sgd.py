"""Gradient descent with momentum (Rumelhart, Hinton & Williams 1986), the paper's rule: ``torch.optim.SGD``.

``buf = momentum * buf + g; w -= lr * buf`` (no dampening, no Nesterov). Online (``optim.batch_size`` 1, the
paper, Note 1 of Table 1: lr 0.15, momentum 0.9) it runs on the online engines (the native kernel among
them); on mini-batches and in batch mode (one step per epoch) as torch's own class.
"""

from __future__ import annotations

import torch

from selpres.engines.optim._base import BATCH, MINIBATCH, ONLINE, rate, unit


class SGD(torch.optim.SGD):
    """``torch.optim.SGD`` from the config's flat keys (see :meth:`hparams`)."""

    MODES = (ONLINE, MINIBATCH, BATCH)

    def __init__(self, params, **hparams):
        super().__init__(params, **self.hparams(**hparams))

    @staticmethod
    def hparams(lr: float = 0.15, momentum: float = 0.0) -> dict:
        """The keyword arguments with their defaults, checked (ConfigError naming the key); config validation
        calls this alone, without building an optimizer."""
        return dict(lr=rate(lr), momentum=unit("momentum", momentum, "a momentum in [0, 1)"))


OPTIMIZER = SGD
