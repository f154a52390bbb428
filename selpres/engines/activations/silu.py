"""SiLU hidden units (Elfwing et al. 2018; "swish"), z sigmoid(z), a linear output layer."""

from __future__ import annotations

import torch


class SiLU:
    @staticmethod
    def forward(z: torch.Tensor) -> torch.Tensor:
        # z * sigmoid(z) as the mini-batch engine has trained since issue 22 (torch.nn.functional.silu differs
        # from it by an ulp, and was what prediction used: now both use this one form)
        return z * torch.sigmoid(z)

    @staticmethod
    def prime(z: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        s = torch.sigmoid(z)
        return s * (1 + z * (1 - s))


ACTIVATION = SiLU
