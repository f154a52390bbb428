"""Hidden units: one module per activation, found by the registry :data:`ACTIVATIONS` (``model.activation``).

A built-in is a module here exporting ``ACTIVATION``, a class with static ``forward(z)`` and ``prime(z, a)``
(d activation / dz from the pre-activation z and the activation a: the mini-batch engine's hand-written
backward). ``sigmoid`` is the paper's BPN: sigmoid hidden *and* output units (``SIGMOID_OUTPUT``); with any
other the output layer is linear (a regression head). A user's own is a class with the same two methods,
named by its import path (``model.activation=myunits.GELU``); it runs on the mini-batch engine.
"""

from __future__ import annotations

from selpres.errors import ConfigError
from selpres.registry import Registry

ACTIVATIONS = Registry("model.activation", "selpres.engines.activations", "ACTIVATION")


def activation(name: str) -> type:
    """The class ``model.activation`` names, with ``forward`` and ``prime``, or a ConfigError."""
    cls = ACTIVATIONS.get(name)
    if not all(callable(getattr(cls, m, None)) for m in ("forward", "prime")):
        raise ConfigError("model.activation", name, "a class with static forward(z) and prime(z, a)")
    return cls
