"""Checks a type cannot express, run before any training or output: each failure is one ConfigError naming the
key, the bad value and what is allowed (exit code 2 from ``python train.py``).

``selpres.run.resolve`` calls them on the job's plain specs: values against each other (ranges, the optimizer and
the units, the schedule and its pruning, the robot and data specs of each kind, topology widths against the task's
inputs and outputs); the checks that need the exemplar set (stage sizes against n, filters that keep nothing, a data
file's cells) run in ``selpres.run.problem.prepare``, still before anything is written. Work that cannot fit this
machine's memory or would take absurdly long is refused from estimates (``selpres.run.estimate``): replicas and the
plan's length here, before the task is built, the whole job once the exemplar set is known.
"""

from __future__ import annotations

import math

from selpres.data.paper import heldout_count
from selpres.data.routes import ROUTES, required_of
from selpres.data.spec import DataSpec
from selpres.data.task import Shape, task_shape
from selpres.engines.activations import activation
from selpres.engines.minibatch import check_epoch_clock
from selpres.engines.model import TopologyError, parse_topology
from selpres.errors import ConfigError
from selpres.presentation.orders import make_order
from selpres.presentation.proportions import check_form
from selpres.presentation.pruning._job import check_pruning
from selpres.registry import Choice
from selpres.run.config import undeclared
from selpres.run.estimate import refuse_before_task
from selpres.run.optimizer import check_optim
from selpres.run.specs import Cadence, JobSpec, OptimSpec, ScheduleSpec

MAX_SEED = 2**64 - 1  # torch.manual_seed's largest
MAX_LAYER_WIDTH = 4096  # wider layers are refused: a guard against typos such as 6-13000-2


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


def check_plain(c: dict) -> None:
    """The plain config as a whole: an appended key no code reads (``+schedule.p=1``: it would be recorded as if it
    ran) and a number that is not finite are refused, naming their key."""
    appended = undeclared(c)
    if appended is not None:
        raise ConfigError(*appended)
    for key, value in _walk(c):
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(key, value, "a finite number (NaN and inf are not allowed)")


def check(job: JobSpec) -> tuple[int, ...]:
    """Every check of a read job that needs no exemplar set, before the task is built but the last two (they build
    the arm or read a data file's header); returns the topology's widths, which fit the task."""
    check_run(job.replicas, job.seed, job.threads, job.cadence)
    check_optim(job.optim, job.engine)  # the optimizer's keys, its modes against the units and the engine
    activation(job.activation)  # a built-in or an importable class with forward and prime (model.activation)
    check_schedule(job.schedule, job.optim)
    refuse_before_task(job.replicas, job.layers, job.schedule)  # replicas=10^9: before the task is built
    return check_topology(job.layers, check_task(job.robot, job.data))


def check_schedule(s: ScheduleSpec, optim: OptimSpec) -> None:
    """The order, the selector around the schedule and the optimizer, the strata and the choosing charge."""
    sel = s.selector
    make_order(sel.order)  # a built-in or an importable Order: ConfigError naming schedule.order
    check_form(s.node)  # listed sizes or the parametric keys, not both (selpres.presentation.proportions)
    check_epoch_clock(optim.lr_schedule, s.sizes, s.epochs, s.budget)  # cosine_epochs: one stage of U for N epochs
    if sel.target is not None:
        kw = dict(sizes=s.sizes, order=sel.order, budget=s.budget, epochs=s.epochs, selection_cost=sel.selection_cost)
        check_pruning(sel.target, dict(sel.params), **kw)
        if optim.batch:
            why = f"a mini-batch >= 1 with schedule.pruning._target_={sel.target}"
            raise ConfigError("optim.batch_size", optim.batch_size, why)
    if sel.strata_bins < 1:
        raise ConfigError("schedule.strata_bins", sel.strata_bins, "a whole number >= 1")
    if not 0 <= sel.selection_cost <= 1:
        raise ConfigError(
            "schedule.selection_cost",
            sel.selection_cost,
            "a fraction of a training presentation in [0, 1] charged per candidate scored "
            "(0 = choosing is free; default 1/3, a forward pass of forward + backward)",
        )


def check_run(replicas: int, seed: int, threads: int, cadence: Cadence) -> None:
    """Replicas, the seed range they take, threads, and how often the loop scores and checkpoints."""
    if replicas < 1:
        raise ConfigError("replicas", replicas, "a whole number >= 1")
    check_seed(seed, replicas)
    if threads < 0:
        raise ConfigError("threads", threads, "0 (all cores) or a positive number of threads")
    if cadence.heldout_every < 0:
        raise ConfigError("eval.every", cadence.heldout_every, "0 (stage ends only) or a positive number of epochs")
    if cadence.heldout_curve < 1:
        raise ConfigError("eval.heldout_curve", cadence.heldout_curve, "a positive number of held-out patterns")
    if cadence.checkpoint_every < 0:
        raise ConfigError(
            "checkpoint.every", cadence.checkpoint_every, "0 (stage boundaries only) or a positive number of epochs"
        )


def check_seed(seed: int, replicas: int) -> None:
    """Replica r uses seed + r, and torch.manual_seed takes [0, 2^64): checked before anything is seeded."""
    top = MAX_SEED - max(1, replicas) + 1
    if not 0 <= seed <= top:
        raise ConfigError("seed", seed, f"a whole number in [0, {top}] (seed + replicas - 1 < 2^64)")


def check_task(robot: Choice, d: DataSpec) -> Shape:
    """The robot and data specs: the data node holds only keys its route reads, of the types it declares
    (``selpres.run.specs.data_spec``), its required ones set, the common ones in range, the route's own values in
    range (its ``check``); returns the shape of the task (``selpres.data.task.task_shape``: builds the arm or reads a
    data file's header)."""
    route = ROUTES.get(d.kind)
    for k in required_of(route):
        if d.params[k] is None:
            raise ConfigError(f"data.{k}", None, f"a value: data.kind={d.kind} reads it")
    if d.test_patterns < 1:
        raise ConfigError("data.test_patterns", d.test_patterns, "a whole number >= 1")
    if not 0 <= d.test_from_exemplar <= d.test_patterns:
        raise ConfigError(
            "data.test_from_exemplar", d.test_from_exemplar, f"a count in [0, data.test_patterns = {d.test_patterns}]"
        )
    heldout_count(d.heldout, 1, "the patterns")  # type and range only: selpres.data.task counts a fraction
    s = d.scaling
    if not (0 <= s["lo"] < s["hi"] <= 1):
        raise ConfigError("data.scaling.lo", s["lo"], f"0 <= lo < hi <= 1 (the sigmoid's range); hi = {s['hi']}")
    if s["margin"] < 0:
        raise ConfigError("data.scaling.margin", s["margin"], "a margin >= 0 (fraction of each column's range)")
    getattr(route(), "check", lambda data: None)(d)  # the route's own values (ranges, sizes)
    return task_shape(robot, d)


def check_topology(layers: str, shape: Shape) -> tuple[int, ...]:
    """Layer widths that parse and fit the task: its numbers of inputs and outputs, named in the message."""
    try:
        sizes = parse_topology(layers)
    except TopologyError as e:
        raise ConfigError("topology.layers", layers, e.allowed) from None
    n_in, n_out = len(shape.input_names), len(shape.output_names)
    if sizes[0] != n_in or sizes[-1] != n_out:
        hidden = "-".join(str(w) for w in sizes[1:-1]) or "13"
        fits = f"a network that fits {shape.source}: {shape.describe()}"
        raise ConfigError("topology.layers", layers, f"{fits}, e.g. {n_in}-{hidden}-{n_out}")
    if max(sizes) > MAX_LAYER_WIDTH:
        raise ConfigError("topology.layers", layers, f"layer widths of at most {MAX_LAYER_WIDTH} units")
    return sizes
