"""A job's selector and ledger from a plain spec: the one place a config's choice of method becomes the object the
loop asks each epoch. ``selpres.run`` reads :class:`SelectorSpec` from ``schedule.*`` and calls :func:`plan` (the
epochs the loop may run) and :func:`build_selector`; nothing else here reads a config.

Which class: ``schedule.pruning._target_`` when set (a pruning policy or any :class:`Selector` subclass, a built-in
by its registry name or a user's by its import path), else the staged presentation of ``schedule.order``
(:class:`~selpres.presentation.staged.Staged`), which every selector is also given as its ``source``. What ran is
named by :func:`identity`: a built-in by its registry name and class path, a user's class by its import path.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass, field

import torch

from selpres.presentation.orders import REGISTRY as ORDERS
from selpres.presentation.orders import make_order
from selpres.presentation.pruning import REGISTRY as SELECTORS
from selpres.presentation.pruning._job import selector_class as named_class
from selpres.presentation.schedule import Schedule
from selpres.presentation.selector import Ledger, Selector
from selpres.presentation.staged import Staged
from selpres.registry import Registry


@dataclass(frozen=True)
class SelectorSpec:
    """What decides a job's epochs, as plain values (``schedule.order``, ``schedule.strata_bins``,
    ``schedule.selection_cost``, and the ``schedule.pruning`` node's ``_target_`` and other keys)."""

    order: str = "stratified"
    strata_bins: int = 2
    selection_cost: float = 1 / 3
    target: str | None = None  # None: the staged presentation of ``order``
    params: Mapping = field(default_factory=dict)


def selector_class(spec: SelectorSpec) -> type[Selector]:
    return Staged if spec.target is None else named_class(spec.target)


def plan(spec: SelectorSpec, node: Mapping, n: int) -> tuple[Schedule, str | None, int | None]:
    """The epochs the loop may run on U of ``n`` patterns from the ``schedule`` node (plain values), as the
    selector's class plans them (the configured stages, or a pruning policy's one stage), how named counts were
    applied, and the budget per replica its ledger runs against (None: the plan's epochs)."""
    return selector_class(spec).schedule(node, n, dict(spec.params), spec.selection_cost)


def build_selector(
    spec: SelectorSpec,
    schedule: Schedule,
    seeds: list[int],
    X_raw: torch.Tensor,
    X: torch.Tensor,
    Y: torch.Tensor,
    budget: int | None,
) -> tuple[Selector, Ledger]:
    """The job's selector and its fresh ledger (``budget``: presentations per replica, :func:`plan`'s, or None).
    ``X_raw``: U's raw inputs (the orders' space); ``X``, ``Y``: U scaled (what the networks see)."""
    epochs = None if budget is not None else schedule.total_epochs
    ledger = Ledger(schedule.n, seeds, budget, epochs, spec.selection_cost)
    order = make_order(spec.order, spec.strata_bins)
    staged = Staged(order, schedule, seeds, X_raw, X, Y, spec.selection_cost)
    if spec.target is None:
        selector = staged
    else:
        cls = named_class(spec.target)
        selector = cls(cls.check(dict(spec.params), budget=budget, selection_cost=spec.selection_cost), ledger)
        selector.source = staged
    ran = [("selector", SELECTORS, type(selector)), ("order", ORDERS, type(order))]
    selector.identity = identity(ran)
    selector.name = selector.identity["name"]
    return selector, ledger


def identity(ran: list[tuple[str, Registry | None, type]]) -> dict:
    """results.json's names of the classes that ran: for each role, its name (a built-in's registry name; a user's
    import path; the staged selector's ``staged``), its class path; and ``user_classes``, the import paths of the
    classes no registry of the package holds (what names a user's method apart)."""
    out, own = {}, []
    for role, registry, cls in ran:
        path = f"{cls.__module__}.{cls.__qualname__}"
        name = "staged" if cls is Staged else _builtin_name(registry, cls)
        if name is None:
            name = path
            own.append(path)
        prefix = "" if role == "selector" else f"{role}_"
        out[f"{prefix}name"], out[f"{prefix}class"] = name, path
    return {**out, "user_classes": own}


def _builtin_name(registry: Registry, cls: type) -> str | None:
    """The registry name under which the package exports ``cls``, or None (a user's class)."""
    module = cls.__module__
    pkg, _, name = module.rpartition(".")
    if pkg != registry.package or name not in registry.names:
        return None
    return name if getattr(sys.modules.get(module), registry.entry, None) is cls else None
