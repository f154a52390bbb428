"""Dynamic data pruning: selectors that choose each epoch's patterns from the network's losses, charged on the
paper's cost axis (issue 22). Selective presentation decides *before* each stage which patterns to present; the
methods it competes with today decide every epoch.

A policy is one module here exporting ``POLICY = <class>`` (``infobatch``, ``selective_backprop``, ...), named in
a config as ``schedule.pruning: {_target_: <module name>, <its parameters>}``; a user's own is named by its import
path (``_target_: my_pruning.RandomPruning``). The class subclasses :class:`Policy` (``_policy``), a
:class:`~selpres.presentation.selector.Selector` that refines each epoch's shuffle of U, and checks its own
parameters; any other ``Selector`` subclass may be named the same way. What every policy shares lives in the
``_``-prefixed modules: ``_policy`` (the interface, δ-annealing), ``_job`` (the class a node names, the checks of
its parameters and of the schedule around it).

Light on purpose: :mod:`selpres.presentation.arguments` reads the registry's names from here, and nothing here
imports the heavy modules (which import the sampler, which imports the arguments).
"""

from __future__ import annotations

from selpres.registry import Registry

REGISTRY = Registry("schedule.pruning._target_", "selpres.presentation.pruning", "POLICY")


# what a policy of your own builds from (``_policy``)
PUBLIC = ("Policy", "ScoredByLoss", "EpochChoice", "Param", "Annealing", "Ledger")


def __getattr__(name: str):
    """The pieces of ``_policy`` a user's own policy builds from, imported only when asked for (torch)."""
    if name in PUBLIC:
        from selpres.presentation.pruning import _policy

        return getattr(_policy, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
