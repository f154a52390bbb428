"""The config's ``optim`` node as a plain spec, and how the optimizer it names may run.

``optim`` is an open node: ``_target_`` names the optimizer (a built-in of :mod:`selpres.engines.optim`, by its
import path or its alias, or a class of your own by its import path), ``batch_size``, ``reduction``,
``lr_schedule`` and ``sigmoid_prime_offset`` say how the engines run it, and every other key is the optimizer's own
keyword argument: a key its class does not take is refused, naming the key and the class, as Hydra's
``instantiate`` refuses it (so a new optimizer edits no schema). When ``optim._target_`` names another class than
the group file the job composed (``optim=adam optim._target_=mylion.Lion``), that file's keys are still the node's:
one the class does not take is refused saying which file set it, and one it takes with a value other than its own
default is said in the log, never handed over in silence. Which modes the optimizer runs in (online, mini-batch,
batch) is its class's ``MODES``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from omegaconf import DictConfig, OmegaConf

from selpres.engines.batch import check_batch_options
from selpres.engines.factory import EngineSpec, check_request, mode_for
from selpres.engines.minibatch import LR_SCHEDULES
from selpres.engines.optim import KEY, OPTIMIZERS, check_hparams, keyword_defaults, modes, optimizer_class
from selpres.engines.optim._base import BATCH, MINIBATCH, ONLINE
from selpres.errors import ConfigError
from selpres.run.config import CONFIG_DIR
from selpres.run.specs import plain

log = logging.getLogger(__name__)
HOW = ("batch_size", "reduction", "lr_schedule", "sigmoid_prime_offset")  # the engines' keys, not the optimizer's


@dataclass(frozen=True)
class OptimSpec:
    """What the engines need of ``optim``: the optimizer (a built-in's alias, or an import path), its keyword
    arguments (None values left out) and how it runs."""

    target: str
    params: dict
    batch_size: int
    reduction: str
    lr_schedule: str
    sigmoid_prime_offset: float

    @property
    def modes(self) -> tuple[str, ...]:
        return modes(self.target)

    @property
    def batch(self) -> bool:
        """One optimizer step per epoch (selpres.engines.batch) rather than online/mini-batch training."""
        return self.batch_size == 0 or not ({ONLINE, MINIBATCH} & set(self.modes))

    @property
    def path(self) -> str:
        """The import path of the class that runs (results.json ``optimizer``)."""
        return OPTIMIZERS.path_of(self.target)


def optim_spec(cfg: DictConfig) -> OptimSpec:
    """``cfg.optim`` as an :class:`OptimSpec`, its keys' types checked (ConfigError naming ``optim.<key>``)."""
    o = plain(cfg.optim)
    if "name" in o:  # the spelling before optim._target_
        raise ConfigError(
            "optim.name", o["name"], f"no key: renamed, write optim._target_={o['name']} (or optim=<file>)"
        )
    if "_target_" not in o:
        raise ConfigError(KEY, None, OPTIMIZERS.allowed())
    target = OPTIMIZERS.canonical(OPTIMIZERS.check(o["_target_"]))
    b = o.get("batch_size")
    if isinstance(b, bool) or not isinstance(b, int) or b < 0:
        raise ConfigError(
            "optim.batch_size", b, "0 (the whole epoch) or a whole number >= 1 (1 = online, as in the paper)"
        )
    if o["lr_schedule"] not in LR_SCHEDULES:
        raise ConfigError("optim.lr_schedule", o["lr_schedule"], f"one of {', '.join(LR_SCHEDULES)}")
    offset, reduction = check_batch_options(o["sigmoid_prime_offset"], o["reduction"])
    params = {k: v for k, v in o.items() if k != "_target_" and k not in HOW and v is not None}
    return OptimSpec(target, params, b, reduction, o["lr_schedule"], offset)


_group_file_name: str | None = None  # the optim group option of the CLI job running in this process (run_job sets it)


def composed_from(choice: str | None) -> None:
    """Called by the CLI for every job with Hydra's choice of the ``optim`` group (``paper``, ``adam``, ...)."""
    global _group_file_name
    _group_file_name = choice


def _group_file() -> tuple[str, dict] | None:
    """(name, keys) of the ``optim`` group file the CLI job composed, or None (the compose API: no file known)."""
    path = CONFIG_DIR / "optim" / f"{_group_file_name}.yaml"
    if not _group_file_name or not path.is_file():
        return None
    return _group_file_name, OmegaConf.to_container(OmegaConf.load(path))


def _of_another_class(spec: OptimSpec) -> tuple[str, dict] | None:
    """The composed group file, when it was written for another optimizer than ``spec``'s (else None)."""
    group = _group_file()
    if group is None or OPTIMIZERS.canonical(group[1].get("_target_")) == spec.target:
        return None
    return group


def check_keys(spec: OptimSpec) -> dict:
    """The optimizer's keyword arguments checked by its class (ConfigError naming ``optim.<key>`` and the class;
    a key from another optimizer's group file says so). A value such a file hands the class over its own default
    is said in one warning line."""
    group = _of_another_class(spec)
    try:
        hp = check_hparams(spec.target, spec.params)
    except ConfigError as e:
        key = e.key.removeprefix("optim.")
        if group is None or key not in group[1] or group[1][key] != spec.params.get(key):
            raise
        hint = f"; optim={group[0]}'s file sets it: drop it with '~optim.{key}', or pick a group file for this class"
        raise ConfigError(e.key, e.value, e.allowed + hint) from None
    if group is not None:
        defaults = keyword_defaults(optimizer_class(spec.target))
        taken = [k for k, v in spec.params.items() if group[1].get(k) == v and k in defaults and defaults[k] != v]
        if taken:
            over = ", ".join(f"{k}={spec.params[k]!r} (its default: {defaults[k]!r})" for k in taken)
            log.warning("optim=%s's file hands %s %s", group[0], OPTIMIZERS.path_of(spec.target), over)
    return hp


def engine_spec(cfg: DictConfig) -> EngineSpec:
    """What the job's engine is built from, but the network's sizes and the run's planned cost (known once the task
    is): the engine asked for, the mode the optimizer, units and rate need (selpres.engines.factory.mode_for), the
    optimizer and how it runs."""
    o = optim_spec(cfg)
    activation = cfg.model.activation
    mode, why = mode_for(o.target, o.modes, o.batch_size, activation, o.lr_schedule)
    return EngineSpec(
        requested=cfg.engine.value,
        mode=mode,
        optimizer=o.target,
        hparams=o.params,
        batch_size=o.batch_size,
        activation=activation,
        lr_schedule=o.lr_schedule,
        reduction=o.reduction,
        sigmoid_prime_offset=o.sigmoid_prime_offset,
        why=why,
    )


def check_optim(cfg: DictConfig) -> OptimSpec:
    """The optimizer and how it runs, against itself, the model, the schedule and the engine asked for."""
    spec = optim_spec(cfg)
    check_keys(spec)  # ConfigError naming optim.<key> and the class
    b, runs = spec.batch_size, spec.modes
    if b == 0 and BATCH not in runs:
        raise ConfigError("optim.batch_size", b, f"a whole number >= 1: {spec.target} runs on mini-batches only")
    if b >= 1 and not ({ONLINE, MINIBATCH} & set(runs)):
        raise ConfigError("optim.batch_size", b, "0 (the whole epoch): a batch method")
    act = cfg.model.activation
    if spec.batch and act != "sigmoid":
        raise ConfigError("model.activation", act, "sigmoid in batch mode (optim.batch_size=0), or a mini-batch")
    if spec.batch and spec.lr_schedule != "constant":
        raise ConfigError("optim.lr_schedule", spec.lr_schedule, "constant in batch mode (optim.batch_size=0)")
    es = engine_spec(cfg)
    check_request(es.requested, es.mode, es.why)  # ConfigError naming engine (reference with Adam, ...)
    return spec
