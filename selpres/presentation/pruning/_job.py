"""The selector a ``schedule.pruning`` node names, and the checks of its parameters and of the schedule around it.
``selpres.run`` hands it plain values: the class's name or import path (``schedule.pruning._target_``) and a dict of
its parameters. Building the job's selector is ``selpres.presentation.build``'s.
"""

from __future__ import annotations

from selpres.errors import ConfigError
from selpres.presentation.pruning import REGISTRY
from selpres.presentation.selector import Selector


def selector_class(target: str) -> type[Selector]:
    """The class ``target`` names (a built-in or an import path), refused unless it is a :class:`Selector` (a
    pruning policy is one)."""
    cls = REGISTRY.get(target)
    if not (isinstance(cls, type) and issubclass(cls, Selector)):
        allowed = "a subclass of selpres.presentation.pruning.Policy or selpres.presentation.Selector"
        raise ConfigError(REGISTRY.key, target, f"{allowed} ({REGISTRY.allowed()})")
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
) -> type[Selector]:
    """The selector's parameters (its own check) and the schedule around it (its ``check_schedule``: a pruning
    policy's is one stage of all of U, shuffled, with either a budget or one epoch count). A ConfigError names the
    key; returns the class."""
    cls = selector_class(target)
    cls.check(params, budget=budget, selection_cost=selection_cost)
    name = f"schedule.pruning._target_={target}"
    cls.check_schedule(sizes=list(sizes), order=order, budget=budget, epochs=epochs, name=name)
    return cls
