"""Selective presentation as a ``torch.utils.data.Sampler``: the single source of presentation order.

The nested training sets A1 ⊂ A2 ⊂ … ⊂ A_{p+1} = U are the prefixes of one *priority order* of the
exemplar set (``selpres.presentation.orders``: stratified, random, coverage), so nesting holds by construction. The
stage-wise orders of ``selpres.presentation.selection`` (loss_high, loss_low, reselect) replace a sampler's ``order`` at
each stage start; the sampler itself never changes it.

Within an epoch the current set is reshuffled; ``set_epoch(e)`` picks the epoch (and so the stage),
following ``DistributedSampler``'s convention. The shuffle of epoch e is a counter-based hash of
(seed, e), so a resumed run needs no sampler state beyond the epoch number (and a stage-wise order, which
the checkpoint keeps), and the shuffles of all replicas of a job are computed in one vectorised step
(``epoch_orders``).
"""

from __future__ import annotations

import functools
from collections.abc import Iterator

import numpy as np
import torch
from torch.utils.data import Sampler

from selpres.presentation.schedule import Schedule
from selpres.seeding import derive_seed

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # splitmix64's increment: the counter step of the shuffle hash
_BLOCK_HASHES = 2**15  # per block of replicas: 256 KB stays in L2, and torch.gather stays on one thread


_MIX_STEPS = tuple(
    (np.uint64(s), None if m is None else np.uint64(m))
    for s, m in ((30, 0xBF58476D1CE4E5B9), (27, 0x94D049BB133111EB), (31, None))
)


def _mix64_(z: np.ndarray, tmp: np.ndarray | None = None) -> np.ndarray:
    """splitmix64's finaliser, in place on ``z`` (uint64; arithmetic wraps): a bijective 64-bit hash."""
    tmp = np.empty_like(z) if tmp is None else tmp
    for shift, mult in _MIX_STEPS:
        np.right_shift(z, shift, out=tmp)
        z ^= tmp
        if mult is not None:
            z *= mult
    return z


@functools.lru_cache(maxsize=8)
def _counters(size: int) -> np.ndarray:
    """i * golden for i < size (the hash's counters), computed once per set size, read-only."""
    with np.errstate(over="ignore"):
        steps = np.arange(size, dtype=np.uint64) * _GOLDEN
    steps.flags.writeable = False
    return steps


def _shuffle_bases(keys: np.ndarray, epochs: np.ndarray) -> np.ndarray:
    """Each replica's hash base for its epoch: mix(key ^ mix(epoch + golden))."""
    return _mix64_(keys ^ _mix64_(epochs + _GOLDEN))


def _row_hashes(base: np.ndarray, out: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """out[r, i] = mix(base_r + i * golden): the keys replica r's shuffle sorts (buffers reused)."""
    np.add(base[:, None], _counters(out.shape[1])[None, :], out=out)
    return _mix64_(out, tmp)


@functools.lru_cache(maxsize=1)
def native_shuffles():
    """``(shuffler, None)`` when the native shuffles (``kernels/shuffle.c``) load here, else ``(None, why)``;
    decided once per process, so a missing compiler is not retried every epoch."""
    from selpres.native import KernelUnavailable, load_shuffle

    try:
        return load_shuffle(), None
    except KernelUnavailable as exc:
        return None, str(exc)


def shuffle_implementation() -> str:
    """What computes the shuffles in this process, for the job's record: ``native``, or ``numpy (why)``.
    Both give the same permutations (tested); only the speed differs."""
    shuffler, why = native_shuffles()
    return "native" if shuffler is not None else f"numpy ({why})"


def epoch_orders(samplers: list[SelectivePresentationSampler], buffer: torch.Tensor | None = None) -> torch.Tensor:
    """Every sampler's current epoch order, stacked [R, m]: one vectorised shuffle for all replicas.

    ``buffer`` (one-dimensional int64, at least R * m elements), when given, holds the result (a view of it
    is returned): a job reuses one buffer every epoch, since fresh memory (8 MB at R = 1000) is mapped in
    page by page, which cost more than the shuffle itself.

    Replica r's shuffle is argsort of hash(key_r, epoch, i) over the current set's positions i, a
    counter-based permutation, so it is the same whether computed alone or with other replicas, and
    costs no generator set-up. The native shuffles compute it with a bucket sort, on every thread torch
    may use; without them, numpy: replicas hashed and argsorted in blocks that stay in cache (exact: the hash
    is bijective, so a row's keys are distinct).
    """
    plans = [s._plan[s.epoch] for s in samplers]
    size, count = plans[0].size, plans[0].presentations
    if any((p.size, p.presentations) != (size, count) for p in plans):
        raise ValueError("samplers are at different stages; set_epoch them alike")
    R = len(samplers)
    keys = np.array([s._key for s in samplers], dtype=np.uint64)
    epochs = np.array([s.epoch for s in samplers], dtype=np.uint64)
    dtype = samplers[0].order.dtype
    if (
        buffer is not None
        and buffer.dtype == dtype
        and buffer.dim() == 1
        and buffer.is_contiguous()
        and buffer.numel() >= R * count
    ):
        out = buffer[: R * count].view(R, count)
    else:
        out = torch.empty((R, count), dtype=dtype)
    shuffler, _ = native_shuffles()
    if shuffler is not None:  # it hashes keys and epochs itself (kernels/shuffle.c)
        orders = [s.order for s in samplers]  # contiguous int64 of length n (the sampler's setter); kept alive
        shuffler.shuffle(keys, epochs, orders, size, count, out, torch.get_num_threads())
        return out
    with np.errstate(over="ignore"):
        base = _shuffle_bases(keys, epochs)
    block = max(1, min(R, _BLOCK_HASHES // size))
    h = np.empty((block, size), dtype=np.uint64)
    tmp = np.empty_like(h)
    with np.errstate(over="ignore"):
        for r0 in range(0, R, block):
            r1 = min(R, r0 + block)
            hb = _row_hashes(base[r0:r1], h[: r1 - r0], tmp[: r1 - r0])
            pos = torch.from_numpy(np.argsort(hb, axis=1)[:, :count])  # exact: a row's hashes are distinct
            orders = torch.stack([s.order for s in samplers[r0:r1]])  # per block: no 8 MB copy to fault in
            torch.gather(orders, 1, pos, out=out[r0:r1])
    return out


class SelectivePresentationSampler(Sampler[int]):
    """Yields the indices presented in one epoch: the current stage's subset of U, freshly shuffled."""

    def __init__(self, order: torch.Tensor, schedule: Schedule, seed: int):
        self.schedule = schedule
        self.order = order  # checked and stored contiguous (the setter below)
        self.seed = int(seed)
        self._key = derive_seed(self.seed, "shuffle")
        self._plan = schedule.plan()
        self.epoch = 0

    @property
    def order(self) -> torch.Tensor:
        """The priority order of U (A_i is its first n_i): a contiguous int64 tensor of the schedule's n,
        which the native shuffles read directly (selection replaces it at stage starts)."""
        return self._order

    @order.setter
    def order(self, order: torch.Tensor) -> None:
        if order.numel() != self.schedule.n:
            raise ValueError(
                f"priority order has {order.numel()} indices but the schedule ends at n = {self.schedule.n}"
            )
        self._order = order.to(torch.int64).contiguous().view(-1)

    def set_epoch(self, epoch: int) -> None:
        if not 0 <= epoch < len(self._plan):
            raise IndexError(f"epoch {epoch} outside the schedule's {len(self._plan)} epochs")
        self.epoch = epoch

    @property
    def stage(self) -> int:
        return self._plan[self.epoch].stage

    def subset(self, stage: int | None = None) -> torch.Tensor:
        """A_i as indices into U (the first n_i of the priority order)."""
        k = self.stage if stage is None else stage
        return self.order[: self.schedule.stages[k].size]

    def epoch_indices(self) -> torch.Tensor:
        """This epoch's presentation order as one tensor (what the engines consume)."""
        return epoch_orders([self])[0]

    def __iter__(self) -> Iterator[int]:
        return iter(self.epoch_indices().tolist())

    def __len__(self) -> int:
        return self._plan[self.epoch].presentations
