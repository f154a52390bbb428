"""Orders chosen stage by stage: adaptive loss orders and re-drawn subsets, with the cost of choosing counted.

The priority orders of :mod:`selpres.presentation.orders` are fixed before training. The orders here choose A_k at the
start of stage k (its first epoch), so each replica's sampler gets a new order there:

* ``loss_high`` / ``loss_low``: adaptive and nested. A_1 is the seed's *stratified* sample (there is no
  network to ask yet); at each enlargement A_k = A_{k-1} plus the n_k - n_{k-1} patterns of U \\ A_{k-1} on
  which the replica's *current* network errs most (hard first) or least (easy first): per-pattern squared
  error summed over the outputs, in scaled units. Ties go to the earlier pattern of the seed's stratified
  order: the candidates are kept in that order, and the chosen ones join A_k in it too. All replicas are
  scored together by one forward pass over U (``engine.predict``), and the chosen patterns are found by a
  partition, not a sort (at R = 1000: ~13 ms against ~60-80 ms for a stable sort).
* ``reselect``: not nested. Stage k's A_k is a fresh stratified draw of size n_k (stage 1's is the
  ``stratified`` order's A_1; stage k > 1 draws from the seed's stream ``(seed, "subset", k)``), so
  consecutive subsets overlap only by chance, about n_{k-1} n_k / n patterns; the last stage is U.

The cost of choosing (``schedule.selection_cost``, default 1/3): scoring a candidate is one forward pass,
charged as that fraction of a training presentation (per enlargement, rounded up to whole presentations).
Why 1/3: the backward pass of a layer costs about two forward passes (the error propagated through W and
the weight gradient, each a product of W's size), the common rule of training = 3 x forward (Kaplan et al.
2020, "Scaling laws for neural language models", section 2.1: "the backwards pass is approximately twice
the compute as the forwards pass", C ~ 6N per training token against 2N per forward pass). Counted for
the 6-13-2 net: forward 208 flops + 15 sigmoids, backward 260 flops (no error is propagated into the
inputs), the momentum update 4 flops for each of 119 weights (476): forward / all = 0.22 (0.37 if a
sigmoid costs ~15 flops); measured for this package's torch engine in one layout (forward of the same
[R, n, 6] batch against ``TorchEngine.train_epoch``, one batch of n = 1002): 0.18 at R = 1, 0.41 at
R = 30, 0.31 at R = 1000. So 1/3 is neither generous nor harsh; set 0 to ignore the cost, as CORDS and
DeepCore do. A charge is per replica (every replica scores the same number of candidates) and is added
to the job's cumulative presentations, the cost axis of curves and results; its wall time is the clock
phase "select". Stratified draws (A_1, ``reselect``) need no network and are charged nothing.
"""

from __future__ import annotations

import functools
import math
from contextlib import contextmanager

import numpy as np
import torch

from selpres.presentation.orders import strata, stratified_orders
from selpres.presentation.sampler import SelectivePresentation
from selpres.presentation.schedule import EpochPlan, Schedule
from selpres.seeding import generator

LOSS_ORDERS = {"loss_high": True, "loss_low": False}  # order -> hard first?
STAGEWISE = (*LOSS_ORDERS, "reselect")  # the orders whose A_k is chosen at the start of stage k


@contextmanager
def one_thread():
    """Choosing runs on one torch thread: its blocks are too small to share (with two threads on a busy
    machine, R = 1000, one enlargement took 0.8 s instead of 0.07 s: OpenMP waits at every small op), and
    ``threads`` is not part of a job's identity, so the choice must not depend on it (BLAS may round
    differently with another thread count)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def initial_kind(kind: str) -> str:
    """The priority order a job starts from: the stage-wise orders begin with the stratified A_1."""
    return "stratified" if kind in STAGEWISE else kind


def pattern_errors(outputs: torch.Tensor, Y: torch.Tensor) -> torch.Tensor:
    """Squared error of every replica on every pattern, summed over outputs: [R, n, out], [n, out] -> [R, n].
    A diverged replica's NaN counts as +inf, so its choice stays deterministic."""
    return torch.nan_to_num((outputs - Y).square().sum(-1), nan=float("inf"))


def enlarge_by_loss(orders: torch.Tensor, errors: torch.Tensor, kept: int, added: int, hard: bool) -> torch.Tensor:
    """New orders [R, n]: each row's first ``kept`` patterns (A_{k-1}) stay; of the candidates after them,
    the ``added`` with the largest (``hard``) or smallest ``errors`` [R, n] come next and the others after,
    both in the order the candidates were in (so equal errors go to the earlier candidate).

    Exactly the first ``added`` of a stable sort by error, found by a partition: v = the added-th value, then
    every candidate beyond v and the first of those equal to v."""
    tail = orders[:, kept:]
    e = errors.gather(1, tail).numpy()
    R, c = e.shape
    at = c - added if hard else added - 1  # v's position in each row sorted ascending
    v = np.partition(e, at, axis=1)[:, at, None]
    beyond = e > v if hard else e < v
    tied = e == v
    need = added - beyond.sum(1, keepdims=True)
    chosen = beyond | (tied & (np.cumsum(tied, 1) <= need))
    t = tail.numpy()  # numpy's boolean indexing: ~4x torch's here
    rows = (orders[:, :kept].numpy(), t[chosen].reshape(R, added), t[~chosen].reshape(R, c - added))
    return torch.from_numpy(np.concatenate(rows, axis=1))


def reselected_orders(sid: torch.Tensor, seeds: list[int], stage: int) -> torch.Tensor:
    """Stage ``stage``'s fresh stratified orders [R, n] of U's strata ``sid`` (``orders.strata``, computed
    once per job; stage 0: the ``stratified`` order's own draw)."""
    gens = [generator(s, "subset") if stage == 0 else generator(s, "subset", stage) for s in seeds]
    return stratified_orders(sid, gens)


def selection_charge(candidates: int, fraction: float) -> int:
    """Presentations charged per replica for scoring ``candidates`` patterns by a forward pass: candidates x
    fraction, rounded up to a whole presentation (presentations are counts; never under-charged), after
    rounding off float noise (952 x 1/3 -> 318, 900 x 1/3 -> 300)."""
    return math.ceil(round(candidates * fraction, 9))


def planned_charge(kind: str, sizes: list[int], fraction: float) -> int:
    """Presentations a schedule of stage ``sizes`` (counts, the last = n) will be charged per replica for
    choosing in order ``kind``: at each enlargement the loss orders score the n - n_k candidates outside
    A_k; the other orders choose without a network and pay nothing. Known before training, so a run's
    total cost (training + this) can be matched by a one-stage partner (configs/design/selection/)."""
    if kind not in LOSS_ORDERS:
        return 0
    return sum(selection_charge(sizes[-1] - kept, fraction) for kept in sizes[:-1])


def errors_of(engine, X: torch.Tensor, Y: torch.Tensor) -> torch.Tensor:
    """Every replica's per-pattern squared error on (X, Y) [n, in], [n, out] -> [R, n], from one
    ``engine.predict`` call."""
    with torch.no_grad():
        return pattern_errors(engine.predict(X), Y)


class StageSelection:
    """Chooses each replica's A_k at the start of stage k, and charges what choosing costs.

    The chosen orders live in the job's progress (``progress.orders`` [R, n], None until the first choice:
    the prepared orders), so a checkpoint holds them and a resumed job presents what it would have.
    """

    def __init__(
        self,
        kind: str,
        schedule: Schedule,
        seeds: list[int],
        X_raw: torch.Tensor,
        bins: int,
        X: torch.Tensor,
        Y: torch.Tensor,
        cost_fraction: float,
        samplers: list[SelectivePresentation],
    ):
        if kind not in STAGEWISE:
            raise ValueError(f"order {kind!r} is fixed before training; stage-wise orders: {STAGEWISE}")
        self.kind, self.schedule, self.seeds, self.X_raw, self.bins = kind, schedule, seeds, X_raw, bins
        self.X, self.Y, self.cost_fraction = X, Y, float(cost_fraction)
        self.samplers = samplers
        plan = schedule.plan()
        self.stage_starts = {ep.index: ep.stage for ep in plan if ep.stage > 0 and plan[ep.index - 1].stage != ep.stage}
        self._applied = None  # the orders tensor the samplers currently present

    @functools.cached_property
    def strata(self) -> torch.Tensor:
        """U's strata, once per job (k-means for many inputs: seconds at n = 1e5), for reselect's draws."""
        return strata(self.X_raw, self.bins)

    def begin_epoch(self, ep: EpochPlan, engine, progress) -> int:
        """Before epoch ``ep``: the samplers present ``progress.orders`` (restored after a resume); at a
        stage start the new A_k is chosen into it. Returns the presentations charged per replica (also
        added to ``progress.presentations`` and ``progress.selection_presentations``)."""
        stage = self.stage_starts.get(ep.index)
        charge = 0
        if stage is not None:
            with one_thread():
                charge = self._choose(stage, engine, progress)
            progress.presentations += charge
            progress.selection_presentations += charge
        if progress.orders is not None and progress.orders is not self._applied:
            for s, order in zip(self.samplers, progress.orders):
                s.order = order
            self._applied = progress.orders
        return charge

    def _choose(self, stage: int, engine, progress) -> int:
        """Stage ``stage``'s orders into ``progress.orders``; returns the charge per replica."""
        if self.kind == "reselect":
            progress.orders = reselected_orders(self.strata, self.seeds, stage)
            return 0  # a stratified draw needs no network
        current = progress.orders
        if current is None:  # the first choice: from the prepared (stratified) orders
            current = torch.stack([s.order for s in self.samplers])
        kept, size = self.schedule.stages[stage - 1].size, self.schedule.stages[stage].size
        errors = errors_of(engine, self.X, self.Y)
        progress.orders = enlarge_by_loss(current, errors, kept, size - kept, LOSS_ORDERS[self.kind])
        return selection_charge(self.schedule.n - kept, self.cost_fraction)


def stage_selection(kind: str, *args) -> StageSelection | None:
    """The job's stage-wise selection (``StageSelection(kind, *args)``), or None for an order fixed before
    training (nothing to choose or charge)."""
    return StageSelection(kind, *args) if kind in STAGEWISE else None
