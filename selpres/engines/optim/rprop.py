"""Rprop (Riedmiller & Braun 1993, ICNN, 586-591): ``torch.optim.Rprop``, a batch method.

Only the gradient's sign is used: each weight's update value grows by ``eta_plus`` while the sign holds and
shrinks by ``eta_minus`` when it flips, within ``[step_min, step_max]``. torch's Rprop does not backtrack the
weight after a sign change (it skips the step).
"""

from __future__ import annotations

import torch

from selpres.engines.optim._base import BATCH, rate, require


class Rprop(torch.optim.Rprop):
    """``torch.optim.Rprop`` from the config's flat keys (see :meth:`hparams`); one step per epoch."""

    MODES = (BATCH,)

    def __init__(self, params, **hparams):
        super().__init__(params, **self.hparams(**hparams))

    @staticmethod
    def hparams(lr=0.1, eta_minus=0.5, eta_plus=1.2, step_min=1e-6, step_max=50.0) -> dict:
        """The keyword arguments with their defaults (Riedmiller & Braun's), checked, as torch's arguments."""
        step_min = require("step_min", step_min, "a smallest update value >= 0 (1e-6)", lambda v: v >= 0)
        return dict(
            lr=rate(lr, "an initial update value > 0 (Riedmiller & Braun: 0.1)"),
            etas=(
                require("eta_minus", eta_minus, "a decrease factor in (0, 1) (0.5)", lambda v: 0 < v < 1),
                require("eta_plus", eta_plus, "an increase factor > 1 (1.2)", lambda v: v > 1),
            ),
            step_sizes=(
                step_min,
                require(
                    "step_max",
                    step_max,
                    f"a largest update value >= step_min = {step_min:g} (50)",
                    lambda v: v >= step_min,
                ),
            ),
        )


OPTIMIZER = Rprop
