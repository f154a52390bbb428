"""The exported two-link data as tensors, and the network, for the examples (``selpres-export --out twolink``
writes ``twolink.npz``: the paper's 1002 exemplars and 10,000 held-out patterns)."""

from __future__ import annotations

import numpy as np
import torch
from torch.utils.data import TensorDataset


def load(path: str):
    """(raw exemplar inputs for the sampler's strata, the training set standardised, the held-out set, its
    un-scaling to Nm)."""
    z = np.load(path)
    X, Y = torch.from_numpy(z["exemplar_X"]), torch.from_numpy(z["exemplar_Y"])
    mx, sx = X.mean(0), X.std(0).clamp(min=1e-12)
    my, sy = Y.mean(0), Y.std(0)
    scale = lambda A: ((A - mx) / sx).float()
    train = TensorDataset(scale(X), ((Y - my) / sy).float())
    heldout = (scale(torch.from_numpy(z["heldout_X"])), torch.from_numpy(z["heldout_Y"]))
    return X, train, heldout, (my, sy)


def mlp() -> torch.nn.Module:
    """The issue's user network: ReLU 6-64-64-2."""
    return torch.nn.Sequential(
        torch.nn.Linear(6, 64), torch.nn.ReLU(), torch.nn.Linear(64, 64), torch.nn.ReLU(), torch.nn.Linear(64, 2)
    )


@torch.no_grad()
def heldout_rms_nm(model: torch.nn.Module, heldout, unscale) -> float:
    (X, Y), (my, sy) = heldout, unscale
    return float((model(X).double() * sy + my - Y).square().mean().sqrt())
