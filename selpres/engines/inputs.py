"""What every engine's ``train_epoch``, ``predict`` and ``squared_errors`` take, checked once for all of them
(online, mini-batch and batch engines): an epoch's pattern order, the pruned epoch's counts and weights
(:mod:`selpres.presentation.pruning`), patterns to score. A bad shape or index is a ValueError/IndexError naming it.
"""

from __future__ import annotations

import numpy as np
import torch


def check_inputs(sizes, X: torch.Tensor, Y: torch.Tensor, order: torch.Tensor, R: int) -> None:
    if X.dim() != 2 or X.shape[1] != sizes[0]:
        raise ValueError(f"X must be [n, {sizes[0]}], got {tuple(X.shape)}")
    if Y.dim() != 2 or Y.shape[1] != sizes[-1] or Y.shape[0] != X.shape[0]:
        raise ValueError(f"Y must be [{X.shape[0]}, {sizes[-1]}], got {tuple(Y.shape)}")
    if order.dim() != 2 or order.shape[0] != R:
        raise ValueError(f"order must be [R={R}, m], got {tuple(order.shape)}")
    o = order.detach().cpu().numpy()  # numpy: see NativeEngine.train_epoch
    if o.dtype == np.int64:  # one pass: viewed as unsigned, a negative index is larger than any valid one
        bad = o.size and int(o.view(np.uint64).max()) >= X.shape[0]
    else:
        bad = o.size and (int(o.min()) < 0 or int(o.max()) >= X.shape[0])
    if bad:
        raise IndexError(f"order has indices outside [0, {X.shape[0]})")


def pruned_epoch_args(order: torch.Tensor, weights, counts) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """``train_epoch``'s ``weights`` (float64 [R, m]) and ``counts`` (int64 [R], clamped to [0, m]) checked;
    (None, None) for an epoch that is not pruned."""
    R, m = order.shape
    if weights is not None:
        if tuple(weights.shape) != (R, m):
            raise ValueError(f"weights must be [R={R}, m={m}] like order, got {tuple(weights.shape)}")
        weights = weights.detach().to(torch.float64).contiguous()
    if counts is not None:
        if tuple(counts.shape) != (R,):
            raise ValueError(f"counts must be [R={R}], got {tuple(counts.shape)}")
        counts = counts.detach().to(torch.int64).clamp(0, m).contiguous()
    elif weights is not None:
        counts = torch.full((R,), m, dtype=torch.int64)
    return weights, counts


def pruned_mean(total: torch.Tensor, counts: torch.Tensor) -> torch.Tensor:
    """An epoch's mean pattern loss [R] over each replica's presented patterns (NaN where none)."""
    presented = counts.to(torch.float64)
    return torch.where(presented > 0, total / presented.clamp(min=1), float("nan"))


def check_patterns(sizes, X: torch.Tensor) -> torch.Tensor:
    if X.dim() != 2 or X.shape[1] != sizes[0]:
        raise ValueError(f"X must be [N, {sizes[0]}], got {tuple(X.shape)}")
    return X.detach().to(torch.float64)


def check_scoring(sizes, X: torch.Tensor, Y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``squared_errors``' inputs as float64, or a ValueError naming the bad shape."""
    X = check_patterns(sizes, X)
    if Y.dim() != 2 or Y.shape != (X.shape[0], sizes[-1]):
        raise ValueError(
            f"Y must be [{X.shape[0]}, {sizes[-1]}] (scaled targets of X's patterns), got {tuple(Y.shape)}"
        )
    return X, Y.detach().to(torch.float64)
