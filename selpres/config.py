"""Typed configuration schema (Hydra structured configs) and the checks a type cannot express.

The dataclasses are registered in Hydra's ConfigStore as ``selpres_schema`` and listed first in
``configs/train.yaml``'s defaults, so omegaconf itself rejects unknown keys and wrong types with a
message naming the key. ``validate`` then checks values against each other and against the data
(topology width, stage sizes vs n, ranges that leave no pattern) before any training or output.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from selpres.data import grid_points
from selpres.errors import ConfigError
from selpres.model import TopologyError, parse_topology


MAX_GRID_CANDIDATES = 50_000_000  # ~3 GB of float64 work arrays in build_exemplar_set
MAX_LAYER_WIDTH = 4096  # the native kernel keeps a layer's activations on the stack (~200 bytes a unit)


class EngineName(Enum):
    reference = "reference"  # nn.Module + torch.optim.SGD, one replica at a time: defines correct results
    fast = "fast"  # the best available of native, then torch (see selpres/engine.py)
    native = "native"  # AVX2 C kernel, 4 replicas a vector, built with gcc at first use
    torch = "torch"  # replica-batched eager PyTorch: the pure-torch fallback


class Order(Enum):
    stratified = "stratified"
    random = "random"


class ScalingMode(Enum):
    exemplar = "exemplar"
    commanded = "commanded"


@dataclass
class RobotConfig:
    m1: float = 0.42
    m2: float = 3.0
    l1: float = 0.2
    l2: float = 0.26
    g: float = 9.81


@dataclass
class GridRange:
    lo: float = 0.0
    hi: float = 1.0
    step: float = 0.1


@dataclass
class ScalingConfig:
    mode: ScalingMode = ScalingMode.exemplar
    margin: float = 0.1
    lo: float = 0.1
    hi: float = 0.9


@dataclass
class DataConfig:
    theta: GridRange = field(default_factory=GridRange)
    dtheta: GridRange = field(default_factory=GridRange)
    tau1: GridRange = field(default_factory=GridRange)
    tau2: GridRange = field(default_factory=GridRange)
    accel_limit: float = 2.0
    test_patterns: int = 10
    test_from_exemplar: int = 5
    heldout: int = 10000
    test_seed: int = 0  # the test sets are part of the benchmark: fixed across seeds and methods (paired comparisons)
    scaling: ScalingConfig = field(default_factory=ScalingConfig)


@dataclass
class ScheduleConfig:
    name: str = "selective"
    # counts (ints) or fractions of n (floats in (0, 1]); Any keeps 50 and 0.05 apart
    sizes: List[Any] = field(default_factory=lambda: [1.0])
    epochs: Optional[List[int]] = None
    budget: Optional[int] = None  # total presentations for a one-stage, compute-matched schedule
    order: Order = Order.stratified
    strata_bins: int = 2


@dataclass
class TopologyConfig:
    layers: str = "6-13-2"


@dataclass
class OptimConfig:
    lr: float = 0.15
    momentum: float = 0.9
    batch_size: int = 1


@dataclass
class EvalConfig:
    every: int = 5  # score the held-out set every this many epochs (and at every stage end); 10-pattern set every epoch
    heldout_curve: int = 2000  # held-out patterns scored for the curves; the final metric uses all of them


@dataclass
class LoggingConfig:
    tensorboard: bool = True
    per_replica: bool = True  # also log each replica's held-out curve (mean/min/max are always logged)
    progress: bool = True


@dataclass
class CheckpointConfig:
    every: int = 10  # epochs between checkpoints (also at every stage boundary); 0 = stage boundaries only
    enabled: bool = True


@dataclass
class TrainConfig:
    robot: RobotConfig = field(default_factory=RobotConfig)
    data: DataConfig = field(default_factory=DataConfig)
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)
    topology: TopologyConfig = field(default_factory=TopologyConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    logging: LoggingConfig = field(default_factory=LoggingConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    seed: int = 0
    replicas: int = 1  # replica r trains with seed + r: one job = many independent runs
    engine: EngineName = EngineName.fast
    threads: int = 0  # torch / kernel threads for this job; 0 = all cores
    overwrite: bool = False  # re-run even if this job's folder already holds a finished result
    name: str = "selpres"


def _dirname(overrides: str) -> str:
    """A job folder's name from its overrides ('default' when there are none)."""
    return overrides.replace("/", "_") or "default"


def register() -> None:
    ConfigStore.instance().store(name="selpres_schema", node=TrainConfig)
    if not OmegaConf.has_resolver("dirname"):
        OmegaConf.register_new_resolver("dirname", _dirname)


register()


def _walk(node, prefix=""):
    """(dotted key, value) for every leaf of a plain container."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _walk(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _walk(v, f"{prefix}[{i}]")
    else:
        yield prefix, node


def validate(cfg: DictConfig) -> tuple[int, ...]:
    """Checks that need more than a type; returns the parsed topology. Raises ConfigError."""
    for key, value in _walk(to_container(cfg)):
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(key, value, "a finite number (NaN and inf are not allowed)")
    o = cfg.optim
    if not o.lr > 0:
        raise ConfigError("optim.lr", o.lr, "a learning rate > 0 (the paper uses 0.15)")
    if not 0 <= o.momentum < 1:
        raise ConfigError("optim.momentum", o.momentum, "a momentum in [0, 1) (the paper uses 0.9)")
    if o.batch_size < 1:
        raise ConfigError("optim.batch_size", o.batch_size, "a whole number >= 1 (1 = online, as in the paper)")
    if cfg.replicas < 1:
        raise ConfigError("replicas", cfg.replicas, "a whole number >= 1")
    if cfg.threads < 0:
        raise ConfigError("threads", cfg.threads, "0 (all cores) or a positive number of threads")
    if cfg.eval.every < 0:
        raise ConfigError("eval.every", cfg.eval.every, "0 (stage ends only) or a positive number of epochs")
    if cfg.eval.heldout_curve < 1:
        raise ConfigError("eval.heldout_curve", cfg.eval.heldout_curve, "a positive number of held-out patterns")
    if cfg.checkpoint.every < 0:
        raise ConfigError("checkpoint.every", cfg.checkpoint.every, "0 (stage boundaries only) or a positive number of epochs")
    if cfg.schedule.strata_bins < 1:
        raise ConfigError("schedule.strata_bins", cfg.schedule.strata_bins, "a whole number >= 1")
    for k in ("m1", "m2", "l1", "l2", "g"):
        if not cfg.robot[k] > 0:
            raise ConfigError(f"robot.{k}", cfg.robot[k], "a positive number")
    d = cfg.data
    points = {}
    for k in ("theta", "dtheta", "tau1", "tau2"):
        r = d[k]
        if not r.step > 0:
            raise ConfigError(f"data.{k}.step", r.step, "a positive grid step")
        if not r.hi >= r.lo:
            raise ConfigError(f"data.{k}.hi", r.hi, f"a value >= data.{k}.lo = {r.lo}")
        try:
            points[k] = grid_points(r.lo, r.hi, r.step, f"data.{k}")
        except ValueError:
            raise ConfigError(f"data.{k}.step", r.step, f"a step that divides hi - lo = {r.hi - r.lo:g} into whole steps") from None
    candidates = points["theta"] ** 2 * points["dtheta"] ** 2 * points["tau1"] * points["tau2"]
    if candidates > MAX_GRID_CANDIDATES:
        finest = max(points, key=points.get)
        raise ConfigError(f"data.{finest}.step", d[finest].step,
                          f"a coarser step: the grid (θ² × θ̇² × τ1 × τ2 points) would have {candidates:,} candidates, "
                          f"at most {MAX_GRID_CANDIDATES:,} are allowed (the paper's has 1,050,625)")
    if not d.accel_limit > 0:
        raise ConfigError("data.accel_limit", d.accel_limit, "a positive acceleration bound in rad/s²")
    if d.test_patterns < 1:
        raise ConfigError("data.test_patterns", d.test_patterns, "a whole number >= 1")
    if not 0 <= d.test_from_exemplar <= d.test_patterns:
        raise ConfigError("data.test_from_exemplar", d.test_from_exemplar, f"a count in [0, data.test_patterns = {d.test_patterns}]")
    if d.heldout < 1:
        raise ConfigError("data.heldout", d.heldout, "a whole number >= 1")
    s = d.scaling
    if not (0 <= s.lo < s.hi <= 1):
        raise ConfigError("data.scaling.lo", s.lo, f"0 <= lo < hi <= 1 (the sigmoid's range); hi = {s.hi}")
    if s.margin < 0:
        raise ConfigError("data.scaling.margin", s.margin, "a margin >= 0 (fraction of each column's range)")
    try:
        sizes = parse_topology(cfg.topology.layers, n_inputs=6, n_outputs=2)
    except TopologyError as e:
        raise ConfigError("topology.layers", cfg.topology.layers, e.allowed) from None
    if max(sizes) > MAX_LAYER_WIDTH:
        raise ConfigError("topology.layers", cfg.topology.layers, f"layer widths of at most {MAX_LAYER_WIDTH} units")
    return sizes


def to_container(cfg: DictConfig) -> dict:
    return OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
