"""Leaky ReLU hidden units (Maas, Hannun & Ng 2013), slope 0.01 below zero (``torch.nn.LeakyReLU``'s default), a
linear output layer: a unit is never dead, some gradient reaches it on every input (the modern study's remedy for
its stalled ReLU nets, issue 40). The native mini-batch kernel runs it too (``ACT=4``, the same slope)."""

from __future__ import annotations

import torch

SLOPE = 0.01  # the kernel's (selpres/native/kernels/minibatch.c, ACT == 4)


class LeakyReLU:
    @staticmethod
    def forward(z: torch.Tensor) -> torch.Tensor:
        return torch.where(z > 0, z, SLOPE * z)

    @staticmethod
    def prime(z: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        return torch.where(z > 0, torch.ones_like(z), torch.full_like(z, SLOPE))  # (scalars would be float32)


ACTIVATION = LeakyReLU
