"""One job's pruning: the policy a spec names, the forward pass it may ask for, its costs, the epochs it may run,
and the checks of the schedule around it. ``selpres.run`` hands it a plain spec: the policy's name or import path
(``schedule.pruning._target_``) and a dict of its parameters.
"""

from __future__ import annotations

import math

import torch

from selpres.errors import ConfigError
from selpres.presentation.pruning import REGISTRY
from selpres.presentation.pruning._policy import EpochChoice, Ledger, Policy
from selpres.presentation.schedule import Schedule, Stage
from selpres.presentation.selection import errors_of, one_thread


def policy_class(target: str) -> type[Policy]:
    """The class ``target`` names (a built-in or an import path), refused unless it is a :class:`Policy`."""
    cls = REGISTRY.get(target)
    if not (isinstance(cls, type) and issubclass(cls, Policy)):
        raise ConfigError(
            REGISTRY.key, target, "a subclass of selpres.presentation.pruning.Policy (" + REGISTRY.allowed() + ")"
        )
    return cls


def check_pruning(
    target: str,
    params: dict,
    *,
    sizes: list,
    order: str,
    budget: int | None,
    epochs: list | None,
    selection_cost: float,
) -> type[Policy]:
    """The policy's parameters (its own check) and the schedule around it: one stage of all of U, shuffled, with
    either a budget or one epoch count. A ConfigError names the key; returns the policy's class."""
    cls = policy_class(target)
    cls.check(params, budget=budget, selection_cost=selection_cost)
    name = f"schedule.pruning._target_={target}"
    if list(sizes) != [1.0]:
        raise ConfigError("schedule.sizes", list(sizes), f"[1.0]: {name} prunes all of U every epoch")
    if order != "random":
        raise ConfigError("schedule.order", order, f"random: {name} shuffles all of U every epoch")
    if (budget is None) == (epochs is None):
        raise ConfigError(
            "schedule.budget", budget, f"either a budget or schedule.epochs=[N] for {name}, not both or neither"
        )
    if epochs is not None and len(epochs) != 1:
        raise ConfigError("schedule.epochs", list(epochs), f"one entry [N]: {name} has one stage")
    return cls


def pruning_plan(target: str, params: dict, n: int, budget: int | None, epochs: int | None, selection_cost) -> Schedule:
    """The epochs the loop may run: ``epochs`` as given, or (budget form) as many as the budget could buy at the
    policy's cheapest epoch (:meth:`Policy.epoch_share`); the loop stops once the budget is spent."""
    if budget is None:
        return Schedule((Stage(n, int(epochs)),))
    cls = policy_class(target)
    share = cls.epoch_share(cls.check(params, budget=budget, selection_cost=selection_cost), selection_cost)
    cheapest = n * share
    return Schedule((Stage(n, math.ceil(budget / max(cheapest, 1e-9)) + 1),))


class Pruning:
    """The pruning of one job over its replicas: the policy, and the ledger of what it cost."""

    def __init__(
        self,
        target: str,
        params: dict,
        n: int,
        seeds: list[int],
        budget: int | None,
        epochs: int | None,
        selection_cost: float,
    ):
        cls = policy_class(target)
        self.name, self.path = target, REGISTRY.path_of(target)
        self.ledger = Ledger(n, seeds, budget, epochs, selection_cost)
        self.policy = cls(cls.check(params, budget=budget, selection_cost=selection_cost), self.ledger)

    @property
    def spent(self) -> torch.Tensor:
        return self.ledger.spent

    @property
    def charged(self) -> torch.Tensor:
        return self.ledger.charged

    @property
    def exhausted(self) -> bool:
        return self.ledger.exhausted

    def choose(self, epoch: int, order: torch.Tensor, engine, X: torch.Tensor, Y: torch.Tensor) -> EpochChoice:
        """This epoch's presentations from the samplers' shuffles of U ``order`` [R, n]; the per-pattern losses of
        a forward pass over U (mse in scaled units) if the policy asks for them."""
        losses = None
        if self.policy.forward_pass:
            with one_thread():
                losses = errors_of(engine, X, Y) / Y.shape[1]
        return self.policy.choose(epoch, order, losses)

    def finish(self, choice: EpochChoice, losses: torch.Tensor) -> None:
        """After the epoch's updates: costs, then the policy's scores from the losses [R, m] of the presented."""
        self.ledger.record(choice)
        self.policy.finish(choice, losses)

    def describe(self) -> dict:
        """results.json's ``pruning``: the policy that ran (its class path), its parameters and its cost."""
        led = self.ledger
        return {
            "kind": self.name,
            "policy": self.path,
            **self.policy.describe(),
            "budget": led.budget,
            "selection_cost": led.cost_fraction,
            "cost": led.spent.tolist(),
            "trained_presentations": led.trained.tolist(),
            "charged_presentations": led.charged.tolist(),
            "left_out": led.left_out.tolist(),
            "epochs": led.epochs_done.tolist(),
            "checkpointed": False,  # the scores are not in a checkpoint: a killed pruning job starts again
        }
