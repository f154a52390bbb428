"""The data node as plain Python: what ``selpres.run`` hands this room in place of the composed config.

A ``data`` node is open: ``kind`` names its route (a built-in of ``selpres.data.routes`` or a route class by its
import path), the keys below (:class:`CommonKeys`) are every route's, and the rest are the route's own, declared
by its ``Keys`` dataclass. ``DataSpec`` holds the common keys as fields and the route's keys in ``params``, as
plain values (strings for enums, dicts for nested nodes, lists for boxes); every key reads by name
(``data["theta"]``), so the functions of this room read a spec as they read a plain dict or a config node, and the
route's keys by attribute as well (``data.n``). The dataclasses here say the types; ``selpres.run.specs`` checks a
composed node against them (this room imports no omegaconf), so a new route's keys edit no schema.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from enum import Enum
from typing import Any

from selpres.data.routes import ROUTES, defaults_of, keys_of
from selpres.errors import ConfigError


class ScalingMode(Enum):
    exemplar = "exemplar"  # each column's min/max over the exemplar set
    commanded = "commanded"  # the configured boxes (a route that has them: Task.commanded)


@dataclasses.dataclass
class Scaling:
    mode: ScalingMode
    margin: float
    lo: float
    hi: float


@dataclasses.dataclass
class CommonKeys:
    """The keys of every data node, whatever its route, with their types (``selpres.run.specs`` checks them)."""

    kind: str  # the route: a built-in of selpres.data.routes or an import path
    test_patterns: int  # the paper's metric: this many test patterns ...
    test_from_exemplar: int  # ... of which this many from the exemplar set
    heldout: Any  # a count, or a fraction (float in (0, 1)) of all patterns (a file: of its rows)
    test_seed: int  # the test sets' draws
    scaling: Scaling


COMMON = tuple(f.name for f in dataclasses.fields(CommonKeys))


@dataclasses.dataclass(frozen=True)
class DataSpec:
    kind: str  # a route of selpres.data.routes (grid | sampled | file) or a route class's import path
    test_patterns: int
    test_from_exemplar: int
    heldout: Any  # a count, or a fraction of the patterns
    test_seed: int
    scaling: Mapping[str, Any]  # {mode, margin, lo, hi}
    params: Mapping[str, Any] = dataclasses.field(default_factory=dict)  # the route's own keys (its Keys)

    def __getattr__(self, name: str) -> Any:
        """A route's key by attribute (``data.n``); only for keys the route declares."""
        if name.startswith("__"):
            raise AttributeError(name)
        params = self.__dict__.get("params", {})
        if name in params:
            return params[name]
        raise AttributeError(f"data.{name}: not a key of data.kind={self.__dict__.get('kind')}")

    def __getitem__(self, key: str) -> Any:
        """Any key by name, a common one or the route's (``data["theta"]``), as a plain dict reads it."""
        try:
            return getattr(self, key)
        except AttributeError as e:
            raise KeyError(key) from e

    @classmethod
    def of(cls, node: Mapping[str, Any]) -> DataSpec:
        """From a plain data node: ``kind`` checked by the registry, the common keys required; a key neither common
        nor the route's is refused naming ``data.<key>`` unless it is unset (None: a results.json written when the
        schema held every route's keys); a route's key it lacks (or holds as None) reads the route's default, None
        for a key without one (``selpres.run.checks`` requires those). Types are converted by ``selpres.run.specs``."""
        node = dict(node)
        kind = ROUTES.check(node.get("kind"))
        route = ROUTES.get(kind)
        keys = keys_of(route)
        for k, v in node.items():
            if k not in COMMON and k not in keys and v is not None:
                where = f"{route.__module__}.{route.__qualname__}"
                raise ConfigError(f"data.{k}", v, f"unset (null): data.kind={kind} ({where}) reads {list(keys)}")
        for k in COMMON:
            if node.get(k) is None:
                raise ConfigError(f"data.{k}", None, f"a value: data.kind={kind} reads it")
        defaults = defaults_of(route)
        params = {k: defaults.get(k) if node.get(k) is None else node[k] for k in keys}
        return cls(params=params, **{k: node[k] for k in COMMON})

    def as_dict(self) -> dict[str, Any]:
        """The flat node: the common keys and the route's (what :meth:`of` takes back)."""
        return {**{k: getattr(self, k) for k in COMMON}, **self.params}
