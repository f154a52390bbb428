"""Typed configuration schema (Hydra structured configs): types here, values in ``configs/`` (:data:`CONFIG_DIR`).

The dataclasses are registered in Hydra's ConfigStore as ``selpres_schema`` and listed first in
``configs/train.yaml``'s defaults, so omegaconf itself rejects unknown keys and wrong types with a
message naming the key. Every value a user reads lives in YAML: a field is ``MISSING`` here when a
config file supplies it, so no default is written twice. Checks that need more than a type (ranges,
values against each other and against the data) live in :mod:`selpres.run.checks`. The nodes that name a
registry's choice (``robot``, ``data``, ``optim``, ``schedule.pruning``) are open here: the chosen class declares
or checks its own keys, so a new choice edits no schema.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, OmegaConf

# The configs: a checkout's top-level configs/, which the wheel maps into the package (selpres/configs/), so a
# checkout and an install compose the same files
_PACKAGE = Path(__file__).resolve().parents[1]
CONFIG_DIR = _PACKAGE / "configs" if (_PACKAGE / "configs").is_dir() else _PACKAGE.parent / "configs"


class EngineName(Enum):
    reference = "reference"  # nn.Module + torch.optim.SGD, one replica at a time: defines correct results
    fast = "fast"  # native if the kernel can be built and run here, else torch (the fallback is recorded)
    native = "native"  # AVX2 C kernel, 4 replicas a vector, built with the system C compiler at first use
    torch = "torch"  # replica-batched eager PyTorch: the pure-torch fallback


@dataclass
class ScheduleConfig:
    name: str = MISSING
    # counts (ints) or fractions of n (floats in (0, 1]); Any keeps 50 and 0.05 apart; null in the parametric form
    sizes: Optional[List[Any]] = None
    epochs: Optional[List[int]] = None
    # total presentations: of a one-stage, compute-matched schedule; in the parametric form split over the stages
    budget: Optional[int] = None
    # the parametric schedule (configs/schedule/stages.yaml, selpres.presentation.proportions): set p, and the sizes
    # and epochs follow from these keys. Null everywhere else: a key left null is not recorded (selpres.run.specs
    # recorded), so the configs written before them keep their identity
    p: Optional[int] = None  # enlargements: p + 1 nested sets
    first: Optional[Any] = None  # n_1: a count, or a share of n in (0, 1)
    growth: Optional[str] = None  # geometric | linear | paper (Table 1's sizes, p = 4)
    profile: Optional[str] = None  # the N_i rule: equal | increasing | decreasing
    total_epochs: Optional[int] = None  # ΣN_i (or budget, or epochs listed)
    order: str = MISSING  # an order of selpres.presentation.orders (its registry) or an import path, checked there
    strata_bins: int = MISSING
    selection_cost: float = MISSING  # presentations charged per candidate scored (selpres.presentation.selection)
    # data pruning every epoch, null: none; else an open node {_target_: a policy of selpres.presentation.pruning
    # (its registry) or an import path, <the policy's parameters>}, which the policy checks itself
    pruning: Optional[Any] = None


@dataclass
class TopologyConfig:
    layers: str = MISSING


@dataclass
class ModelConfig:
    # hidden units: a built-in of selpres.engines.activations (sigmoid, tanh, relu, silu, leaky_relu) or an import path
    activation: str = MISSING


@dataclass
class EvalConfig:
    every: int = MISSING
    heldout_curve: int = MISSING


@dataclass
class LoggingConfig:
    tensorboard: bool = MISSING
    per_replica: bool = MISSING
    progress: bool = MISSING


@dataclass
class CheckpointConfig:
    every: int = MISSING
    enabled: bool = MISSING


@dataclass
class TrainConfig:
    # an open node {_target_: two_link|serial|urdf|package.module.Class, <its parameters>}: the arm source's class
    # checks its own keys (selpres.arms.sources), so a new source edits no schema
    robot: Dict[str, Any] = field(default_factory=dict)
    # an open node {kind: grid|sampled|file|package.module.Class, <the common keys>, <the route's keys>}: the route
    # (selpres.data.routes) declares its keys and their types, which selpres.run.specs checks, so a new route edits
    # no schema
    data: Dict[str, Any] = field(default_factory=dict)
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)
    topology: TopologyConfig = field(default_factory=TopologyConfig)
    # open: ``_target_`` (selpres.engines.optim.OPTIMIZERS: a built-in or an import path) and the optimizer's own
    # keyword arguments, which its class checks (selpres.run.optimizer); these keys say how the engines run it
    optim: Dict[str, Any] = field(
        default_factory=lambda: {
            "sigmoid_prime_offset": 0.0,  # batch mode: added to σ' in the backward pass (Fahlman: 0.1)
            "reduction": "sum",  # batch mode: the epoch's error, summed (Rumelhart's ½Σe²) or mean (mse_loss)
            "lr_schedule": "constant",  # mini-batch: constant, or lr (1 + cos(π c / C)) / 2 over the run's budget C
        }
    )
    model: ModelConfig = field(default_factory=ModelConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    logging: LoggingConfig = field(default_factory=LoggingConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    seed: int = MISSING
    replicas: int = MISSING
    engine: EngineName = MISSING
    threads: int = MISSING
    overwrite: bool = MISSING
    name: str = MISSING


# Spellings users typed that the schema no longer has -> the new spelling (refused in one line by
# selpres.run.main before Hydra composes: Hydra's own refusal of an unknown key does not name the new one)
RETIRED = {
    "schedule.prune_ratio": "schedule.pruning.prune_ratio",
    "schedule.delta": "schedule.pruning.delta",
    "schedule.beta": "schedule.pruning.beta",
}


def retired(overrides: list[str]) -> str | None:
    """The one-line refusal of the first override in ``overrides`` that uses a retired spelling, or None."""
    for arg in overrides:
        key, eq, value = arg.lstrip("+~").partition("=")
        if key in RETIRED:
            return f"{key}{eq}{value} is no longer a key: use {RETIRED[key]}{eq}{value} (the pruning policy's node)"
    return None


def undeclared(c: dict) -> tuple[str, Any, str] | None:
    """(key, value, what is allowed) of the first key of a typed node of the plain config ``c`` that the schema does
    not declare (``+schedule.q=1``, ``+eval.foo=1``, ``+foo=1``), or None. Such a key was appended (Hydra's ``+``)
    and no code reads it: a job that ran with it would record a setting that did not run. The open nodes (robot,
    data, optim, schedule.pruning) are their classes' to check."""
    return _undeclared(c, TrainConfig, "")


def _undeclared(c: dict, schema: type, prefix: str) -> tuple[str, Any, str] | None:
    hints = typing.get_type_hints(schema)
    for k, v in c.items():
        if not prefix and k == "hydra":
            continue
        if k not in hints:
            node = prefix.rstrip(".") or "the config"
            keys = ", ".join(hints)
            return f"{prefix}{k}", v, f"a key {node} declares ({keys}): no code reads {prefix}{k}"
        if dataclasses.is_dataclass(hints[k]) and isinstance(v, dict):
            found = _undeclared(v, hints[k], f"{prefix}{k}.")
            if found:
                return found
    return None


def unread(overrides: list[str]) -> str | None:
    """The one-line refusal of the first command-line override that appends (``+``/``++``) a key to a typed node of
    the schema that declares no such key (``+schedule.q=1,2``), or None: said before Hydra composes or a sweep
    launches anything. Config groups (``+experiment=...``) and the open nodes (checked per job by the class they
    name) pass."""
    for arg in overrides:
        if not arg.startswith("+") or "=" not in arg:
            continue
        key, _, value = arg.lstrip("+").partition("=")
        if "/" in key or key.startswith("hydra") or (CONFIG_DIR / key).is_dir():
            continue
        schema, parts = TrainConfig, key.split(".")
        for i, part in enumerate(parts):
            hints = typing.get_type_hints(schema)
            if part not in hints:
                node = ".".join(parts[:i]) or "the config"
                return f"{key}={value}: {node} has no such key (it declares {', '.join(hints)}): no code would read it"
            if not dataclasses.is_dataclass(hints[part]):
                break
            schema = hints[part]
    return None


def _dirname(overrides: str) -> str:
    """A job folder's name from its overrides ('default' when there are none)."""
    return overrides.replace("/", "_") or "default"


def register() -> None:
    ConfigStore.instance().store(name="selpres_schema", node=TrainConfig)
    if not OmegaConf.has_resolver("dirname"):
        OmegaConf.register_new_resolver("dirname", _dirname)


register()


def compose_train(configs: str | Path, overrides: list[str], hydra: bool = False):
    """The ``train`` config composed from ``configs`` as ``python train.py <overrides>`` composes it (Hydra's
    compose API; the global Hydra state is cleared before and after; ``hydra``: with the ``hydra`` node)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(configs), version_base="1.3"):
            return compose("train", overrides=list(overrides), return_hydra_config=hydra)
    finally:
        GlobalHydra.instance().clear()
