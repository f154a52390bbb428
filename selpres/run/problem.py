"""The problem a config determines before the first update: validated data, schedule, the selector and its ledger,
initial weights (``prepare``, which writes nothing), and the engine that will train it (``job_engine``). The loop
that runs it is ``selpres.run.train``.
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass

import torch
from omegaconf import DictConfig

from selpres.data.file import DataFileError
from selpres.data.task import Task, load_task
from selpres.engines.batch import BatchEngine
from selpres.engines.model import init_replica_params
from selpres.engines.native_minibatch import NAME as NATIVE_MINIBATCH
from selpres.engines.native_minibatch import make_minibatch_engine
from selpres.engines.online import make_engine
from selpres.engines.optim import check_hparams, with_defaults
from selpres.errors import ConfigError
from selpres.patterns import Scaler
from selpres.presentation.build import SelectorSpec, build_selector, plan
from selpres.presentation.sampler import SelectivePresentation
from selpres.presentation.schedule import EpochPlan, Schedule
from selpres.presentation.selector import Ledger, Selector
from selpres.run.checks import pruning_spec, validate
from selpres.run.estimate import refuse_job
from selpres.run.optimizer import minibatch_reason, optim_spec
from selpres.run.specs import plain, task_specs
from selpres.seeding import derive_seed

log = logging.getLogger("selpres")


@dataclass
class Problem:
    """Everything a config determines before the first update."""

    sizes: tuple[int, ...]
    schedule: Schedule
    seeds: list[int]
    scaler: Scaler
    X: torch.Tensor  # exemplar inputs, scaled
    Y: torch.Tensor  # exemplar targets, scaled
    tests: dict  # name -> (X scaled, Y in Nm)
    init_params: list[torch.Tensor]
    selector: Selector  # what decides every epoch's presentations (selpres.presentation.selector)
    ledger: Ledger  # what the replicas have cost so far: charged by the selector and the loop, checkpointed
    task: Task | None = None  # names of the columns, and task.info: what data was made, how (for results)
    schedule_note: str | None = None  # how a named schedule's counts were applied to this n (None: as given)
    budget: float | None = None  # the run's own planned cost (presentations): the cosine schedule's horizon

    @property
    def samplers(self) -> list[SelectivePresentation]:
        """Each replica's sampler of the schedule's nested sets (whose shuffles every selector presents from)."""
        return self.selector.source.samplers

    @functools.cached_property
    def plan(self) -> list[EpochPlan]:
        return self.schedule.plan()

    @functools.cached_property
    def stage_ends(self) -> frozenset[int]:
        return frozenset(self.schedule.stage_ends())

    @functools.cached_property
    def scored(self) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
        """name -> (inputs, targets), both scaled: what the engines score (tests holds targets in Nm)."""
        return {name: (X, self.scaler.transform_y(Y)) for name, (X, Y) in self.tests.items()}

    @functools.cached_property
    def nm_per_scaled(self) -> torch.Tensor:
        """Nm per scaled unit of each output (the scaler is affine): scaled errors times this are errors in Nm."""
        return (self.scaler.y_max - self.scaler.y_min) / (self.scaler.hi - self.scaler.lo)

    @functools.cached_property
    def nm2_per_scaled2(self) -> torch.Tensor:
        """Its square: what sums of squared scaled errors are multiplied by to be in Nm^2."""
        return self.nm_per_scaled.square()


def prepare(cfg: DictConfig) -> Problem:
    """Validate ``cfg`` against itself and against the exemplar set; raises ConfigError, writes nothing."""
    sizes = validate(cfg)
    task = load_task(*task_specs(cfg))
    schedule, note, budget = task_schedule(cfg, task)
    # scored in torch: batch methods, the mini-batch engine (what the native kernel cannot run), torch/reference
    torch_eval = (
        optim_spec(cfg).batch or minibatch_reason(cfg) is not None or cfg.engine.value in ("torch", "reference")
    )
    largest_test = max(len(task.tests.heldout.X), len(task.tests.test10.X))
    refuse_job(cfg, sizes, schedule, task.n, largest_test, torch_eval)  # before any replica's state is made
    seed = int(cfg.seed)  # read once: an OmegaConf access costs ~20 us, 1000 of them 23 ms at R = 1000
    seeds = [seed + r for r in range(cfg.replicas)]
    X, Y = task.scaler.transform_x(task.exemplar.X), task.scaler.transform_y(task.exemplar.Y)
    selector, ledger = build_selector(selector_spec(cfg), schedule, seeds, task.exemplar.X, X, Y, budget)
    return Problem(
        sizes=sizes,
        schedule=schedule,
        seeds=seeds,
        scaler=task.scaler,
        X=X,
        Y=Y,
        tests=task.scaled_tests(),
        init_params=init_replica_params(sizes, [derive_seed(s, "init") for s in seeds]),
        selector=selector,
        ledger=ledger,
        task=task,
        schedule_note=note,
        budget=budget if budget is not None else schedule.presentations + selector.planned_charge(schedule),
    )


def selector_spec(cfg: DictConfig) -> SelectorSpec:
    """``schedule.*`` as the plain spec the presentation room builds a job's selector from."""
    s = cfg.schedule
    target, params = pruning_spec(s) or (None, {})
    return SelectorSpec(str(s.order), int(s.strata_bins), float(s.selection_cost), target, params)


def task_schedule(cfg: DictConfig, task: Task) -> tuple[Schedule, str | None, int | None]:
    """The schedule on the task's n as the job's selector plans it (listed or parametric, the paper's counts by their
    proportions when n is not 1002: ``selpres.presentation.proportions``, logged), how named counts were applied,
    and the budget the selector runs against (None: the plan's epochs); a data file too short for the schedule named
    as such."""
    sch = plain(cfg.schedule)
    try:
        schedule, note, budget = plan(selector_spec(cfg), sch, task.n)
        if note:
            log.info(note)
        return schedule, note, budget
    except ConfigError as e:
        if e.key == "schedule.sizes" and task.info.get("kind") == "file":
            i = task.info
            raise DataFileError(
                i["path"],
                "rows",
                f"{i['rows']:,} rows ({task.n:,} for training after "
                f"holding out {i['heldout']:,}): too few for schedule.sizes={sch['sizes']} "
                f"({e.allowed})",
            ) from None
        raise


def engine_kind(cfg: DictConfig) -> str:
    """The update a config's job runs: ``minibatch`` (selpres.engines.minibatch), ``batch`` (one step an epoch)
    or ``online`` (the native, torch and reference engines: one update rule)."""
    if minibatch_reason(cfg) is not None:
        return "minibatch"
    return "batch" if optim_spec(cfg).batch else "online"


def kind_of(engine_name: str | None) -> str:
    """:func:`engine_kind` of an engine that ran (results.json ``engine``; records older than it name none)."""
    if engine_name == NATIVE_MINIBATCH:  # the mini-batch update, run by the native kernel
        return "minibatch"
    return engine_name if engine_name in ("minibatch", "batch") else "online"


def job_engine(cfg: DictConfig, prob: Problem):
    """The engine the config asks for; ``engine=native`` where the kernel cannot run is a user error.
    Batch methods (QuickProp, Delta-Bar-Delta, Rprop, Adam, batch SGD) step once per epoch in torch."""
    from selpres.native import KernelUnavailable

    o = optim_spec(cfg)
    kind = engine_kind(cfg)
    if kind == "minibatch":  # the native mini-batch kernel (fast, native) or the torch mini-batch engine (torch)
        log.info("engine=%s: the mini-batch update (%s)", cfg.engine.value, minibatch_reason(cfg))
        try:
            return make_minibatch_engine(
                cfg.engine.value,
                prob.sizes,
                prob.init_params,
                o.target,
                with_defaults(o.target, o.params),  # the optimizer's defaults for unset keys, for both engines
                o.batch_size,
                cfg.model.activation,
                o.lr_schedule,
                prob.budget,
                o.reduction,
            )
        except KernelUnavailable as exc:
            raise ConfigError(
                "engine", "native", f"fast or torch: the native mini-batch kernel cannot run this job ({exc})"
            ) from None
    if kind == "batch":
        return BatchEngine(
            prob.sizes,
            prob.init_params,
            o.target,
            o.params,
            sigmoid_prime_offset=o.sigmoid_prime_offset,
            reduction=o.reduction,
        )
    try:
        hp = check_hparams(o.target, o.params)  # the online rule, SGD with momentum: lr, momentum
        return make_engine(cfg.engine.value, prob.sizes, prob.init_params, hp["lr"], hp["momentum"], o.batch_size)
    except KernelUnavailable as exc:
        raise ConfigError(
            "engine", cfg.engine.value, f"fast, torch or reference: the native kernel cannot run here ({exc})"
        ) from None
