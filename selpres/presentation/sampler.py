"""Selective presentation as a ``torch.utils.data.Sampler``: the single source of presentation order, one object
(``SelectivePresentation``) for the CLI's loop and for any PyTorch loop, plain, DistributedDataParallel or Lightning
(``selpres.presentation.lightning``); its arguments are read by ``selpres.presentation.arguments``.

The nested training sets A1 ⊂ A2 ⊂ … ⊂ A_{p+1} = U are the prefixes of one *priority order* of the
exemplar set (``selpres.presentation.orders``: stratified, random, coverage), so nesting holds by construction. The
stage-wise orders (loss_high, loss_low, reselect), run by the ``staged`` selector (``selpres.presentation.staged``),
replace a sampler's ``order`` at each stage start; the sampler itself never changes it.

Within an epoch the current set is reshuffled; ``set_epoch(e)`` picks the epoch (and so the stage),
following ``DistributedSampler``'s convention. The shuffle of epoch e is a counter-based hash of
(seed, e), so a resumed run needs no sampler state beyond the epoch, the position within it and the count
(``state_dict``, kept by ``selpres.presentation.handout`` with the passes and warnings; the CLI's checkpoint keeps
a stage-wise order), and the shuffles of all replicas of a job are computed in one vectorised step
(``epoch_orders``).
"""

from __future__ import annotations

import functools
import sys

import numpy as np
import torch
import torch.distributed as dist
from torch.utils.data.distributed import DistributedSampler

from selpres.presentation import arguments as A
from selpres.presentation.handout import LIGHTNING, Handout
from selpres.presentation.handout import SelectivePresentationWarning as SelectivePresentationWarning  # its home
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


class SelectivePresentation(Handout, DistributedSampler):
    """Selective presentation for any PyTorch loop: each epoch yields the current training set A_i, reshuffled.

        sampler = SelectivePresentation(X, sizes=[0.05, 0.1, 0.4, 0.8, 1.0], epochs=[30] * 5, seed=0)
        loader = DataLoader(dataset, batch_size=32, sampler=sampler)
        for epoch in range(sampler.num_epochs):
            sampler.set_epoch(epoch)
            for batch in loader: ...

    The schedule: ``sizes`` (any sequence or 1-D array; ints are counts n_i, floats fractions of n rounded half up
    and at least 1, the last the whole set: ``1.0`` or n),
    ``epochs`` N_i per stage, or ``budget`` presentations of one conventional stage (the compute-matched
    baseline), or ``schedule=`` a name of ``configs/schedule/`` ("selective", "matched", "random_growth", …).
    ``order`` grows the nested sets A1 ⊂ … ⊂ U: "stratified" (the paper's uniform sampling of the input space X),
    "random", "coverage" (farthest-point), or a permutation of range(n) of your own; ``seed`` fixes the order and
    every epoch's shuffle, exactly as replica 0 of ``python train.py seed=<seed>`` with the same X.

    Distributed as ``DistributedSampler``: ``num_replicas``/``rank`` default to torch.distributed's (read when
    the sampler is used, so it may be built before the process group); rank r takes ``epoch[r::num_replicas]`` of
    the epoch's one shuffled order, which every rank computes alike from (seed, epoch) without communicating;
    ``drop_last=False`` pads that order by repeating its head to a multiple of num_replicas, ``drop_last=True``
    drops its tail. It *is* a DistributedSampler, so Lightning and other wrappers leave it unwrapped.

    Cost: ``presentations`` counts the patterns presented so far by all ranks together (the paper's T / t),
    ``rank_presentations`` this rank's: every index handed to the loop (cut-short and repeated passes included; a
    resumed run's earlier ones come with ``load_state_dict``). Resume: ``state_dict()``/``load_state_dict()`` hold
    the epoch and the position in it (torchdata's ``StatefulDataLoader`` calls them); ``set_epoch`` with the saved
    epoch keeps the position.
    """

    shuffle = True  # DistributedSampler's attribute: every epoch is a fresh shuffle
    dataset = None  # DistributedSampler's attribute: sized by the schedule, not by a dataset

    def __init__(
        self,
        X=None,
        *,
        sizes=None,
        epochs=None,
        budget=None,
        schedule=None,
        order=None,
        seed: int = 0,
        strata_bins: int = 2,
        n: int | None = None,
        num_replicas: int | None = None,
        rank: int | None = None,
        drop_last: bool = False,
    ):
        # DistributedSampler.__init__ is not called: it needs a dataset and an initialised process group, and
        # every attribute it would set is a property or set here.
        X = None if X is None else A.inputs_of(X)
        n = A.size_of(X, n, order)
        sched, named_order, note = A.schedule_of(n, sizes, epochs, budget, schedule)
        self.schedule = sched
        self.seed = A._whole("seed", seed, 0)
        bins = A._whole("strata_bins", strata_bins, 1)
        kind = order if order is not None else named_order or "stratified"
        self.order, self.order_kind = A.order_of(kind, X, n, self.seed, bins)
        self.schedule_note = note  # how a named schedule's counts were applied to this n (None: as given)
        self.drop_last = bool(drop_last)
        self._replicas, self._rank = A.replicas_of(num_replicas, rank)
        self._key = derive_seed(self.seed, "shuffle")
        self._plan = sched.plan()
        self.epoch = 0
        self._begin_handout()

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

    # ------------------------------------------------------------------------------------ where we are

    @property
    def num_epochs(self) -> int:
        """Σ N_i (a budget's partial epoch counts as one): ``range(sampler.num_epochs)`` is the loop."""
        return len(self._plan)

    def set_epoch(self, epoch: int) -> None:
        """Choose the epoch (and so the stage): call it before each epoch, as for DistributedSampler."""
        if isinstance(epoch, bool) or not isinstance(epoch, int):
            epoch = A._whole("epoch", epoch, 0)  # numpy ints pass; floats and bools raise TypeError
        if not 0 <= epoch < len(self._plan):
            raise IndexError(
                f"epoch={epoch} is outside the schedule's {len(self._plan)} epochs (0 .. {len(self._plan) - 1}):"
                " stop after sampler.num_epochs epochs (Lightning: SelectivePresentationCallback sets max_epochs)"
            )
        if not self._lightning and sys._getframe(1).f_globals.get("__name__", "").startswith(LIGHTNING):
            raise RuntimeError(
                "SelectivePresentation in a Lightning Trainer needs its callback: Trainer(callbacks="
                "[SelectivePresentationCallback(sampler)]) (from selpres import SelectivePresentationCallback); "
                "without it Lightning cuts every epoch to A1's batch count and runs past the schedule's "
                f"{len(self._plan)} epochs"
            )
        self._move_to(epoch)  # (a loop that never iterates, as the CLI's, allocates nothing here)

    @property
    def stage(self) -> int:
        """The current stage's index (0 for A1)."""
        return self._plan[self.epoch].stage

    def subset(self, stage: int | None = None) -> torch.Tensor:
        """A_i as indices into U (the first n_i of the priority order); the current stage's by default."""
        k = self.stage if stage is None else stage
        return self.order[: self.schedule.stages[k].size]

    @property
    def training_set(self) -> torch.Tensor:
        """The current training set A_i (the paper's word), as indices into U."""
        return self.subset()

    # ------------------------------------------------------------------------------------ distribution

    @property
    def num_replicas(self) -> int:
        if self._replicas is not None:
            return self._replicas
        return dist.get_world_size() if dist.is_available() and dist.is_initialized() else 1

    @property
    def rank(self) -> int:
        r = self._rank
        if r is None:
            r = dist.get_rank() if dist.is_available() and dist.is_initialized() else 0
        if r >= self.num_replicas:
            raise ValueError(f"rank={r}: expected 0 <= rank < num_replicas = {self.num_replicas}")
        return r

    def _share(self, count: int, world: int) -> int:
        """Indices per rank of an epoch presenting ``count`` (DistributedSampler's num_samples)."""
        return count if world == 1 else count // world if self.drop_last else -(-count // world)

    @property
    def num_samples(self) -> int:
        """This rank's indices in the current epoch (``len(sampler)``)."""
        return self._share(self._plan[self.epoch].presentations, self.num_replicas)

    @property
    def total_size(self) -> int:
        """All ranks' indices in the current epoch (padded or dropped to a multiple of num_replicas)."""
        return self.num_samples * self.num_replicas

    # ------------------------------------------------------------------------------------ what is presented

    def epoch_indices(self) -> torch.Tensor:
        """This epoch's presentation order for all ranks together, as one tensor (what the engines consume)."""
        return epoch_orders([self])[0]

    def rank_indices(self) -> torch.Tensor:
        """This rank's share of the epoch: ``epoch[rank:total_size:num_replicas]`` of the padded or cut order."""
        idx, world = self.epoch_indices(), self.num_replicas
        if world == 1:
            return idx
        total = self._share(idx.numel(), world) * world
        if total > idx.numel():  # DistributedSampler's padding: the head of the order again
            idx = idx.repeat(-(-total // idx.numel()))
        return idx[self.rank : total : world]

    def __len__(self) -> int:
        return self.num_samples

    def __repr__(self) -> str:
        return (
            f"SelectivePresentation(n={self.schedule.n}, sizes={self.schedule.sizes}, epochs={self.schedule.epochs}, "
            f"order={self.order_kind!r}, seed={self.seed}, epoch={self.epoch}/{self.num_epochs}, stage={self.stage})"
        )


class SelectivePresentationSampler(SelectivePresentation):
    """The CLI's spelling (a built priority order and schedule, positional); the same object."""

    def __init__(self, order: torch.Tensor, schedule: Schedule, seed: int):
        super().__init__(order=order, schedule=schedule, seed=seed)
