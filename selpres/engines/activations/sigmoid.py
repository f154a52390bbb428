"""The logistic sigmoid, the paper's unit (Rumelhart et al.'s BPN): every layer, the output's included."""

from __future__ import annotations

import torch


class Sigmoid:
    SIGMOID_OUTPUT = True  # the paper's net: targets scaled into (0, 1)

    @staticmethod
    def forward(z: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(z)

    @staticmethod
    def prime(z: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        return a * (1 - a)


ACTIVATION = Sigmoid
