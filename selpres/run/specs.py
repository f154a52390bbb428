"""The composed config turned into plain Python, once, for the rooms below ``run`` (which never see omegaconf).

``plain`` is the one "to plain values" helper: interpolations resolved, enums as their names, nested nodes as dicts
and lists. ``robot_spec`` and ``data_spec`` give the task's two specs: the robot node as a
``selpres.registry.Choice`` (its ``_target_`` and parameters; ``selpres.arms.sources`` builds the arm) and the data
node as a ``selpres.data.spec.DataSpec``, its values checked against the types its route declares (the common keys'
``CommonKeys``, the route's ``Keys``) and converted as a typed schema would (``accel_limit: 3`` is 3.0): one line
naming ``data.<key>``, the value and what its type allows. ``recorded`` is a job's config as results.json records
it and its identity hashes it.
"""

from __future__ import annotations

import dataclasses
import re
import types
import typing
from collections.abc import Mapping
from enum import Enum
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf
from omegaconf.errors import ConfigKeyError, OmegaConfBaseException

from selpres.arms.sources import SOURCES, as_choice
from selpres.data.routes import ROUTES, keys_of
from selpres.data.spec import COMMON, CommonKeys, DataSpec
from selpres.errors import ConfigError
from selpres.registry import Choice

# The data node's keys when the schema typed every route's (before the routes declared their own): a job's config
# holds them as unset where its route does not read them, so results.json's config, and the job hash taken of it,
# stay what they were for the configs written before. Fixed, never grown: a new route's keys are not added here.
TYPED_BEFORE = ("theta", "dtheta", "tau1", "tau2", "accel_limit", "n", "route", "draw", "seed", "q", "dq", "tau")
TYPED_BEFORE += ("wrench", "path", "inputs", "outputs")


def plain(node: Any) -> Any:
    """Plain, resolved values of a config node (or of a container holding nodes): dicts, lists, scalars."""
    if isinstance(node, (DictConfig, ListConfig)):
        return OmegaConf.to_container(node, resolve=True, enum_to_str=True)
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


def recorded(cfg: Any) -> dict:
    """A job's config as plain values, as results.json records it and ``job_hash`` hashes it: the data node as its
    spec (types converted), with the keys of :data:`TYPED_BEFORE` it lacks as unset, and every registry's choice by
    one name (:func:`canonical`: ``selpres.engines.optim.adam.Adam`` and ``adam`` are one job)."""
    c = canonical(plain(cfg))
    c["data"] = {**dict.fromkeys(TYPED_BEFORE), **data_spec(cfg.data).as_dict()}
    return c


def canonical(c: dict) -> dict:
    """A plain config with each registry's choice by its one name (:meth:`selpres.registry.Registry.canonical`): a
    built-in named by its import path (the shipped files' spelling) as its alias (the command line's, and every
    config's before the files named import paths), so hashes and recorded configs stay what they were."""
    from selpres.engines.activations import ACTIVATIONS
    from selpres.engines.optim import OPTIMIZERS
    from selpres.presentation.orders import REGISTRY as ORDERS
    from selpres.presentation.pruning import REGISTRY as PRUNING

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
