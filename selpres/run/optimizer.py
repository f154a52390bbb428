"""How the optimizer a job names may run: its keys against its class, its modes against the units and the engine.

``optim`` is an open node (read into ``selpres.run.specs.OptimSpec``): ``_target_`` names the optimizer (a built-in
of :mod:`selpres.engines.optim`, by its import path or its alias, or a class of your own by its import path),
``batch_size``, ``reduction``, ``lr_schedule`` and ``sigmoid_prime_offset`` say how the engines run it, and every
other key is the optimizer's own keyword argument: a key its class does not take is refused, naming the key and the
class, as Hydra's ``instantiate`` refuses it (so a new optimizer edits no schema). When ``optim._target_`` names
another class than the group file the job composed (``optim=adam optim._target_=mylion.Lion``), that file's keys are
still the node's: one the class does not take is refused saying which file set it, and one it takes with a value
other than its own default is said in the log, never handed over in silence. Which modes the optimizer runs in
(online, mini-batch, batch) is its class's ``MODES``.
"""

from __future__ import annotations

import logging

from omegaconf import OmegaConf

from selpres.engines.factory import EngineSpec, check_request
from selpres.engines.optim import OPTIMIZERS, check_hparams, keyword_defaults, optimizer_class
from selpres.engines.optim._base import BATCH, MINIBATCH, ONLINE
from selpres.errors import ConfigError
from selpres.run.config import CONFIG_DIR
from selpres.run.specs import OptimSpec

log = logging.getLogger(__name__)


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


def check_optim(spec: OptimSpec, engine: EngineSpec) -> None:
    """The optimizer and how it runs, against itself, the hidden units and the engine asked for."""
    check_keys(spec)  # ConfigError naming optim.<key> and the class
    b, runs = spec.batch_size, spec.modes
    if b == 0 and BATCH not in runs:
        raise ConfigError("optim.batch_size", b, f"a whole number >= 1: {spec.target} runs on mini-batches only")
    if b >= 1 and not ({ONLINE, MINIBATCH} & set(runs)):
        raise ConfigError("optim.batch_size", b, "0 (the whole epoch): a batch method")
    if spec.batch and engine.activation != "sigmoid":
        raise ConfigError(
            "model.activation", engine.activation, "sigmoid in batch mode (optim.batch_size=0), or a mini-batch"
        )
    if spec.batch and spec.lr_schedule != "constant":
        raise ConfigError("optim.lr_schedule", spec.lr_schedule, "constant in batch mode (optim.batch_size=0)")
    check_request(engine.requested, engine.mode, engine.why)  # ConfigError naming engine (reference with Adam, ...)
