"""The one protocol of everything that decides what an epoch presents, and the ledger it charges.

A :class:`Selector` is asked once per epoch, by the loop, for each replica's patterns and weights
(:meth:`Selector.select` -> :class:`Presentation`); after the epoch's updates it is shown what was presented and the
presented patterns' training losses (:meth:`Selector.observe`). It keeps whatever it learns between epochs as state
(:meth:`Selector.state_dict`), which a checkpoint holds, so every job resumes exactly. The paper's stages
(``staged``: the samplers' nested sets, fixed or chosen stage by stage), the data-pruning policies (``pruning/``)
and a user's own class all meet it; the loop never asks which one it has.

Every job has one :class:`Ledger`, owned by the loop and handed to the selector to charge: per replica, the
presentations back-propagated (charged by the loop from the :class:`Presentation` itself, so nothing presented goes
uncharged), the forward passes a selector spends choosing (charged by the selector, at ``schedule.selection_cost``
of a presentation each), what conventional training would have presented in the same epochs, and the budget they
run against. results.json's cost and cost ratio are read from it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from contextlib import nullcontext
from dataclasses import dataclass

import torch

from selpres.errors import ConfigError
from selpres.presentation.proportions import schedule_of
from selpres.presentation.schedule import EpochPlan, Schedule
from selpres.presentation.selection import errors_of, one_thread


@dataclass
class Presentation:
    """What each replica presents in one epoch: the first ``counts[r]`` entries of ``order[r]`` (the whole row when
    ``counts`` is None), each pattern's loss weighted by ``weights`` (1 when None)."""

    order: torch.Tensor  # [R, m] int64 indices into U (padded past counts[r])
    weights: torch.Tensor | None = None  # [R, m] float64, or None (all 1)
    counts: torch.Tensor | None = None  # [R] int64, or None (every row whole)

    def presented(self, loss: torch.Tensor) -> torch.Tensor:
        """The epoch's mean losses [R] with a replica that presented nothing (its budget spent) at 0: NaN there
        means no pattern, not divergence."""
        return loss if self.counts is None else loss.masked_fill(self.counts == 0, 0.0)


_SPENT, _TRAINED, _CHARGED, _CONVENTIONAL, _EPOCHS = range(5)  # the ledger's rows
_ROW = {
    "spent": _SPENT,
    "trained": _TRAINED,
    "charged": _CHARGED,
    "conventional": _CONVENTIONAL,
    "epochs_done": _EPOCHS,
}


class Ledger:
    """What a job's replicas have cost so far, and the budget they run against (None: the plan's epochs).

    Costs are in presentations (the paper's T / t): ``trained`` back-propagated, ``charged`` forward passes spent
    choosing, ``spent`` both; ``conventional`` what conventional training would have presented in the epochs each
    replica ran (all n patterns an epoch; a cut epoch of a compute-matched plan its share); ``epochs_done`` the
    epochs in which it presented anything; ``left_out`` patterns a pruning selector left out (its own count).
    While every replica has been charged alike (a staged job) each is one number, so an epoch's bookkeeping at
    R = 1 is a few float additions; the first charge that differs makes them per-replica tensors.
    """

    def __init__(self, n: int, seeds: list[int], budget: int | None, epochs: int | None, selection_cost: float):
        self.n, self.seeds, self.budget, self.epochs = n, list(seeds), budget, epochs
        self.cost_fraction = float(selection_cost)
        self._even: list[float] | None = [0.0] * 5  # every replica's value, while they are all alike
        self._rows: torch.Tensor | None = None  # [5, R] float64 once they differ
        self.left_out = torch.zeros(len(self.seeds), dtype=torch.float64)

    def _split(self) -> torch.Tensor:
        if self._rows is None:
            self._rows = torch.tensor(self._even, dtype=torch.float64).unsqueeze(1).repeat(1, len(self.seeds))
            self._even = None
        return self._rows

    spent = property(lambda self: self._split()[_SPENT], doc="[R] training + forward passes charged")
    trained = property(lambda self: self._split()[_TRAINED], doc="[R] back-propagated presentations")
    charged = property(lambda self: self._split()[_CHARGED], doc="[R] forward passes charged for choosing")
    conventional = property(lambda self: self._split()[_CONVENTIONAL], doc="[R] conventional's presentations")
    epochs_done = property(lambda self: self._split()[_EPOCHS], doc="[R] epochs with a presentation")

    def clock(self) -> float | torch.Tensor:
        """Each replica's cost so far, as an engine's rate schedule reads it (one number while all are alike)."""
        return self._even[_SPENT] if self._rows is None else self._rows[_SPENT]

    def mean(self, row: str) -> float:
        """The mean over replicas of ``spent``, ``trained``, ``charged``, ``conventional`` or ``epochs_done``."""
        i = _ROW[row]
        return self._even[i] if self._rows is None else float(self._rows[i].mean())

    @property
    def remaining(self) -> torch.Tensor:
        if self.budget is None:
            return torch.full_like(self.spent, math.inf)
        return self.budget - self.spent

    @property
    def exhausted(self) -> bool:
        """Every replica has spent its budget (a fraction of a presentation left cannot buy one)."""
        if self.budget is None:
            return False
        least = min(1.0, 1.0 + self.cost_fraction)
        if self._rows is None:
            return self.budget - self._even[_SPENT] < least
        return bool((self.remaining < least).all())

    def affordable(self, r: int, k: int) -> int:
        """How many of ``k`` presentations replica r's remaining budget pays for (the epoch is cut there)."""
        if self.budget is None:  # (asked once per replica and epoch: no tensor for an answer known already)
            return k
        left = float(self.remaining[r])
        return k if math.isinf(left) else min(k, int(math.floor(left + 1e-9)))

    def charge(self, presentations: float, replica: int | None = None) -> None:
        """Charge forward passes spent choosing, in presentations (a candidate scored costs ``cost_fraction``):
        to ``replica``, or to every replica alike."""
        if replica is None and self._rows is None:
            self._even[_SPENT] += presentations
            self._even[_CHARGED] += presentations
            return
        rows, at = self._split(), slice(None) if replica is None else replica
        rows[_CHARGED, at] += presentations
        rows[_SPENT, at] += presentations

    def record(self, shown: Presentation, ep: EpochPlan) -> None:
        """After the epoch's updates (the loop calls it): the presentations it back-propagated, and what
        conventional training would have presented in it."""
        share = self.n * ep.presentations / ep.size  # all of U an epoch; a compute-matched plan's cut epoch its part
        if shown.counts is None:
            m, e = shown.order.shape[1], self._even
            if e is not None:
                e[_TRAINED] += m
                e[_SPENT] += m
                e[_EPOCHS] += 1
                e[_CONVENTIONAL] += share
                return
            counts = torch.full((len(self.seeds),), m, dtype=torch.int64)
        else:
            counts = shown.counts
        rows = self._split()
        c, on = counts.to(torch.float64), (counts > 0).to(torch.float64)
        rows[_TRAINED] += c
        rows[_SPENT] += c
        rows[_EPOCHS] += on
        rows[_CONVENTIONAL] += on * share

    def state_dict(self) -> dict:
        return {"even": self._even, "rows": self._rows, "left_out": self.left_out}

    def load_state_dict(self, state: dict) -> None:
        R = len(self.seeds)
        even, rows, left = state["even"], state["rows"], state["left_out"]
        if (even is None) == (rows is None) or (even is not None and len(even) != 5):
            raise ValueError("a ledger holds either its five common values or its rows")
        for name, t, shape in (("rows", rows, (5, R)), ("left_out", left, (R,))):
            if t is not None and (not isinstance(t, torch.Tensor) or tuple(t.shape) != shape):
                raise ValueError(f"ledger.{name} is not a float64 tensor of shape {shape}")
        self._even = None if even is None else [float(v) for v in even]
        self._rows = None if rows is None else rows.to(torch.float64).clone()
        self.left_out = left.to(torch.float64).clone()

    def describe(self) -> dict:
        """results.json's ``cost``: per replica and as means (a mean of whole presentations is written whole)."""
        R = len(self.seeds)
        rows = self._split().tolist() if self._rows is not None else [[v] * R for v in self._even]
        spent, trained, charged, conventional = rows[_SPENT], rows[_TRAINED], rows[_CHARGED], rows[_CONVENTIONAL]
        mean = lambda xs: _count(sum(xs) / R)
        return {
            "presentations": mean(spent),
            "trained_presentations": mean(trained),
            "charged_presentations": mean(charged),
            "conventional_presentations": mean(conventional),
            "cost_ratio": sum(spent) / sum(conventional) if sum(conventional) else None,
            "budget": self.budget,
            "selection_cost": self.cost_fraction,
            "per_replica": {
                "spent": spent,
                "trained": trained,
                "charged": charged,
                "conventional": conventional,
                "left_out": self.left_out.tolist(),
                "epochs": [int(e) for e in rows[_EPOCHS]],
            },
        }


def _count(x: float) -> int | float:
    """A number of presentations: whole ones as an int."""
    return int(x) if float(x).is_integer() else x


class Network:
    """The replicas' current networks as a selector may ask them (``errors``), and the loop's clock for the parts
    of choosing it times apart (``phase``: the epoch's shuffles are the clock's ``shuffle``)."""

    def __init__(self, engine, X: torch.Tensor, Y: torch.Tensor, phase=None):
        self.engine, self.X, self.Y = engine, X, Y
        self.phase = phase or (lambda name: nullcontext())  # phase(name): a context timing that part

    def errors(self) -> torch.Tensor:
        """Every replica's squared error on every pattern of U, summed over outputs [R, n] (scaled units), from
        one forward pass on one thread. Whoever asks charges it."""
        with one_thread():
            return errors_of(self.engine, self.X, self.Y)


class Selector:
    """Decides what every epoch presents. The loop calls :meth:`select` before an epoch's updates and
    :meth:`observe` after them; a subclass implements :meth:`select` and, if it learns from the losses,
    :meth:`observe`.

    Named by ``schedule.pruning._target_`` (a built-in of ``selpres.presentation.pruning`` or an import path), a
    subclass is made as ``cls(cls.check(params, ...), ledger)`` and given ``source``: the staged presentation of the
    schedule (``selpres.presentation.staged.Staged``), whose ``select`` yields each replica's shuffle of the current
    set, for a selector that refines it. Its randomness must come from ``selpres.seeding.generator(seed_r, ...,
    epoch)`` and its state from :meth:`state_dict`, so a resumed job presents what it would have.
    """

    name = ""  # the registry's name or the import path (set by selpres.presentation.build)
    forward_pass = False  # True: it scores U by a forward pass (charged at schedule.selection_cost)
    source = None  # the schedule's staged presentation (set by selpres.presentation.build)

    def __init__(self, params: dict, ledger: Ledger):
        self.params, self.ledger = dict(params), ledger

    @classmethod
    def check(cls, params: dict, *, budget: int | None, selection_cost: float) -> dict:
        """The parameters as the selector reads them; a ConfigError naming the key for a bad one."""
        for k, v in params.items():
            raise ConfigError(f"schedule.pruning.{k}", v, f"not set: {cls.__name__} reads no parameters")
        return {}

    @classmethod
    def check_schedule(cls, *, sizes: list, order: str, budget: int | None, epochs: list | None, name: str) -> None:
        """The schedule around the selector (``name``: how the config names it), before any data is made."""

    @classmethod
    def schedule(cls, node: Mapping, n: int, params: dict, cost: float) -> tuple[Schedule, str | None, int | None]:
        """The epochs the loop may run on U of n patterns, from the ``schedule`` node (plain values): the configured
        stages, listed or parametric (``proportions.schedule_of``); how named counts were applied (None: as given);
        the budget the ledger runs against (None: the plan is the whole cost)."""
        schedule, note = schedule_of(node, n)
        return schedule, note, None

    def planned_charge(self, schedule: Schedule) -> int:
        """Forward passes the selector is known, before training, to charge per replica (a rate schedule's
        horizon counts them)."""
        return 0

    def select(self, ep: EpochPlan, ledger: Ledger, net: Network) -> Presentation:
        """Epoch ``ep``'s presentations; forward passes spent choosing are charged to ``ledger`` here."""
        raise NotImplementedError

    def observe(self, shown: Presentation, losses: torch.Tensor) -> None:
        """After the epoch's updates: what was presented and the presented patterns' losses before their
        updates [R, m] (the engine's ``last_losses``: filled where ``shown.counts`` was given, NaN past it)."""

    def describe(self) -> dict:
        """results.json's ``selector`` parameters (what ran)."""
        return dict(self.params)

    def state_dict(self) -> dict:
        """What a resume needs: every public tensor attribute, and every public attribute that has a state of its
        own (``state_dict``/``load_state_dict``), the ledger excepted (the loop's). Override for more."""
        out = {}
        for k, v in vars(self).items():
            if k.startswith("_") or k == "ledger":
                continue
            if isinstance(v, torch.Tensor):
                out[k] = v
            elif hasattr(v, "state_dict") and hasattr(v, "load_state_dict") and v is not self:
                out[k] = v.state_dict()
        return out

    def load_state_dict(self, state: dict) -> None:
        """The state :meth:`state_dict` gave; ValueError where it does not fit this selector."""
        ours = self.state_dict()
        if set(ours) != set(state):
            raise ValueError(f"selector state holds {sorted(state)}, this {type(self).__name__} {sorted(ours)}")
        for k, v in state.items():
            mine = getattr(self, k)
            if isinstance(mine, torch.Tensor):
                if not isinstance(v, torch.Tensor) or (v.shape, v.dtype) != (mine.shape, mine.dtype):
                    raise ValueError(f"selector state {k} is not a {mine.dtype} tensor of shape {tuple(mine.shape)}")
                setattr(self, k, v.clone())
            else:
                mine.load_state_dict(v)
