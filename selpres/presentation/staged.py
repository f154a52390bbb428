"""``staged``: the paper's selective presentation as a selector. Each replica's sampler
(``selpres.presentation.sampler.SelectivePresentation``) presents the current training set A_i, reshuffled each
epoch; the sets are the prefixes of a priority order of U (``selpres.presentation.orders``). An order fixed before
training (stratified, random, coverage, a user's ``Order``) needs nothing more. A stage-wise order (loss_high,
loss_low, reselect, a user's ``StagewiseOrder``) chooses A_k at stage k's first epoch, from the replicas' current
networks or afresh; the candidates it scores are charged to the ledger (``orders.selection_charge``), every replica
alike, and the chosen orders are the selector's state, so a checkpoint holds them and a resumed job presents what it
would have. Conventional training is its one-stage schedule; a pruning policy refines its shuffles of U.
"""

from __future__ import annotations

import functools

import torch

from selpres.presentation.orders._order import Order, selection_charge
from selpres.presentation.partition import strata
from selpres.presentation.sampler import SelectivePresentation, epoch_orders
from selpres.presentation.schedule import EpochPlan, Schedule
from selpres.presentation.selection import one_thread
from selpres.presentation.selector import Ledger, Network, Presentation, Selector
from selpres.seeding import generator


class Staged(Selector):
    """Presents each replica's A_i of ``schedule`` through its sampler, A_i the prefixes of ``order``'s
    priority orders of U (``X_raw``: U's raw inputs; ``X``, ``Y``: U scaled, which a stage-wise order scores)."""

    name = "staged"

    def __init__(
        self,
        order: Order,
        schedule: Schedule,
        seeds: list[int],
        X_raw: torch.Tensor,
        X: torch.Tensor,
        Y: torch.Tensor,
        cost_fraction: float,
    ):
        super().__init__({}, None)
        self.order, self.schedule, self.seeds = order, schedule, list(seeds)
        self.X_raw, self.X, self.Y, self.cost_fraction = X_raw, X, Y, float(cost_fraction)
        priority = order.orders(X_raw, [generator(s, "subset") for s in self.seeds])
        self.samplers = [SelectivePresentation(order=o, schedule=schedule, seed=s) for o, s in zip(priority, seeds)]
        plan = schedule.plan()
        self._starts = {}  # epoch -> the stage that starts there (where a stage-wise order chooses)
        if order.stagewise:
            self._starts = {e.index: e.stage for e in plan if e.stage > 0 and plan[e.index - 1].stage != e.stage}
        self.chosen: torch.Tensor | None = None  # [R, n] the orders chosen during training (None: the prepared)
        self._applied = None  # the chosen orders the samplers present now
        self._buffer: torch.Tensor | None = None
        self.source = self

    @functools.cached_property
    def strata(self) -> torch.Tensor:
        """U's strata, once per job (k-means for many inputs: seconds at n = 1e5), for reselect's draws."""
        return strata(self.X_raw, self.order.strata_bins)

    def planned_charge(self, schedule: Schedule) -> int:
        return self.order.planned_charge(schedule.sizes, self.cost_fraction)

    def select(self, ep: EpochPlan, ledger: Ledger, net: Network) -> Presentation:
        stage = self._starts.get(ep.index)
        if stage is not None:
            current = self.chosen if self.chosen is not None else torch.stack([s.order for s in self.samplers])
            with one_thread():
                self.chosen = self.order.choose(self, stage, current, net.engine)
            kept = self.schedule.stages[stage - 1].size
            ledger.charge(selection_charge(self.order.candidates(kept, self.schedule.n), self.cost_fraction))
        if self.chosen is not None and self.chosen is not self._applied:
            for s, order in zip(self.samplers, self.chosen):
                s.order = order
            self._applied = self.chosen
        with net.phase("shuffle"):
            for s in self.samplers:
                s.set_epoch(ep.index)
            return Presentation(epoch_orders(self.samplers, self._orders_buffer()))

    def _orders_buffer(self) -> torch.Tensor:
        """Where every epoch's presentation orders are written ([R * the largest epoch], reused every epoch:
        ``epoch_orders`` says why)."""
        if self._buffer is None:
            largest = max(st.size if st.epochs else st.extra for st in self.schedule.stages)
            self._buffer = torch.empty(len(self.seeds) * largest, dtype=torch.int64)
        return self._buffer

    def describe(self) -> dict:
        return {"stagewise": self.order.stagewise}

    def state_dict(self) -> dict:
        return {"chosen": self.chosen}

    def load_state_dict(self, state: dict) -> None:
        chosen = state["chosen"]
        shape = (len(self.seeds), self.schedule.n)
        if chosen is not None and (not isinstance(chosen, torch.Tensor) or tuple(chosen.shape) != shape):
            raise ValueError(f"the chosen orders are not a tensor of shape {shape}")
        self.chosen, self._applied = chosen, None
