"""Checks a type cannot express, run before any training or output: each failure is one ConfigError naming the
key, the bad value and what is allowed (exit code 2 from ``python train.py``).

``validate`` checks values against each other (ranges, grid steps, the robot and data configs of each kind,
topology widths against the task's inputs and outputs); the checks that need the exemplar set (stage sizes
against n, filters that keep nothing, a data file's cells) run in ``selpres.run.problem.prepare``, still before
anything is written. Work that cannot fit this machine's memory or would take absurdly long is refused from
estimates (``selpres.run.estimate``): replicas and the plan's length here, before the task is built, the whole
job once the exemplar set is known.
"""

from __future__ import annotations

import math

from omegaconf import DictConfig

from selpres.data.paper import heldout_count
from selpres.data.routes import ROUTES, required_of
from selpres.data.task import Shape, task_shape
from selpres.engines.activations import activation
from selpres.engines.minibatch import check_epoch_clock
from selpres.engines.model import TopologyError, parse_topology
from selpres.errors import ConfigError
from selpres.presentation.orders import make_order
from selpres.presentation.pruning import REGISTRY as PRUNING
from selpres.presentation.pruning._job import check_pruning
from selpres.run.estimate import refuse_before_task
from selpres.run.optimizer import check_optim
from selpres.run.specs import plain, task_specs

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


def validate(cfg: DictConfig) -> tuple[int, ...]:
    """Checks that need more than a type; returns the parsed topology. Raises ConfigError."""
    for key, value in _walk(plain(cfg)):
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(key, value, "a finite number (NaN and inf are not allowed)")
    activation(cfg.model.activation)  # ConfigError naming model.activation
    spec = check_optim(cfg)  # ConfigError naming optim.<key>
    check_epoch_clock(spec.lr_schedule, plain(cfg.schedule))  # cosine_epochs: one stage of U for N epochs
    make_order(cfg.schedule.order)  # a built-in or an importable Order: ConfigError naming schedule.order
    pruning = pruning_spec(cfg.schedule)
    if pruning is not None:
        s = cfg.schedule
        epochs = None if s.epochs is None else list(s.epochs)
        check_pruning(
            *pruning,
            sizes=list(s.sizes),
            order=s.order,
            budget=s.budget,
            epochs=epochs,
            selection_cost=s.selection_cost,
        )
        if spec.batch:
            why = f"a mini-batch >= 1 with schedule.pruning._target_={pruning[0]}"
            raise ConfigError("optim.batch_size", cfg.optim.batch_size, why)
    if cfg.replicas < 1:
        raise ConfigError("replicas", cfg.replicas, "a whole number >= 1")
    check_seed(cfg)
    refuse_before_task(cfg)  # replicas=1000000000 and 10^9 epochs: refused before any data or seed list is made
    if cfg.threads < 0:
        raise ConfigError("threads", cfg.threads, "0 (all cores) or a positive number of threads")
    if cfg.eval.every < 0:
        raise ConfigError("eval.every", cfg.eval.every, "0 (stage ends only) or a positive number of epochs")
    if cfg.eval.heldout_curve < 1:
        raise ConfigError("eval.heldout_curve", cfg.eval.heldout_curve, "a positive number of held-out patterns")
    if cfg.checkpoint.every < 0:
        raise ConfigError(
            "checkpoint.every", cfg.checkpoint.every, "0 (stage boundaries only) or a positive number of epochs"
        )
    if cfg.schedule.strata_bins < 1:
        raise ConfigError("schedule.strata_bins", cfg.schedule.strata_bins, "a whole number >= 1")
    if not 0 <= cfg.schedule.selection_cost <= 1:
        raise ConfigError(
            "schedule.selection_cost",
            cfg.schedule.selection_cost,
            "a fraction of a training presentation in [0, 1] charged per candidate scored "
            "(0 = choosing is free; default 1/3, a forward pass of forward + backward)",
        )
    return check_topology(cfg.topology.layers, check_task(cfg))


def pruning_spec(s: DictConfig) -> tuple[str, dict] | None:
    """``schedule.pruning`` as the plain spec the pruning room takes: (the policy's name or import path, its
    parameters), or None (no pruning). The old spelling ``schedule.pruning=infobatch`` is refused naming the new."""
    node = s.pruning
    if node is None:
        return None
    if not isinstance(node, DictConfig):
        raise ConfigError(
            "schedule.pruning",
            node,
            f"null or a node {{_target_: <policy>, <its parameters>}}: schedule={node} sets one, or "
            f"schedule.pruning._target_={node} (policies: {PRUNING.allowed()})",
        )
    params = plain(node)
    target = params.pop("_target_", None)
    if target is None:
        raise ConfigError("schedule.pruning._target_", None, PRUNING.allowed())
    return PRUNING.check(target), params


def check_seed(cfg: DictConfig) -> None:
    """Replica r uses seed + r, and torch.manual_seed takes [0, 2^64): checked before anything is seeded."""
    top = MAX_SEED - max(1, cfg.replicas) + 1
    if not 0 <= cfg.seed <= top:
        raise ConfigError("seed", cfg.seed, f"a whole number in [0, {top}] (seed + replicas - 1 < 2^64)")


def check_task(cfg: DictConfig) -> Shape:
    """The robot and data configs: the data node holds only keys its route reads, of the types it declares
    (``selpres.run.specs.data_spec``), its required ones set, the common ones in range, the route's own values in
    range (its ``check``); returns the shape of the task (``selpres.data.task.task_shape``: builds the arm or reads a
    data file's header)."""
    robot, d = task_specs(cfg)
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
