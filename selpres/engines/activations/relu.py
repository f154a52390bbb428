"""ReLU hidden units (Nair & Hinton 2010), a linear output layer."""

from __future__ import annotations

import torch


class ReLU:
    @staticmethod
    def forward(z: torch.Tensor) -> torch.Tensor:
        return torch.relu(z)

    @staticmethod
    def prime(z: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        return (z > 0).to(z.dtype)


ACTIVATION = ReLU
