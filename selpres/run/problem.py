"""The problem a resolved job determines before the first update: validated data, schedule, samplers, initial
weights (``prepare``, which writes nothing), and the engine that will train it (``job_engine``, through
``selpres.engines.factory.build_engine``). It reads the job's specs (``selpres.run.resolve.JobSpec``), never the
config. The loop that runs it is ``selpres.run.train``.
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass

import torch

from selpres.data.file import DataFileError
from selpres.data.task import Task, load_task
from selpres.engines.factory import ONLINE, Engine, build_engine
from selpres.engines.model import init_replica_params
from selpres.errors import ConfigError
from selpres.patterns import Scaler
from selpres.presentation.orders import make_order
from selpres.presentation.proportions import fit_schedule, schedule_of
from selpres.presentation.pruning._job import Pruning, pruning_plan
from selpres.presentation.sampler import SelectivePresentation
from selpres.presentation.schedule import EpochPlan, Schedule
from selpres.presentation.selection import StageSelection, stage_selection
from selpres.run.estimate import Work, refuse_job
from selpres.run.resolve import engine_kind, kind_of
from selpres.run.specs import JobSpec, ScheduleSpec
from selpres.seeding import derive_seed, generator

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
    samplers: list[SelectivePresentation]
    init_params: list[torch.Tensor]
    selection: StageSelection | None = None  # a stage-wise order (loss_high, reselect, ...): A_k chosen per stage
    task: Task | None = None  # names of the columns, and task.info: what data was made, how (for results)
    schedule_note: str | None = None  # how a named schedule's counts were applied to this n (None: as given)
    pruning: Pruning | None = None  # a pruning policy (schedule.pruning): each epoch's patterns chosen by loss
    budget: float | None = None  # the run's own planned cost (presentations): the cosine schedule's horizon

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


def prepare(job: JobSpec) -> Problem:
    """The resolved job against the exemplar set; raises ConfigError, writes nothing."""
    task = load_task(job.robot, job.data)
    sch = job.schedule
    schedule, note = task_schedule(sch, task)
    # scored in torch: batch methods, the mini-batch engine (what the native kernel cannot run), torch/reference
    torch_eval = job.engine.mode != ONLINE or job.engine.requested in ("torch", "reference")
    largest_test = max(len(task.tests.heldout.X), len(task.tests.test10.X))
    work = Work(job.replicas, job.sizes, sch, schedule, task.n, largest_test, job.cadence.heldout_every, torch_eval)
    refuse_job(work)  # before any replica's state is made
    seeds = job.seeds
    order = make_order(sch.order, sch.strata_bins)
    orders = order.orders(task.exemplar.X, [generator(s, "subset") for s in seeds])
    samplers = [SelectivePresentation(order=order, schedule=schedule, seed=s) for order, s in zip(orders, seeds)]
    X, Y = task.scaler.transform_x(task.exemplar.X), task.scaler.transform_y(task.exemplar.Y)
    pruning, budget = None, schedule.presentations + order.planned_charge(schedule.sizes, sch.selection_cost)
    if sch.pruning is not None:
        fitted = fit_schedule(sch.sizes, sch.budget, task.n)[1]
        epochs = None if sch.epochs is None else int(sch.epochs[0])
        pruning = Pruning(*sch.pruning, task.n, seeds, fitted, epochs, float(sch.selection_cost))
        budget = fitted if fitted is not None else task.n * epochs
    sizes = job.sizes
    return Problem(
        sizes=sizes,
        schedule=schedule,
        seeds=seeds,
        scaler=task.scaler,
        X=X,
        Y=Y,
        tests=task.scaled_tests(),
        samplers=samplers,
        init_params=init_replica_params(sizes, [derive_seed(s, "init") for s in seeds]),
        selection=stage_selection(order, schedule, seeds, task.exemplar.X, X, Y, sch.selection_cost, samplers),
        task=task,
        schedule_note=note,
        pruning=pruning,
        budget=budget,
    )


def task_schedule(sch: ScheduleSpec, task: Task) -> tuple[Schedule, str | None]:
    """The schedule on the task's n: the paper's counts by their proportions when n is not 1002
    (``selpres.presentation.proportions``, logged), refusals with the fraction form, and a data file too short for
    the schedule named as such."""
    if sch.pruning is not None:  # checked in resolve: sizes [1.0], a budget or one epoch count
        sizes, budget, note = fit_schedule(sch.sizes, sch.budget, task.n)
        if note:
            log.info(note)
        epochs = None if sch.epochs is None else int(sch.epochs[0])
        return pruning_plan(*sch.pruning, task.n, budget, epochs, float(sch.selection_cost)), note
    try:
        schedule, note = schedule_of(sch.node, task.n)  # listed or parametric (selpres.presentation.proportions)
        if note:
            log.info(note)
        return schedule, note
    except ConfigError as e:
        if e.key == "schedule.sizes" and task.info.get("kind") == "file":
            i = task.info
            raise DataFileError(
                i["path"],
                "rows",
                f"{i['rows']:,} rows ({task.n:,} for training after "
                f"holding out {i['heldout']:,}): too few for schedule.sizes={sch.sizes} "
                f"({e.allowed})",
            ) from None
        raise


def job_engine(job: JobSpec, prob: Problem) -> Engine:
    """The engine the job asks for, its replicas from the problem's initial weights, its planned cost the problem's
    (a cosine rate's horizon): ``selpres.engines.factory.build_engine`` chooses, and falls back once saying why."""
    return build_engine(job.engine.replace(horizon=prob.budget), prob.init_params)


__all__ = ["Problem", "prepare", "task_schedule", "job_engine", "engine_kind", "kind_of"]  # the last two: run/cli's
