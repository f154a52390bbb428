"""The exported two-link data as tensors, and the network, for the examples (``selpres-export --out twolink``
writes ``twolink.npz``: the paper's 1002 exemplars and 10,000 held-out patterns)."""

from __future__ import annotations

import gc

import numpy as np
import torch
import torch.distributed as dist
import torch.distributed.nn  # noqa: F401  imported before any process group exists: see end_process_group
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


def end_process_group() -> None:
    """Destroy the default process group once the model that used it is gone (call it after the function that
    trained returns), so gloo's worker threads are joined while Python is alive. A worker still freeing the last
    backward's all-reduce needs the GIL for it (the work keeps backward's Python context); one left running into
    interpreter shutdown aborts the process, "terminate called without an active exception" (pytorch#190489): once
    in ~15 runs of ddp_torchrun.py on a loaded 2-core machine, and in a Lightning DDP fit. The group must have no
    holder left: torch.distributed.nn, first imported with a group in place (DistributedDataParallel imports it),
    keeps that group in its functions' defaults, hence its import at the top of this module."""
    gc.collect()  # a Lightning Trainer, its module and the DDP wrapper that holds the group refer to each other
    if dist.is_initialized():
        dist.destroy_process_group()
