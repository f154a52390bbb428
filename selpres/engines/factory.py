"""The one way to an engine: what every engine offers the loop (:class:`Engine`), which engines there are
(:data:`ENGINES`, by mode and implementation), which mode a job's optimizer needs (:func:`mode_for`), and
:func:`build_engine`, which chooses, falls back once with the reason, and leaves on the engine what ran.

A **mode** is the update an epoch makes: ``online`` (SGD with momentum on mini-batches of ``batch_size``, sigmoid
units, a constant rate: the paper's rule, ``batch_size`` 1), ``minibatch`` (any elementwise optimizer, any hidden
units, a rate schedule) or ``batch`` (one optimizer step an epoch). An **implementation** computes a mode:
``reference`` (one ``nn.Module`` and ``torch.optim`` optimizer per replica: the definition of correct), ``torch``
(every replica at once, eager torch) or ``native`` (the C kernels of :mod:`selpres.native`). A request (the config's
``engine``) names an implementation, or ``fast``: ``native`` where the mode has a kernel and it can run here, else
``torch``; when the kernel cannot run, the torch engine's ``fallback_reason`` says why and one warning is logged.
``native`` where the kernel cannot run is a ConfigError naming ``engine``, never a silent fallback.

An engine is built from an :class:`EngineSpec` (plain values; ``selpres.run`` makes it from the config) by its
class's ``from_spec(spec, params)``.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import torch

from selpres.engines.batch import BatchEngine
from selpres.engines.minibatch import MiniBatchEngine
from selpres.engines.native_minibatch import NativeMiniBatchEngine
from selpres.engines.online import NativeEngine, ReferenceEngine, TorchEngine
from selpres.engines.optim._base import BATCH, MINIBATCH, ONLINE
from selpres.errors import ConfigError
from selpres.native import KernelUnavailable

log = logging.getLogger("selpres")

MODES = (ONLINE, MINIBATCH, BATCH)
IMPLEMENTATIONS = ("reference", "torch", "native")
REQUESTS = ("fast", "native", "torch", "reference")  # the config's ``engine``: an implementation, or fast
KEY = "engine"


class Engine(Protocol):
    """What the loop, the checkpoints and the results ask of an engine: R replicas of one network, trained an
    epoch at a time. :class:`selpres.engines.online.ReferenceEngine` defines the online mode's numbers; every other
    engine of that mode gives the same ones faster."""

    name: str  # the engine that ran (results.json ``engine``): reference, torch, native, minibatch, ...
    fallback_reason: str | None  # why ``fast`` did not run natively (None: it did, or the mode has no kernel)
    evaluation: str  # what runs the scoring's forward passes (native: its vector width), for results.json
    last_losses: torch.Tensor  # [R, m]: each presented pattern's loss before its update, after a pruned epoch

    def train_epoch(self, X, Y, order, weights=None, counts=None, spent=None) -> torch.Tensor:
        """The one epoch call: replica r presents ``order[r, :counts[r]]`` (all of ``order[r]`` without counts),
        each pattern's loss weighted by ``weights`` (1 without), at its rate for the cost ``spent[r]`` it has
        already spent (a constant rate ignores it). Returns each replica's mean loss [R]; a pruned epoch (counts or
        weights given) leaves its per-pattern losses in ``last_losses`` (NaN past ``counts[r]``)."""

    def predict(self, X: torch.Tensor) -> torch.Tensor:
        """[N, in] -> [R, N, out] float64: every replica's scaled outputs."""

    def squared_errors(self, X: torch.Tensor, Y: torch.Tensor) -> torch.Tensor:
        """[R, out] float64: per replica and output, the sum over the patterns of (output - Y)^2 (scaled units)."""

    def finite(self) -> torch.Tensor:
        """[R] bool: every weight of replica r is finite (the divergence check)."""

    def params(self) -> list[torch.Tensor]:
        """Copies of the weights [W1, b1, ...], each with the replicas first."""

    def state_dict(self) -> dict:
        """Everything a resume needs (weights, the optimizer's state), as tensors and plain values."""

    def load_state_dict(self, state: dict) -> None: ...


@dataclass(frozen=True)
class EngineSpec:
    """What an engine is built from, as plain values. ``hparams``: the optimizer's keyword arguments as the config
    gives them (unset ones left out: each engine fills the class's defaults as its optimizer does); ``horizon``: the
    run's planned cost in presentations, a cosine rate's C; ``why``: why the job runs in this mode (logged)."""

    requested: str = "fast"
    mode: str = ONLINE
    sizes: tuple[int, ...] = ()
    optimizer: str = "sgd"
    hparams: Mapping[str, Any] = field(default_factory=dict)
    batch_size: int = 1
    activation: str = "sigmoid"
    lr_schedule: str = "constant"
    horizon: float = 1.0
    reduction: str = "mean"
    sigmoid_prime_offset: float = 0.0
    threads: int | None = None  # the native kernels' OS threads (None: $SELPRES_THREADS or torch's)
    why: str | None = None

    def replace(self, **changes) -> EngineSpec:
        return dataclasses.replace(self, **changes)

    @classmethod
    def online(cls, requested: str, sizes, lr: float, momentum: float, batch_size: int = 1, threads=None):
        """The paper's rule, SGD at ``lr`` with ``momentum`` on mini-batches of ``batch_size``, on ``requested``."""
        hp = {"lr": lr, "momentum": momentum}
        return cls(requested, ONLINE, tuple(sizes), "sgd", hp, batch_size, threads=threads)


# (mode, implementation) -> the class; each offers ``from_spec(spec, params)`` and meets :class:`Engine`
ENGINES: dict[tuple[str, str], type] = {
    (ONLINE, "reference"): ReferenceEngine,
    (ONLINE, "torch"): TorchEngine,
    (ONLINE, "native"): NativeEngine,
    (MINIBATCH, "torch"): MiniBatchEngine,
    (MINIBATCH, "native"): NativeMiniBatchEngine,
    (BATCH, "torch"): BatchEngine,
}


def mode_for(
    optimizer: str, optimizer_modes: tuple[str, ...], batch_size: int, activation: str, lr_schedule: str
) -> tuple[str, str | None]:
    """(mode, why) of a job: ``batch`` when it steps once an epoch (``batch_size`` 0, or an optimizer that runs in
    batch mode only); ``online`` (why None) when the online engines can run it (an optimizer whose ``MODES`` has
    online: SGD; sigmoid units; a constant rate); else ``minibatch``, ``why`` naming what the online engines lack."""
    if batch_size == 0 or not ({ONLINE, MINIBATCH} & set(optimizer_modes)):
        return BATCH, f"optim._target_={optimizer} with optim.batch_size={batch_size}: one step an epoch, in torch"
    lacks = []
    if ONLINE not in optimizer_modes:
        lacks.append(f"optim._target_={optimizer}")
    if activation != "sigmoid":
        lacks.append(f"model.activation={activation}")
    if lr_schedule != "constant":
        lacks.append(f"optim.lr_schedule={lr_schedule}")
    if not lacks:
        return ONLINE, None
    return MINIBATCH, "the online kernel runs sigmoid units and SGD at a constant rate only; this job has " + ", ".join(
        lacks
    )


def implementations(mode: str) -> tuple[str, ...]:
    """The implementations registered for ``mode``, in :data:`IMPLEMENTATIONS` order."""
    return tuple(i for i in IMPLEMENTATIONS if (mode, i) in ENGINES)


def allowed_requests(mode: str) -> tuple[str, ...]:
    """What ``engine`` may be for a job of ``mode``: fast and the mode's implementations."""
    return ("fast", *(i for i in ("native", "torch", "reference") if (mode, i) in ENGINES))


def check_request(requested: str, mode: str, why: str | None = None) -> None:
    """ConfigError naming ``engine`` when ``requested`` is not one of :data:`REQUESTS`, or names an implementation
    that ``mode`` does not have (``engine=reference`` with Adam on mini-batches; ``engine=native`` in batch mode)."""
    allowed = allowed_requests(mode)
    if requested in allowed:
        return
    if requested not in REQUESTS:
        raise ConfigError(KEY, requested, f"one of {', '.join(REQUESTS)}")
    because = f"{why}; " if why else ""
    has = _either(implementations(mode))
    raise ConfigError(KEY, requested, f"{_either(allowed)}: {because}the {mode} update runs on {has} only")


def _either(items) -> str:
    items = list(items)
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} or {items[-1]}"


def build_engine(spec: EngineSpec, params: list[torch.Tensor]) -> Engine:
    """The engine ``spec`` asks for, its replicas starting from ``params`` ([W1, b1, ...], replicas first).

    ``fast`` builds the mode's native engine where it has one, and where the kernel cannot run (no compiler, no AVX2,
    ``SELPRES_NO_NATIVE``, an optimizer or unit the kernel lacks) its torch engine, whose ``fallback_reason`` says
    why (one warning logged). ``native`` where the kernel cannot run: ConfigError naming ``engine``."""
    if spec.mode not in MODES:
        raise ValueError(f"mode {spec.mode!r}: one of {', '.join(MODES)}")
    check_request(spec.requested, spec.mode, spec.why)
    sizes = tuple(int(s) for s in spec.sizes)
    if len(params) != 2 * (len(sizes) - 1):
        raise ValueError(f"{len(params)} parameter tensors for topology {sizes}: expected {2 * (len(sizes) - 1)}")
    if spec.mode != BATCH and int(spec.batch_size) < 1:
        raise ValueError(f"batch_size must be >= 1 in {spec.mode} mode, got {spec.batch_size}")
    if spec.why:
        log.info("engine=%s: the %s update (%s)", spec.requested, spec.mode, spec.why)
    spec = spec.replace(sizes=sizes)
    impl = spec.requested
    if impl == "fast":
        impl = "native" if (spec.mode, "native") in ENGINES else "torch"
    try:
        return ENGINES[(spec.mode, impl)].from_spec(spec, params)
    except KernelUnavailable as exc:
        if spec.requested != "fast":
            others = _either(r for r in allowed_requests(spec.mode) if r != impl)
            raise ConfigError(
                KEY, impl, f"{others}: the native {spec.mode} kernel cannot run this job ({exc})"
            ) from None
        engine = ENGINES[(spec.mode, "torch")].from_spec(spec, params)
        engine.fallback_reason = str(exc)
        line = " ".join(str(exc).split())  # one line, however long the compiler's message
        log.warning(
            "engine 'fast' runs the %s engine: the native %s kernel cannot run this job: %s",
            engine.name,
            spec.mode,
            line if len(line) <= 400 else line[:400] + " ...",
        )
        return engine


def mode_of(engine_name: str | None) -> str:
    """The mode of an engine that ran, by the name results.json records (``engine``; records older than that field
    name none: the online engines ran them)."""
    for (mode, _), cls in ENGINES.items():
        if cls.name == engine_name:
            return mode
    return ONLINE
