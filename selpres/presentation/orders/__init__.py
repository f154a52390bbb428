"""Orders: how the training sets A1 ⊂ A2 ⊂ … ⊂ U grow, named in a config as ``schedule.order=<name>``.

An order is one module here exporting ``ORDER = <class>`` (``stratified``, the paper's; ``random``; ``coverage``;
``loss_high``, ``loss_low``, ``reselect``); a user's own is named by its import path (``schedule.order=
my_orders.Reversed``), and results.json records the class that ran (``schedule.order_class``). Two interfaces, one
kind: an order fixed before training subclasses :class:`Order` (``_order``) and gives each replica a permutation of
U whose prefixes are the A_i; a stage-wise order subclasses :class:`StagewiseOrder` (``_stagewise``) and chooses A_k
at stage k's start, from the network's losses or afresh, saying how many candidates it scores (each charged
``schedule.selection_cost`` of a presentation). ``_loss`` is what the two loss orders share.

Light on purpose: the registry lists the modules without importing them; the order's module is imported when a
job or a sampler asks for it. Orders may import torch, numpy, ``selpres.errors``, ``selpres.seeding``, and of this
room ``schedule``, ``partition`` and ``selection`` (the network's scores); never the sampler (it imports this
package) nor a selector (the ``staged`` selector runs them).
"""

from __future__ import annotations

import torch

from selpres.registry import Registry

REGISTRY = Registry("schedule.order", "selpres.presentation.orders", "ORDER")

PUBLIC = {"Order": "_order", "StagewiseOrder": "_stagewise", "selection_charge": "_order"}  # for a user's own


def make_order(name: str, strata_bins: int = 2):
    """The order ``name`` (a built-in or an import path) for ``schedule.strata_bins``; ConfigError if there is none
    or it is not an order."""
    from selpres.errors import ConfigError
    from selpres.presentation.orders._order import Order

    cls = REGISTRY.get(name)
    if not (isinstance(cls, type) and issubclass(cls, Order)):
        where = "selpres.presentation.orders.Order or StagewiseOrder"
        raise ConfigError(REGISTRY.key, name, f"a subclass of {where} ({REGISTRY.allowed()})")
    return cls(strata_bins)


def fixed_orders() -> tuple[str, ...]:
    """The built-in orders fixed before training (a sampler can present them without the training loop)."""
    return tuple(name for name in REGISTRY.names if not REGISTRY.get(name).stagewise)


def priority_orders(X: torch.Tensor, kind: str, gens: list[torch.Generator], bins: int = 2) -> list[torch.Tensor]:
    """One priority order of U (X: [n, inputs]) per generator (one per replica), computed together where that is
    cheaper (coverage); each equals ``priority_order`` with that generator alone. A stage-wise order's: the
    orders a job starts from."""
    return make_order(kind, bins).orders(X, gens)


def priority_order(X: torch.Tensor, kind: str, gen: torch.Generator, bins: int = 2) -> torch.Tensor:
    """A permutation of U's indices (X: [n, inputs]) whose prefixes are the nested training sets."""
    return priority_orders(X, kind, [gen], bins)[0]


def planned_charge(kind: str, sizes: list[int], fraction: float) -> int:
    """Presentations a schedule of stage ``sizes`` (counts, the last = n) will be charged per replica for choosing
    in order ``kind`` (``Order.planned_charge``)."""
    return make_order(kind).planned_charge(sizes, fraction)


def __getattr__(name: str):
    """The interfaces a user's own order builds from, imported only when asked for."""
    if name in PUBLIC:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{PUBLIC[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
