"""The problem a resolved job determines before the first update: validated data, schedule, the selector and its
ledger, initial weights (``prepare``, which writes nothing), and the engine that will train it (``job_engine``,
through ``selpres.engines.factory.build_engine``). It reads the job's specs (``selpres.run.specs.JobSpec``), never
the config. The loop that runs it is ``selpres.run.train``.
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
from selpres.presentation.build import build_selector, plan
from selpres.presentation.sampler import SelectivePresentation
from selpres.presentation.schedule import EpochPlan, Schedule
from selpres.presentation.selector import Ledger, Selector
from selpres.run.estimate import Work, refuse_job
from selpres.run.resolve import engine_kind, kind_of
from selpres.run.specs import JobSpec, ScheduleSpec
from selpres.seeding import derive_seed

log = logging.getLogger("selpres")


@dataclass
class Problem:
    """Everything a job determines before the first update."""

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


def prepare(job: JobSpec) -> Problem:
    """The resolved job against the exemplar set; raises ConfigError, writes nothing."""
    task = load_task(job.robot, job.data)
    sch = job.schedule
    schedule, note, budget = task_schedule(sch, task)
    # scored in torch: batch methods, the mini-batch engine (what the native kernel cannot run), torch/reference
    torch_eval = job.engine.mode != ONLINE or job.engine.requested in ("torch", "reference")
    largest_test = max(len(task.tests.heldout.X), len(task.tests.test10.X))
    work = Work(job.replicas, job.sizes, sch, schedule, task.n, largest_test, job.cadence.heldout_every, torch_eval)
    refuse_job(work)  # before any replica's state is made
    seeds, sizes = job.seeds, job.sizes
    X, Y = task.scaler.transform_x(task.exemplar.X), task.scaler.transform_y(task.exemplar.Y)
    selector, ledger = build_selector(sch.selector, schedule, seeds, task.exemplar.X, X, Y, budget)
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


def task_schedule(sch: ScheduleSpec, task: Task) -> tuple[Schedule, str | None, int | None]:
    """The schedule on the task's n as the job's selector plans it (listed or parametric, the paper's counts by their
    proportions when n is not 1002: ``selpres.presentation.proportions``, logged; a pruning policy's one stage),
    how named counts were applied, and the budget the selector runs against (None: the plan's epochs); a data file
    too short for the schedule named as such."""
    try:
        schedule, note, budget = plan(sch.selector, sch.node, task.n)
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
                f"holding out {i['heldout']:,}): too few for schedule.sizes={sch.sizes} "
                f"({e.allowed})",
            ) from None
        raise


def job_engine(job: JobSpec, prob: Problem) -> Engine:
    """The engine the job asks for, its replicas from the problem's initial weights, its planned cost the problem's
    (a cosine rate's horizon): ``selpres.engines.factory.build_engine`` chooses, and falls back once saying why."""
    return build_engine(job.engine.replace(horizon=prob.budget), prob.init_params)


__all__ = ["Problem", "prepare", "task_schedule", "job_engine", "engine_kind", "kind_of"]  # the last two: run/cli's
