"""Hidden units of your own, living outside the package (issue 25), named by their import path:

    PYTHONPATH=examples/extending python train.py model.activation=scaled_tanh.ScaledTanh

LeCun's scaled tanh (LeCun, Bottou, Orr & Müller 1998, "Efficient BackProp", section 4.4):
f(z) = 1.7159 tanh(2z/3), chosen so that f(±1) = ±1 and the effective gain is near 1 where inputs are scaled
to unit variance. An activation is a class with two static methods: ``forward(z)``, the units' output, and
``prime(z, a)``, df/dz from the pre-activation z and the output a = f(z) (the mini-batch engine's hand-written
backward; ``tests/test_user_activation.py`` checks it against autograd). Any unit other than ``sigmoid`` has a
linear output layer and runs on the mini-batch engine (the native kernel runs sigmoid units only). results.json's
``activation`` records ``scaled_tanh.ScaledTanh``.
"""

from __future__ import annotations

import torch

A, S = 1.7159, 2.0 / 3.0  # amplitude and slope: f(z) = A tanh(S z)


class ScaledTanh:
    @staticmethod
    def forward(z: torch.Tensor) -> torch.Tensor:
        return A * torch.tanh(S * z)

    @staticmethod
    def prime(z: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        # d/dz A tanh(S z) = A S (1 - tanh²(S z)), and tanh(S z) = a / A
        return S * (A - a * a / A)
