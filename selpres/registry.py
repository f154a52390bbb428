"""Registries: where the built-in choices of one kind live, and how a user names their own.

A built-in choice is one module of its kind's package: ``selpres/engines/optim/lion.py`` *is* the optimizer
``lion``, exporting the class under the kind's entry name (e.g. ``OPTIMIZER = Lion``). The registry lists the
package's modules without importing them (``--help`` and the config checks need no torch) and imports one only
when it is asked for, so adding a choice is one module and one YAML, and no list is kept in step by hand.
Modules whose names start with ``_`` are the package's helpers, not choices.

A user's own choice lives outside the package and is named by its import path, as Hydra's ``_target_`` names a
class (``mylion.Lion``, ``torch.optim.NAdam``): a dotted name is always an import path, a plain one a built-in. The
shipped config files name built-ins by import path too (``_target_: selpres.engines.optim.adam.Adam``, which
``hydra.utils.instantiate`` resolves); a built-in's module name is its alias (``optim._target_=adam``), and
:meth:`Registry.canonical` maps either spelling to that one name, which results.json records and a job's identity
hashes.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

from selpres.errors import ConfigError


@dataclass(frozen=True)
class Registry:
    """The choices of one kind: ``key`` is the config key that names one (for errors), ``package`` holds the
    built-ins (one module each), ``entry`` the attribute each built-in module exports."""

    key: str
    package: str
    entry: str

    @cached_property
    def names(self) -> tuple[str, ...]:
        """The built-in choices, sorted: the package's public modules (none is imported)."""
        pkg = importlib.import_module(self.package)
        return tuple(sorted(m.name for m in pkgutil.iter_modules(pkg.__path__) if not m.name.startswith("_")))

    def allowed(self) -> str:
        return f"one of {', '.join(self.names)}, or a class by its import path (package.module.Class)"

    def canonical(self, name):
        """The built-in's name when ``name`` is the import path of a built-in's entry
        (``selpres.engines.optim.adam.Adam`` -> ``adam``), else ``name`` as it is: one choice, one name, however it
        was spelt (imports the built-in's module to be sure the path is its entry, not another name of the module)."""
        if not isinstance(name, str) or not name.startswith(f"{self.package}."):
            return name
        module, _, attr = name.rpartition(".")
        short = module[len(self.package) + 1 :]
        if short not in self.names:
            return name
        mod = importlib.import_module(module)
        return short if getattr(mod, attr, None) is getattr(mod, self.entry, self) else name

    def check(self, name) -> str:
        """``name`` if it is a built-in or looks like an import path, else a ConfigError naming the choices.
        Imports nothing: an import path is resolved (and its failure reported) by :meth:`get`."""
        if not isinstance(name, str) or not name or (name not in self.names and not is_path(name)):
            raise ConfigError(self.key, name, self.allowed())
        return name

    def get(self, name: str):
        """The class (or object) a built-in module exports as ``entry``, or the one an import path names."""
        self.check(name)
        if is_path(name):
            return locate(self.key, name)
        return getattr(importlib.import_module(f"{self.package}.{name}"), self.entry)

    def build(self, name: str, params: Mapping[str, Any]):
        """An instance of the class ``name`` resolves to, made from the node's other keys (:func:`construct`)."""
        return construct(self.get(name), params, self.key.rpartition(".")[0] or self.key)

    def path_of(self, name: str) -> str:
        """The import path of what ``name`` resolves to (results.json records it)."""
        obj = self.get(name)
        return f"{obj.__module__}.{obj.__qualname__}"


def is_path(name: str) -> bool:
    return "." in name


def locate(key: str, path: str):
    """The object at the import path ``path`` (``package.module.Name``), or a ConfigError saying why not."""
    module, _, attr = path.rpartition(".")
    if not module or not attr:
        raise ConfigError(key, path, "an import path package.module.Name")
    try:
        mod = importlib.import_module(module)
    except ImportError as e:
        raise ConfigError(key, path, f"an importable module ({module}: {e}; is it on PYTHONPATH?)") from None
    try:
        return getattr(mod, attr)
    except AttributeError:
        raise ConfigError(key, path, f"a name defined in module {module} (it has no {attr!r})") from None


@dataclass(frozen=True)
class Choice:
    """A node that names a choice, as plain Python (what ``selpres.run`` hands a room): ``target``, the value of
    its ``_target_`` (a built-in name or an import path), and ``params``, its other keys (plain values)."""

    target: str
    params: Mapping[str, Any] = field(default_factory=dict)


def construct(cls, params: Mapping[str, Any], node: str):
    """``cls(**params)``, with a key the class does not take, or a required one missing, refused as a ConfigError
    naming ``<node>.<key>`` (a class that takes ``**kwargs`` checks its own keys)."""
    try:
        sig = inspect.signature(cls)
    except (TypeError, ValueError):  # a builtin without a signature: let it say what it takes
        return cls(**params)
    named = [p for p in sig.parameters.values() if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    where = f"{getattr(cls, '__module__', '?')}.{getattr(cls, '__qualname__', cls)}"
    if not any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        for k, v in params.items():
            if k not in {p.name for p in named}:
                raise ConfigError(f"{node}.{k}", v, f"one of the keys {[p.name for p in named]} that {where} takes")
    for p in named:
        if p.default is p.empty and p.name not in params:
            raise ConfigError(f"{node}.{p.name}", None, f"a value ({where} requires it)")
    return cls(**params)
