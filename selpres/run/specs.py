"""The composed config's nodes turned into plain specs for the rooms below ``run`` (which never see omegaconf).

``plain`` is the one "to plain values" helper: interpolations resolved, enums as their names, nested nodes as dicts
and lists; the other functions take a node either way (``selpres.run.resolve`` hands them plain ones, read once).
``robot_spec`` and ``data_spec`` give the task's two specs: the robot node as a ``selpres.registry.Choice`` (its
``_target_`` and parameters; ``selpres.arms.sources`` builds the arm) and the data node as a
``selpres.data.spec.DataSpec``, its values checked against the types its route declares (the common keys'
``CommonKeys``, the route's ``Keys``) and converted as a typed schema would (``accel_limit: 3`` is 3.0): one line
naming ``data.<key>``, the value and what its type allows. ``schedule_spec`` gives the schedule node as a
:class:`ScheduleSpec`. ``recorded`` is a job's config as results.json records it, and ``identity`` the hash of it
that finds a finished job.
"""

from __future__ import annotations

import dataclasses
import functools
import re
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import ConfigKeyError, OmegaConfBaseException

from selpres.arms.sources import SOURCES, as_choice
from selpres.data.file import file_digest
from selpres.data.routes import ROUTES, keys_of
from selpres.data.spec import COMMON, CommonKeys, DataSpec
from selpres.data.task import task_files
from selpres.engines.batch import check_batch_options
from selpres.engines.factory import EngineSpec, mode_for
from selpres.engines.minibatch import LR_SCHEDULES
from selpres.engines.optim import KEY, OPTIMIZERS, modes
from selpres.engines.optim._base import MINIBATCH, ONLINE
from selpres.errors import ConfigError
from selpres.presentation.build import SelectorSpec
from selpres.presentation.orders import REGISTRY as ORDERS
from selpres.presentation.proportions import RULE_KEYS
from selpres.presentation.pruning import REGISTRY as PRUNING
from selpres.registry import Choice
from selpres.storage import stable_hash

# The data node's keys when the schema typed every route's (before the routes declared their own): a job's config
# holds them as unset where its route does not read them, so results.json's config, and the job hash taken of it,
# stay what they were for the configs written before. Fixed, never grown: a new route's keys are not added here.
TYPED_BEFORE = ("theta", "dtheta", "tau1", "tau2", "accel_limit", "n", "route", "draw", "seed", "q", "dq", "tau")
TYPED_BEFORE += ("wrench", "path", "inputs", "outputs")
HOW = ("batch_size", "reduction", "lr_schedule", "sigmoid_prime_offset")  # optim's keys for the engines, not its class
NOT_IDENTITY = ("logging", "overwrite", "threads", "checkpoint", "name")  # knobs that cannot change a job's numbers


def plain(node: Any) -> Any:
    """Plain, resolved values of a config node (or of a container holding nodes): dicts, lists, scalars."""
    if isinstance(node, (DictConfig, ListConfig)):
        return OmegaConf.to_container(node, resolve=True, enum_to_str=True, throw_on_missing=True)
    if isinstance(node, Mapping):
        return {k: plain(v) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return [plain(v) for v in node]
    return node.name if isinstance(node, Enum) else node


def robot_spec(node: Any) -> Choice:
    """The robot node as (``_target_``, parameters), a built-in by its alias: ConfigError naming ``robot._target_``
    when it names none."""
    choice = as_choice(plain(node))
    return Choice(SOURCES.canonical(choice.target), choice.params)


def data_spec(node: Any) -> DataSpec:
    """The data node as a spec, its keys' types checked and converted (ConfigError naming ``data.<key>``)."""
    d = plain(node)
    if not isinstance(d, Mapping):
        raise ConfigError("data", d, "a data node {kind: <route>, ...} (data=paper, sampled or file picks one)")
    d = dict(d)
    kind = ROUTES.check(d.get("kind"))
    route = ROUTES.get(kind)
    typed = {**d, **_typed(CommonKeys, {k: d[k] for k in COMMON if k in d}, kind)}
    if keys_of(route):
        typed.update(_typed(route.Keys, {k: d[k] for k in keys_of(route) if k in d}, kind))
    return DataSpec.of(typed)


@dataclass(frozen=True)
class ScheduleSpec:
    """The schedule node: the stages as written (``sizes``: counts or fractions of n, None in the parametric form;
    ``epochs`` per stage, or a ``budget`` of presentations) and what chooses each epoch's patterns, ``selector``
    (``selpres.presentation.build.SelectorSpec``: the order that grows A_i, its strata, the charge per candidate
    scored, and the ``schedule.pruning`` node's class, a built-in's alias or an import path, and its parameters).
    ``node``: the whole node as plain values, the parametric form's keys included
    (``selpres.presentation.proportions.schedule_of`` reads them)."""

    name: str
    sizes: list | None
    epochs: list[int] | None
    budget: int | None
    selector: SelectorSpec
    node: Mapping[str, Any]


def schedule_spec(node: Any) -> ScheduleSpec:
    s = plain(node)
    sizes = None if s.get("sizes") is None else list(s["sizes"])  # None: the parametric form (p, first, growth, ...)
    epochs = None if s.get("epochs") is None else list(s["epochs"])
    return ScheduleSpec(s["name"], sizes, epochs, s.get("budget"), selector_spec(s), node=s)


def selector_spec(s: Mapping[str, Any]) -> SelectorSpec:
    """The plain schedule node's choice of selector: ``schedule.order`` (an order's alias or import path), its
    strata, the charge per candidate scored, and ``schedule.pruning`` (null: the staged presentation of the order;
    else a node ``{_target_: <a selector's alias or import path>, <its parameters>}``). The old spelling
    ``schedule.pruning=infobatch`` is refused naming the new."""
    order = ORDERS.canonical(s["order"])
    common = (order, s["strata_bins"], s["selection_cost"])
    node = s.get("pruning")
    if node is None:
        return SelectorSpec(*common)
    if not isinstance(node, Mapping):
        raise ConfigError(
            "schedule.pruning",
            node,
            f"null or a node {{_target_: <policy>, <its parameters>}}: schedule={node} sets one, or "
            f"schedule.pruning._target_={node} (policies: {PRUNING.allowed()})",
        )
    params = dict(plain(node))
    target = params.pop("_target_", None)
    if target is None:
        raise ConfigError("schedule.pruning._target_", None, PRUNING.allowed())
    return SelectorSpec(*common, target=PRUNING.canonical(PRUNING.check(target)), params=params)


@dataclass(frozen=True)
class OptimSpec:
    """What the engines need of ``optim``: the optimizer (a built-in's alias, or an import path), its keyword
    arguments (None values left out) and how it runs."""

    target: str
    params: dict
    batch_size: int
    reduction: str
    lr_schedule: str
    sigmoid_prime_offset: float

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


def optim_spec(node: Any) -> OptimSpec:
    """The ``optim`` node as an :class:`OptimSpec`, its keys' types checked (ConfigError naming ``optim.<key>``)."""
    o = plain(node)
    if "name" in o:  # the spelling before optim._target_
        raise ConfigError(
            "optim.name", o["name"], f"no key: renamed, write optim._target_={o['name']} (or optim=<file>)"
        )
    if "_target_" not in o:
        raise ConfigError(KEY, None, OPTIMIZERS.allowed())
    b = o.get("batch_size")
    if isinstance(b, bool) or not isinstance(b, int) or b < 0:
        raise ConfigError(
            "optim.batch_size", b, "0 (the whole epoch) or a whole number >= 1 (1 = online, as in the paper)"
        )
    if o["lr_schedule"] not in LR_SCHEDULES:
        raise ConfigError("optim.lr_schedule", o["lr_schedule"], f"one of {', '.join(LR_SCHEDULES)}")
    offset, reduction = check_batch_options(o["sigmoid_prime_offset"], o["reduction"])
    target = OPTIMIZERS.canonical(OPTIMIZERS.check(o["_target_"]))
    params = {k: v for k, v in o.items() if k != "_target_" and k not in HOW and v is not None}
    return OptimSpec(target, params, b, reduction, o["lr_schedule"], offset)


def engine_spec(optim: OptimSpec, activation: str, requested: str) -> EngineSpec:
    """What the job's engine is built from, but the network's sizes and the run's planned cost (known once the task
    is): the engine asked for, the mode the optimizer, units and rate need (selpres.engines.factory.mode_for), the
    optimizer and how it runs."""
    mode, why = mode_for(optim.target, optim.modes, optim.batch_size, activation, optim.lr_schedule)
    return EngineSpec(
        requested=requested,
        mode=mode,
        optimizer=optim.target,
        hparams=optim.params,
        batch_size=optim.batch_size,
        activation=activation,
        lr_schedule=optim.lr_schedule,
        reduction=optim.reduction,
        sigmoid_prime_offset=optim.sigmoid_prime_offset,
        why=why,
    )


@dataclass(frozen=True)
class Cadence:
    """How often the loop scores and checkpoints (``eval.every``, ``eval.heldout_curve``, ``checkpoint.every``)."""

    heldout_every: int  # epochs between held-out scores (0: stage ends only)
    heldout_curve: int  # held-out patterns scored for the curves
    checkpoint_every: int  # epochs between checkpoints (0: stage boundaries only)


@dataclass(frozen=True)
class JobSpec:
    """A job as the rooms receive it: plain and typed (``selpres.run.resolve`` checks it and fills ``sizes``).
    ``config`` is the config as results.json records it (:func:`recorded`) and ``hash`` its identity
    (``config_hash``: what finds a finished job; it reads the task's files, once, when first asked for)."""

    seed: int  # replica r trains from seed + r
    replicas: int
    threads: int  # torch threads (0: all cores)
    layers: str  # topology.layers as written (6-13-2)
    sizes: tuple[int, ...]  # its widths, checked against the task's inputs and outputs
    robot: Choice
    data: DataSpec
    schedule: ScheduleSpec
    optim: OptimSpec
    activation: str  # the hidden units: a built-in's name or an import path
    engine: EngineSpec  # what the engine is built from (its planned cost, the horizon, once the task is known)
    cadence: Cadence
    checkpoints: bool  # checkpoint.enabled
    tensorboard: bool  # logging.tensorboard
    per_replica: bool  # logging.per_replica
    progress: bool  # logging.progress: one line per stage end
    overwrite: bool
    name: str
    config: dict[str, Any]

    @property
    def seeds(self) -> list[int]:
        return [self.seed + r for r in range(self.replicas)]

    @functools.cached_property
    def hash(self) -> str:
        return identity(self.config, self.robot, self.data)

    def checked(self, sizes: tuple[int, ...]) -> JobSpec:
        """This job with the network's widths, checked against its task, for it and its engine."""
        return dataclasses.replace(self, sizes=sizes, engine=self.engine.replace(sizes=sizes))


def read(c: dict) -> JobSpec:
    """The plain composed config ``c`` as a job's specs, each node's keys typed and its registries' names made one
    (ConfigError naming the key); ``sizes`` is empty until ``selpres.run.resolve`` checks the topology."""
    optim, activation, data = optim_spec(c["optim"]), c["model"]["activation"], data_spec(c["data"])
    log, ckpt, ev = c["logging"], c["checkpoint"], c["eval"]
    return JobSpec(
        seed=c["seed"],
        replicas=c["replicas"],
        threads=c["threads"],
        layers=c["topology"]["layers"],
        sizes=(),
        robot=robot_spec(c["robot"]),
        data=data,
        schedule=schedule_spec(c["schedule"]),
        optim=optim,
        activation=activation,
        engine=engine_spec(optim, activation, c["engine"]),
        cadence=Cadence(ev["every"], ev["heldout_curve"], ckpt["every"]),
        checkpoints=ckpt["enabled"],
        tensorboard=log["tensorboard"],
        per_replica=log["per_replica"],
        progress=log["progress"],
        overwrite=c["overwrite"],
        name=c["name"],
        config=recorded(c, data),
    )


def recorded(cfg: Any, data: DataSpec | None = None) -> dict:
    """A job's config as plain values, as results.json records it and ``identity`` hashes it: the data node as its
    spec (``data``, or read from the config; types converted), with the keys of :data:`TYPED_BEFORE` it lacks as
    unset, every registry's choice by one name (:func:`canonical`: ``selpres.engines.optim.adam.Adam`` and ``adam``
    are one job), and the parametric schedule's keys only where set."""
    c = canonical(plain(cfg))
    c["data"] = {**dict.fromkeys(TYPED_BEFORE), **(data or data_spec(c["data"])).as_dict()}
    # the parametric schedule's keys only where set: a listed schedule's record (and identity) is what it was
    c["schedule"] = {k: v for k, v in c["schedule"].items() if v is not None or k not in RULE_KEYS}
    return c


def identity(config: dict, robot: Choice, data: DataSpec) -> str:
    """The identity of a job's numbers (results.json ``config_hash``), from its ``recorded`` config: everything but
    the knobs that cannot change them (:data:`NOT_IDENTITY`), and the contents of the files its task reads
    (``selpres.data.task.task_files``: what the arm's source reads, a data file), so an edited URDF or CSV is not
    taken for the finished job."""
    c = {k: v for k, v in config.items() if k not in NOT_IDENTITY}
    c["file_sha256"] = [file_digest(p) if p.is_file() else None for p in task_files(robot, data)]
    return stable_hash(c)


def canonical(c: dict) -> dict:
    """A plain config with each registry's choice by its one name (:meth:`selpres.registry.Registry.canonical`): a
    built-in named by its import path (the shipped files' spelling) as its alias (the command line's, and every
    config's before the files named import paths), so hashes and recorded configs stay what they were."""
    from selpres.engines.activations import ACTIVATIONS
    from selpres.engines.optim import OPTIMIZERS

    c = dict(c)
    for node, key, registry in (
        ("robot", "_target_", SOURCES),
        ("optim", "_target_", OPTIMIZERS),
        ("model", "activation", ACTIVATIONS),
        ("schedule", "order", ORDERS),
    ):
        if isinstance(c.get(node), dict) and key in c[node]:
            c[node] = {**c[node], key: registry.canonical(c[node][key])}
    pruning = (c.get("schedule") or {}).get("pruning")
    if isinstance(pruning, dict) and "_target_" in pruning:
        c["schedule"] = {**c["schedule"], "pruning": {**pruning, "_target_": PRUNING.canonical(pruning["_target_"])}}
    return c


def _typed(schema: type, node: dict, kind: str) -> dict:
    """``node``'s values checked against the dataclass ``schema``'s types, one key at a time, and converted as
    omegaconf converts a typed config's (enums by name); an unset (None) value is left to ``DataSpec.of``."""
    out = {}
    for k, v in node.items():
        if v is None:
            out[k] = None
            continue
        try:
            merged = OmegaConf.merge(OmegaConf.structured(schema), {k: v})
        except OmegaConfBaseException as e:
            path = str(e.full_key or k)
            if isinstance(e, ConfigKeyError):  # a key the nested node (theta: {lo, hi, step}) does not have
                parent = path.rpartition(".")[0]
                keys = ", ".join(f.name for f in dataclasses.fields(_type_at(schema, parent)))
                raise ConfigError(f"data.{path}", _at(node, path), f"one of the keys {keys} of data.{parent}") from None
            raise ConfigError(f"data.{path}", _at(node, path), _expects(schema, path)) from None
        missing = sorted(m for m in OmegaConf.missing_keys(merged) if m.startswith(f"{k}."))  # theta without step
        if missing:
            raise ConfigError(f"data.{missing[0]}", None, f"a value: data.kind={kind} reads it")
        out[k] = OmegaConf.to_container(merged, enum_to_str=True)[k]
    return out


def _parts(path: str) -> list[str]:
    return [p for p in re.split(r"\.|\[|\]", path) if p]


def _at(node: Any, path: str) -> Any:
    """The value at ``path`` (``theta.lo``, ``wrench[0]``) of a plain node."""
    for p in _parts(path):
        node = node[int(p)] if isinstance(node, list) else node[p]
    return node


def _type_at(schema: type, path: str) -> Any:
    """The declared type at ``path`` of the dataclass ``schema`` (Optional stripped)."""
    tp: Any = schema
    for p in _parts(path):
        tp = _bare(tp)
        if dataclasses.is_dataclass(tp):
            tp = typing.get_type_hints(tp)[p]
        else:  # a list's element
            args = typing.get_args(tp)
            tp = args[0] if args else Any
    return _bare(tp)


def _expects(schema: type, path: str) -> str:
    """What the type at ``path`` of ``schema`` allows, in words."""
    return _words(_type_at(schema, path))


def _bare(tp: Any) -> Any:
    """``Optional[X]`` -> X."""
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    return args[0] if typing.get_origin(tp) in (typing.Union, types.UnionType) and len(args) == 1 else tp


def _words(tp: Any) -> str:
    bare = _bare(tp)
    if bare is not tp:
        return f"{_words(bare)}, or null"
    if isinstance(tp, type) and issubclass(tp, Enum):
        return f"one of {', '.join(m.name for m in tp)}"
    if dataclasses.is_dataclass(tp):
        return f"a node {{{', '.join(f'{f.name}: ...' for f in dataclasses.fields(tp))}}}"
    if typing.get_origin(tp) is list:
        args = typing.get_args(tp)
        return "a list" + (f", each item {_words(args[0])}" if args and args[0] is not Any else "")
    names = {int: "a whole number", float: "a number", str: "a string", bool: "true or false"}
    return names.get(tp, "any value")


def task_specs(cfg: Any) -> tuple[Choice, DataSpec]:
    """(robot, data) of a composed training config: what ``selpres.data.task.load_task`` takes."""
    return robot_spec(cfg.robot), data_spec(cfg.data)
