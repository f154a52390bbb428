"""Data routes: how a task's exemplar and test sets are made, one module each (a registry, ``ROUTES``, by
``data.kind``): ``grid`` (the paper's section 5.1), ``sampled`` (drawn for any arm), ``file`` (the user's table).

A route module exports ``ROUTE``, a class with ``Keys`` (a dataclass: the keys of the data node it reads besides
the common ones of ``selpres.data.spec.CommonKeys``, with their types; a key without a default must be set, an
unset one with a default reads it; ``selpres.run.specs`` checks a composed node against it, so the config schema
holds no route's keys), ``USES_ARM`` (whether the robot node matters), ``check(data)`` (values a type cannot
express: ranges, sizes, ConfigError naming ``data.<key>``), ``shape(robot, data)`` (the network's inputs and
outputs, no data made), ``build(robot, data)`` (the ``selpres.data.task.Task``) and ``reads_files(data)`` (the
files the data is read from: their stamps key the task, which is then never stored). Adding a route is one module
here and one ``configs/data/<name>.yaml`` with ``kind: <name>``; a user's own is such a class by its import path
(``data.kind=my_routes.Table``).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from selpres.registry import Registry

ROUTES = Registry("data.kind", "selpres.data.routes", "ROUTE")


class DataRoute:
    """What a route offers besides ``shape`` and ``build`` (subclassing is optional: any class with the
    attributes of the module docstring is a route)."""

    @dataclasses.dataclass
    class Keys:
        pass

    USES_ARM = True

    def check(self, data) -> None:
        """Refuse values a type cannot express (ConfigError naming ``data.<key>``); nothing by default."""

    def reads_files(self, data) -> list[Path]:
        return []


def keys_of(route: type) -> tuple[str, ...]:
    """The route's own keys, in its ``Keys`` dataclass's order (none for a class without one)."""
    keys = getattr(route, "Keys", None)
    return tuple(f.name for f in dataclasses.fields(keys)) if dataclasses.is_dataclass(keys) else ()


def defaults_of(route: type) -> dict:
    """The route's keys that have a default, and that default (what an unset key reads)."""
    keys = getattr(route, "Keys", None)
    if not dataclasses.is_dataclass(keys):
        return {}
    out = {}
    for f in dataclasses.fields(keys):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def required_of(route: type) -> tuple[str, ...]:
    """The route's keys that must be set: those its ``Keys`` gives no default."""
    keys = getattr(route, "Keys", None)
    if not dataclasses.is_dataclass(keys):
        return ()
    return tuple(k for k in keys_of(route) if k not in defaults_of(route))
