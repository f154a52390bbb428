"""The speed-up methods of the paper's section 2 as ``torch.optim`` optimizers, for batch-mode training.

The paper (section 2) names four ways to train a BPN faster; selective presentation is compared with
them. Each is a ``torch.optim.Optimizer`` here (the definition of correct), stepped once per epoch by
:class:`selpres.engines.batch.BatchEngine`:

* momentum (Rumelhart et al.): ``torch.optim.SGD`` -- online in :mod:`selpres.engines.online`, or batch here;
* QuickProp (Fahlman 1988): :class:`QuickProp`, with the sigmoid-prime offset as a backward-pass
  option, :func:`offset_sigmoid`;
* Delta-Bar-Delta (Jacobs 1988): :class:`DeltaBarDelta`;
* the modern references ``torch.optim.Rprop`` (Riedmiller & Braun 1993) and ``torch.optim.Adam``
  (Kingma & Ba 2015);
* Samad's "expected source values" (1988): absent, see below.

Config keys (flat, so that each can be swept and named in an error): ``sgd``: lr, momentum;
``quickprop``: lr, mu, weight_decay; ``delta_bar_delta``: lr, kappa, phi, theta, momentum;
``rprop``: lr, eta_minus, eta_plus, step_min, step_max; ``adam``, ``adamw``: lr, beta1, beta2, eps,
weight_decay. Mini-batch SGD/Adam/AdamW (``optim.batch_size`` >= 1) step replica by replica in
:mod:`selpres.engines.optim.replica`.
Keys whose value is ``None`` are left at the optimizer's default.

**Why Samad's rule is absent.** The paper cites Samad [6] only as compensating "not only present weight
changes but future expected changes as well" by "expected source values", and reports (after Godhwani
[2]) that it did not appear to converge at low learning rates; its reference list is not in our copy
of the paper. The stored public sources (web pages, documentation, public code, issue threads) were
searched for its published form: "Samad 1988 expected source values back-propagation"; "Samad expected
value of the source unit weight update backpropagation INNS 1988"; a title remembered for it but not
confirmed by any source ("Back-propagation is significantly faster if the expected value of the source
unit is used for update"); and "expected source value" as an exact string in public code. Nothing
matched: no paper, abstract, textbook restatement or implementation states its update rule. Without its
equations an implementation would be a guess carrying Samad's name, so selpres leaves it out rather
than compare selective presentation against an invention.
"""

from __future__ import annotations

import torch

from selpres.engines.optim._base import require
from selpres.engines.optim.delta_bar_delta import DeltaBarDelta
from selpres.engines.optim.offset import offset_sigmoid
from selpres.engines.optim.quickprop import QuickProp
from selpres.errors import ConfigError

__all__ = [
    "DeltaBarDelta",
    "QuickProp",
    "offset_sigmoid",
    "checked_hparams",
    "make_optimizer",
    "OPTIMIZER_KEYS",
    "HPARAM_KEYS",
]

OPTIMIZER_KEYS = {
    "sgd": ("lr", "momentum"),
    "quickprop": ("lr", "mu", "weight_decay"),
    "delta_bar_delta": ("lr", "kappa", "phi", "theta", "momentum"),
    "rprop": ("lr", "eta_minus", "eta_plus", "step_min", "step_max"),
    "adam": ("lr", "beta1", "beta2", "eps", "weight_decay"),
    "adamw": ("lr", "beta1", "beta2", "eps", "weight_decay"),
}
HPARAM_KEYS = tuple(sorted(set().union(*OPTIMIZER_KEYS.values())))  # pass them all: unused ones must be None


def _sgd(lr=0.15, momentum=0.0) -> dict:
    return dict(
        lr=require("lr", lr, "a learning rate > 0", lambda v: v > 0),
        momentum=require("momentum", momentum, "a momentum in [0, 1)", lambda v: 0 <= v < 1),
    )


def _rprop(lr=0.1, eta_minus=0.5, eta_plus=1.2, step_min=1e-6, step_max=50.0) -> dict:
    step_min = require("step_min", step_min, "a smallest update value >= 0 (1e-6)", lambda v: v >= 0)
    return dict(
        lr=require("lr", lr, "an initial update value > 0 (Riedmiller & Braun: 0.1)", lambda v: v > 0),
        eta_minus=require("eta_minus", eta_minus, "a decrease factor in (0, 1) (0.5)", lambda v: 0 < v < 1),
        eta_plus=require("eta_plus", eta_plus, "an increase factor > 1 (1.2)", lambda v: v > 1),
        step_min=step_min,
        step_max=require(
            "step_max", step_max, f"a largest update value >= step_min = {step_min:g} (50)", lambda v: v >= step_min
        ),
    )


def _adam(lr=1e-3, beta1=0.9, beta2=0.999, eps=1e-8, weight_decay=0.0) -> dict:
    return dict(
        lr=require("lr", lr, "a step size > 0 (Kingma & Ba: 0.001)", lambda v: v > 0),
        beta1=require("beta1", beta1, "a decay rate in [0, 1) (0.9)", lambda v: 0 <= v < 1),
        beta2=require("beta2", beta2, "a decay rate in [0, 1) (0.999)", lambda v: 0 <= v < 1),
        eps=require("eps", eps, "a denominator offset > 0 (1e-8)", lambda v: v > 0),
        weight_decay=require("weight_decay", weight_decay, "a weight decay >= 0", lambda v: v >= 0),
    )


# name -> (its hyperparameters checked, with defaults; the optimizer built from them). The checks are
# separate so that validating a config builds no optimizer: the first torch.optim.Optimizer of a process
# imports torch._dynamo, about 1.3 s, which a job on the native engine never needs.
_OPTIMIZERS = {
    "sgd": (_sgd, lambda params, lr, momentum: torch.optim.SGD(params, lr=lr, momentum=momentum)),
    "quickprop": (QuickProp.hparams, QuickProp),
    "delta_bar_delta": (DeltaBarDelta.hparams, DeltaBarDelta),
    "rprop": (
        _rprop,
        lambda params, lr, eta_minus, eta_plus, step_min, step_max: torch.optim.Rprop(
            params, lr=lr, etas=(eta_minus, eta_plus), step_sizes=(step_min, step_max)
        ),
    ),
    "adam": (
        _adam,
        lambda params, lr, beta1, beta2, eps, weight_decay: torch.optim.Adam(
            params, lr=lr, betas=(beta1, beta2), eps=eps, weight_decay=weight_decay
        ),
    ),
    "adamw": (
        lambda lr=1e-3, beta1=0.9, beta2=0.999, eps=1e-8, weight_decay=0.01: _adam(lr, beta1, beta2, eps, weight_decay),
        lambda params, lr, beta1, beta2, eps, weight_decay: torch.optim.AdamW(
            params, lr=lr, betas=(beta1, beta2), eps=eps, weight_decay=weight_decay
        ),
    ),
}


def checked_hparams(name: str, hparams: dict | None = None) -> dict:
    """The hyperparameters of optimizer ``name`` from flat config keys (``None`` = its default), checked.

    Every error is a :class:`~selpres.errors.ConfigError` naming ``optim.<key>``, the value and what
    is allowed: an unknown name, a key the optimizer does not use, or a value out of range.
    """
    if name not in _OPTIMIZERS:
        raise ConfigError("optim.name", name, f"one of {', '.join(_OPTIMIZERS)}")
    given = {k: v for k, v in (hparams or {}).items() if v is not None}
    for key in given:
        if key not in OPTIMIZER_KEYS[name]:
            raise ConfigError(
                f"optim.{key}",
                given[key],
                f"no value: {name} does not use it (its keys: {', '.join(OPTIMIZER_KEYS[name])})",
            )
    try:
        return _OPTIMIZERS[name][0](**given)
    except ConfigError as e:
        raise ConfigError(f"optim.{e.key}", e.value, e.allowed) from None


def make_optimizer(name: str, params, hparams: dict | None = None) -> torch.optim.Optimizer:
    """The optimizer ``name`` (a key of :data:`OPTIMIZER_KEYS`) over ``params``, from flat config keys,
    checked as :func:`checked_hparams` checks them."""
    checked = checked_hparams(name, hparams)
    return _OPTIMIZERS[name][1](params, **checked)
