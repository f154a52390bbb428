"""tanh hidden units, a linear output layer."""

from __future__ import annotations

import torch


class Tanh:
    @staticmethod
    def forward(z: torch.Tensor) -> torch.Tensor:
        return torch.tanh(z)

    @staticmethod
    def prime(z: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        return 1 - a * a


ACTIVATION = Tanh
