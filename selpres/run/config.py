"""Typed configuration schema (Hydra structured configs): types here, values in ``selpres/configs/``.

The dataclasses are registered in Hydra's ConfigStore as ``selpres_schema`` and listed first in
``configs/train.yaml``'s defaults, so omegaconf itself rejects unknown keys and wrong types with a
message naming the key. Every value a user reads lives in YAML: a field is ``MISSING`` here when a
config file supplies it, so no default is written twice. Checks that need more than a type (ranges,
values against each other and against the data) live in :mod:`selpres.run.checks`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, OmegaConf

CONFIG_DIR = Path(__file__).resolve().parents[1] / "configs"  # shipped in the package (wheel and checkout alike)


class EngineName(Enum):
    reference = "reference"  # nn.Module + torch.optim.SGD, one replica at a time: defines correct results
    fast = "fast"  # native if the kernel can be built and run here, else torch (the fallback is recorded)
    native = "native"  # AVX2 C kernel, 4 replicas a vector, built with the system C compiler at first use
    torch = "torch"  # replica-batched eager PyTorch: the pure-torch fallback


class ScalingMode(Enum):
    exemplar = "exemplar"
    commanded = "commanded"


@dataclass
class GridRange:
    lo: float = MISSING
    hi: float = MISSING
    step: float = MISSING


@dataclass
class ScalingConfig:
    mode: ScalingMode = MISSING
    margin: float = MISSING
    lo: float = MISSING
    hi: float = MISSING


class DataKind(Enum):
    grid = "grid"  # the paper's section 5.1 (robot=two_link): a grid of θ, θ̇, τ kept if |θ̈| <= limit
    sampled = "sampled"  # any arm, any n: random or low-discrepancy draws (selpres.data.sampled)
    file = "file"  # the user's own table, CSV or .npz (selpres.data.file)


class Route(Enum):
    forward = "forward"  # the paper's route: q, q̇, τ drawn, q̈ simulated (eq. 5), |q̈| > accel_limit dropped
    inverse = "inverse"  # q, q̇, q̈ drawn, τ from eq. (4); kept unless data.tau bounds it


class Draw(Enum):
    uniform = "uniform"  # pseudo-random points (a seeded torch.Generator)
    sobol = "sobol"  # scrambled Sobol points (torch.quasirandom.SobolEngine): every prefix low-discrepancy


@dataclass
class DataConfig:
    """One schema for every data kind: the group file sets ``kind`` and its keys; the others stay None
    (``selpres.run.checks`` refuses a key a kind does not read, naming it)."""

    kind: DataKind = MISSING
    theta: Optional[GridRange] = None  # grid: both joints' angles (rad) and rates (rad/s), the torque boxes
    dtheta: Optional[GridRange] = None
    tau1: Optional[GridRange] = None
    tau2: Optional[GridRange] = None
    accel_limit: Optional[float] = None  # grid, sampled: |q̈| bound (rad/s²): a filter or q̈'s box (inverse)
    n: Optional[int] = None  # sampled: exemplar set size
    route: Optional[Route] = None
    draw: Optional[Draw] = None
    seed: Optional[int] = None  # sampled: the exemplar set's draws (the test sets draw from test_seed)
    q: Optional[List[Any]] = None  # sampled: [lo, hi] for every joint or one per joint; q null: joint limits
    dq: Optional[List[Any]] = None
    tau: Optional[List[Any]] = None  # sampled: torque box (forward: drawn from it; inverse: a filter)
    wrench: Optional[List[float]] = None  # sampled: constant k of eq. (4), base frame, (force, moment)
    path: Optional[str] = None  # file: a CSV with a header row, or an .npz
    inputs: Optional[List[str]] = None  # file: the columns the network reads, in this order
    outputs: Optional[List[str]] = None  # file: the columns it predicts
    test_patterns: int = MISSING
    test_from_exemplar: int = MISSING
    heldout: Any = MISSING  # a count, or a fraction (float in (0, 1)) of all patterns (file: of the rows)
    test_seed: int = MISSING
    scaling: ScalingConfig = field(default_factory=ScalingConfig)


@dataclass
class ScheduleConfig:
    name: str = MISSING
    # counts (ints) or fractions of n (floats in (0, 1]); Any keeps 50 and 0.05 apart
    sizes: List[Any] = MISSING
    epochs: Optional[List[int]] = None
    budget: Optional[int] = None  # total presentations for a one-stage, compute-matched schedule
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
    # hidden units: a built-in of selpres.engines.activations (sigmoid, tanh, relu, silu) or a class by its import path
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
    data: DataConfig = field(default_factory=DataConfig)
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
# selpres.run.guard before Hydra composes: Hydra's own refusal of an unknown key does not name the new one)
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
