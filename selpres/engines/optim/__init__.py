"""The optimizers: the speed-up methods of the paper's section 2 and today's rules, as ``torch.optim`` classes.

The paper (section 2) names four ways to train a BPN faster; selective presentation is compared with
them. Each is a ``torch.optim.Optimizer`` here (the definition of correct), stepped once per epoch by
:class:`selpres.engines.batch.BatchEngine` (batch mode) or on every mini-batch by
:class:`selpres.engines.minibatch.MiniBatchEngine`:

* momentum (Rumelhart et al.): ``sgd`` -- online in :mod:`selpres.engines.online`, mini-batch or batch;
* QuickProp (Fahlman 1988): :class:`QuickProp`, with the sigmoid-prime offset as a backward-pass
  option, :func:`offset_sigmoid`;
* Delta-Bar-Delta (Jacobs 1988): :class:`DeltaBarDelta`;
* the modern references ``rprop`` (Riedmiller & Braun 1993), ``adam`` (Kingma & Ba 2015) and ``adamw``
  (Loshchilov & Hutter 2019), torch's own classes;
* Samad's "expected source values" (1988): absent, see below.

Each optimizer is one module here exporting ``OPTIMIZER`` (a ``torch.optim.Optimizer`` subclass): the registry
:data:`OPTIMIZERS` lists the modules (``optim._target_: adam`` names ``adam.py``), so adding one is a module
and a YAML in ``configs/optim/``. A user's own is named by its import path (``optim._target_:
torch.optim.NAdam``, ``mylion.Lion``). A class takes the config's flat keys as keyword arguments (a built-in's
``hparams`` checks them, with their defaults, without building an optimizer: the first
``torch.optim.Optimizer`` of a process imports torch._dynamo, about 1.3 s, which a job on the native engine
never needs); its ``MODES`` say how it may run (``_base``: online, mini-batch, batch). Keys whose value is
``None`` are left at the optimizer's default.

**Elementwise rules only.** The engines step one optimizer over the replicas' stacked ``[R, ...]`` weights
(selpres.engines.batch, selpres.engines.minibatch): a rule that moves every weight from its own gradient and
state (SGD, Adam, AdamW, NAdam, RAdam, Adamax, Adagrad, Adadelta, RMSprop, Rprop, ASGD, QuickProp,
Delta-Bar-Delta, Lion) is then R separate optimizers (tested). A rule that looks across weights would couple
the replicas and is refused by name (:data:`NOT_ELEMENTWISE`); a user's class may say so itself with
``ELEMENTWISE = False``.

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

import inspect

import torch

from selpres.engines.optim._base import DEFAULT_MODES
from selpres.engines.optim._offset import offset_sigmoid
from selpres.engines.optim.delta_bar_delta import DeltaBarDelta
from selpres.engines.optim.quickprop import QuickProp
from selpres.errors import ConfigError
from selpres.registry import Registry

__all__ = [
    "OPTIMIZERS",
    "DeltaBarDelta",
    "QuickProp",
    "offset_sigmoid",
    "check_hparams",
    "make_optimizer",
    "keyword_defaults",
    "modes",
    "with_defaults",
]

KEY = "optim._target_"
OPTIMIZERS = Registry(KEY, "selpres.engines.optim", "OPTIMIZER")

# torch.optim's rules that are not elementwise: on the replicas' stacked weights they would mix the replicas
NOT_ELEMENTWISE = {
    "LBFGS": "its line search and curvature history span all weights (and it needs a closure)",
    "Adafactor": "its second moments are factored over a matrix's rows and columns",
    "Muon": "it orthogonalises each matrix's update (Newton-Schulz iterations)",
    "SparseAdam": "it takes sparse gradients only",
}


def optimizer_class(target: str) -> type:
    """The class ``optim._target_`` names: a ``torch.optim.Optimizer`` with an elementwise rule, or ConfigError."""
    cls = OPTIMIZERS.get(target)
    if not (isinstance(cls, type) and issubclass(cls, torch.optim.Optimizer)):
        raise ConfigError(KEY, target, f"a torch.optim.Optimizer subclass ({target} is {cls!r})")
    torch_name = next((n for n in NOT_ELEMENTWISE if getattr(torch.optim, n, None) is cls), None)
    if torch_name or getattr(cls, "ELEMENTWISE", True) is False:
        why = NOT_ELEMENTWISE[torch_name] if torch_name else "its class says ELEMENTWISE = False"
        raise ConfigError(KEY, target, f"an elementwise rule, as the replicas' weights are stepped stacked: {why}")
    return cls


def modes(target: str) -> tuple[str, ...]:
    """How the optimizer may run: its class's ``MODES`` (a user's own: mini-batch and batch)."""
    return tuple(getattr(optimizer_class(target), "MODES", DEFAULT_MODES))


def keywords(cls: type) -> tuple[list[str], bool]:
    """The keyword arguments a class takes from the config (a built-in: its ``hparams``; else its constructor
    after ``params``), and whether it takes any (``**kwargs``)."""
    fn = cls.hparams if hasattr(cls, "hparams") else cls.__init__
    ps = list(inspect.signature(fn).parameters.values())
    if not hasattr(cls, "hparams"):
        ps = ps[2:]  # self, params
    named = [p.name for p in ps if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    return named, any(p.kind == p.VAR_KEYWORD for p in ps)


def keyword_defaults(cls: type) -> dict:
    """The defaults of the keyword arguments a class takes from the config (those it has; see :func:`keywords`)."""
    fn = cls.hparams if hasattr(cls, "hparams") else cls.__init__
    return {p.name: p.default for p in inspect.signature(fn).parameters.values() if p.default is not p.empty}


def with_defaults(target: str, hparams: dict | None = None) -> dict:
    """The optimizer's flat config keys with a built-in's defaults for the unset ones (a user's class: the keys
    given), what both mini-batch engines take, so an unset key (AdamW's weight_decay 0.01) is the same on either."""
    cls = optimizer_class(target)
    given = {k: v for k, v in (hparams or {}).items() if v is not None}
    if not hasattr(cls, "hparams"):
        return given
    ps = inspect.signature(cls.hparams).parameters.values()
    return {**{p.name: p.default for p in ps if p.default is not inspect.Parameter.empty}, **given}


def check_hparams(target: str, hparams: dict | None = None) -> dict:
    """The keyword arguments of optimizer ``target`` from flat config keys (``None`` = its default), checked.

    Every error is a :class:`~selpres.errors.ConfigError` naming ``optim.<key>``, the value and what is
    allowed: an unknown optimizer, a key its class does not take, or a value out of range. A built-in is
    checked by its ``hparams`` without building an optimizer; a user's class by building one on a dummy weight.
    """
    cls = optimizer_class(target)
    given = {k: v for k, v in (hparams or {}).items() if v is not None}
    named, any_key = keywords(cls)
    for key in given:
        if key not in named and not any_key:
            path = f"{cls.__module__}.{cls.__qualname__}"
            where = target if target == path else f"{target} ({path})"
            raise ConfigError(
                f"optim.{key}", given[key], f"no value: {where} does not take it (its keys: {', '.join(named)})"
            )
    if hasattr(cls, "hparams"):
        try:
            return cls.hparams(**given)
        except ConfigError as e:
            raise ConfigError(f"optim.{e.key}", e.value, e.allowed) from None
    try:
        cls([torch.zeros(1, dtype=torch.float64, requires_grad=True)], **given)
    except (ValueError, TypeError) as e:
        raise ConfigError(KEY, target, f"keyword arguments {target} accepts: {e}") from None
    return given


def make_optimizer(target: str, params, hparams: dict | None = None) -> torch.optim.Optimizer:
    """The optimizer ``target`` (a built-in name or an import path) over ``params``, from flat config keys,
    checked as :func:`check_hparams` checks them."""
    check_hparams(target, hparams)
    return optimizer_class(target)(params, **{k: v for k, v in (hparams or {}).items() if v is not None})
