"""The job's stage-wise selection: at the start of stage k a stage-wise order (``selpres.presentation.orders``,
``StagewiseOrder``) chooses A_k, each replica's sampler gets the new order, and the cost of choosing is counted.

The network's scores every order (and pruning policy) may ask for are here too: one forward pass of all replicas
over U (``errors_of``), on one thread (``one_thread``).

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
from contextlib import contextmanager
from typing import TYPE_CHECKING

import torch

from selpres.presentation.orders._order import selection_charge
from selpres.presentation.partition import strata
from selpres.presentation.schedule import EpochPlan, Schedule

if TYPE_CHECKING:
    from selpres.presentation.orders import StagewiseOrder
    from selpres.presentation.sampler import SelectivePresentation


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


def pattern_errors(outputs: torch.Tensor, Y: torch.Tensor) -> torch.Tensor:
    """Squared error of every replica on every pattern, summed over outputs: [R, n, out], [n, out] -> [R, n].
    A diverged replica's NaN counts as +inf, so its choice stays deterministic."""
    return torch.nan_to_num((outputs - Y).square().sum(-1), nan=float("inf"))


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
        order: StagewiseOrder,
        schedule: Schedule,
        seeds: list[int],
        X_raw: torch.Tensor,
        X: torch.Tensor,
        Y: torch.Tensor,
        cost_fraction: float,
        samplers: list[SelectivePresentation],
    ):
        if not order.stagewise:
            raise ValueError(f"order {type(order).__name__} is fixed before training: there is nothing to choose")
        self.order, self.schedule, self.seeds, self.X_raw = order, schedule, seeds, X_raw
        self.X, self.Y, self.cost_fraction = X, Y, float(cost_fraction)
        self.samplers = samplers
        plan = schedule.plan()
        self.stage_starts = {ep.index: ep.stage for ep in plan if ep.stage > 0 and plan[ep.index - 1].stage != ep.stage}
        self._applied = None  # the orders tensor the samplers currently present

    @functools.cached_property
    def strata(self) -> torch.Tensor:
        """U's strata, once per job (k-means for many inputs: seconds at n = 1e5), for reselect's draws."""
        return strata(self.X_raw, self.order.strata_bins)

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
        current = progress.orders
        if current is None:  # the first choice: from the prepared (stratified) orders
            current = torch.stack([s.order for s in self.samplers])
        progress.orders = self.order.choose(self, stage, current, engine)
        kept = self.schedule.stages[stage - 1].size
        return selection_charge(self.order.candidates(kept, self.schedule.n), self.cost_fraction)


def stage_selection(order, *args) -> StageSelection | None:
    """The job's stage-wise selection (``StageSelection(order, *args)``), or None for an order fixed before
    training (nothing to choose or charge)."""
    return StageSelection(order, *args) if order.stagewise else None
