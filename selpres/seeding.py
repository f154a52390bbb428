"""Seeds: one config seed fans out into independent, named random streams.

Every random choice (initial weights, subset order, per-epoch shuffles, test patterns) draws from its
own stream derived from (seed, purpose, …), so changing how often one is used never shifts another,
and a replica's numbers depend only on its own seed, not on how many replicas share the job.
"""

from __future__ import annotations

import hashlib
import random

import numpy as np
import torch


def derive_seed(*keys) -> int:
    """A 63-bit seed from any tuple of ints/strings (stable across Python runs, unlike hash())."""
    text = "/".join(str(k) for k in keys).encode()
    return int.from_bytes(hashlib.blake2b(text, digest_size=8).digest(), "little") >> 1


def generator(*keys) -> torch.Generator:
    return torch.Generator().manual_seed(derive_seed(*keys))


def seed_everything(seed: int) -> None:
    """Seed python, numpy and torch's global generators (for any code path that uses them)."""
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
