"""The config's ``optim`` node as a plain spec, and how the optimizer it names may run.

``optim`` is an open node: ``_target_`` names the optimizer (a built-in of :mod:`selpres.engines.optim` or a
class by its import path), ``batch_size``, ``reduction``, ``lr_schedule`` and ``sigmoid_prime_offset`` say how
the engines run it, and every other key is the optimizer's own keyword argument, which its class checks (so a
new optimizer edits no schema). Which modes it runs in (online, mini-batch, batch) is its class's ``MODES``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from omegaconf import DictConfig, OmegaConf

from selpres.engines.batch import check_batch_options
from selpres.engines.minibatch import LR_SCHEDULES
from selpres.engines.optim import KEY, OPTIMIZERS, check_hparams, keywords, modes, optimizer_class
from selpres.engines.optim._base import BATCH, MINIBATCH, ONLINE
from selpres.errors import ConfigError
from selpres.run.config import CONFIG_DIR
from selpres.run.specs import plain

log = logging.getLogger(__name__)
HOW = ("batch_size", "reduction", "lr_schedule", "sigmoid_prime_offset")  # the engines' keys, not the optimizer's


@dataclass(frozen=True)
class OptimSpec:
    """What the engines need of ``optim``: the optimizer, its keyword arguments (None values left out) and how
    it runs. ``dropped``: keys of the group file the job composed that the chosen class does not take (a
    ``_target_`` given on the command line over ``optim=paper`` leaves its ``momentum`` behind)."""

    target: str
    params: dict
    batch_size: int
    reduction: str
    lr_schedule: str
    sigmoid_prime_offset: float
    dropped: dict = field(default_factory=dict)

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
    target = OPTIMIZERS.check(o["_target_"])
    b = o.get("batch_size")
    if isinstance(b, bool) or not isinstance(b, int) or b < 0:
        raise ConfigError(
            "optim.batch_size", b, "0 (the whole epoch) or a whole number >= 1 (1 = online, as in the paper)"
        )
    if o["lr_schedule"] not in LR_SCHEDULES:
        raise ConfigError("optim.lr_schedule", o["lr_schedule"], f"one of {', '.join(LR_SCHEDULES)}")
    offset, reduction = check_batch_options(o["sigmoid_prime_offset"], o["reduction"])
    params = {k: v for k, v in o.items() if k != "_target_" and k not in HOW and v is not None}
    dropped = _left_by_the_group_file(target, params)
    return OptimSpec(
        target=target,
        params={k: v for k, v in params.items() if k not in dropped},
        batch_size=b,
        reduction=reduction,
        lr_schedule=o["lr_schedule"],
        sigmoid_prime_offset=offset,
        dropped=dropped,
    )


_group_file: str | None = None  # the optim group option of the CLI job running in this process (run_job sets it)


def composed_from(choice: str | None) -> None:
    """Called by the CLI for every job with Hydra's choice of the ``optim`` group (``paper``, ``adam``, ...)."""
    global _group_file
    _group_file = choice


def _left_by_the_group_file(target: str, params: dict) -> dict:
    """Keys the class does not take whose values are those of the ``optim`` group file the CLI job composed, when
    that file names another optimizer: what ``optim._target_=torch.optim.NAdam`` leaves of ``optim=paper``
    (momentum 0.9). Outside a CLI job (the compose API), nothing: every key is checked."""
    path = CONFIG_DIR / "optim" / f"{_group_file}.yaml"
    if not _group_file or not path.is_file():
        return {}
    group = OmegaConf.to_container(OmegaConf.load(path))
    if group.get("_target_") == target:
        return {}
    named, any_key = keywords(optimizer_class(target))
    if any_key:
        return {}
    return {k: v for k, v in params.items() if k not in named and k in group and group[k] == v}


def minibatch_reason(cfg: DictConfig) -> str | None:
    """Why a job needs a mini-batch engine (the native mini-batch kernel, selpres.engines.native_minibatch, or the
    torch one, selpres.engines.minibatch) rather than the online SGD engines (native kernel / torch / reference),
    or None: the online kernel runs sigmoid units and SGD with momentum at a constant rate, nothing else (pruned
    epochs too: per-replica counts, weighted patterns)."""
    spec = optim_spec(cfg)
    if spec.batch:
        return None
    why = []
    if ONLINE not in spec.modes:
        why.append(f"optim._target_={spec.target}")
    if cfg.model.activation != "sigmoid":
        why.append(f"model.activation={cfg.model.activation}")
    if spec.lr_schedule != "constant":
        why.append(f"optim.lr_schedule={spec.lr_schedule}")
    if not why:
        return None
    return "the online kernel runs sigmoid units and SGD at a constant rate only; this job has " + ", ".join(why)


def check_optim(cfg: DictConfig) -> OptimSpec:
    """The optimizer and how it runs, against itself, the model, the schedule and the engine asked for."""
    spec = optim_spec(cfg)
    check_hparams(spec.target, spec.params)  # ConfigError naming optim.<key>
    for k, v in spec.dropped.items():
        log.warning("optim.%s=%r left out: the optim group file's, and %s does not take it", k, v, spec.target)
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
    reason = minibatch_reason(cfg)
    if reason and cfg.engine.value not in ("fast", "native", "torch"):
        raise ConfigError(
            "engine",
            cfg.engine.value,
            f"fast, native or torch: {reason} (the mini-batch engines: native kernel or torch)",
        )
    if spec.batch and cfg.engine.value not in ("fast", "torch"):
        raise ConfigError(
            "engine",
            cfg.engine.value,
            f"fast or torch with optim._target_={spec.target} and "
            f"optim.batch_size={b}: batch mode runs replica-batched in torch",
        )
    return spec
