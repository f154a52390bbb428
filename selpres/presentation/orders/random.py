"""``random``: plain random growth, the literature's strongest simple baseline (Wu, Dyer & Neyshabur, ICLR 2021)."""

from __future__ import annotations

import torch

from selpres.presentation.orders._order import Order


class Random(Order):
    def orders(self, X: torch.Tensor, gens: list[torch.Generator]) -> list[torch.Tensor]:
        return [torch.randperm(X.shape[0], generator=g) for g in gens]


ORDER = Random
