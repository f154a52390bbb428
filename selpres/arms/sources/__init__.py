"""Arm sources: where the arm of a ``robot`` node comes from, one module each (a registry, ``SOURCES``).

A robot node is ``{_target_: <source>, <its parameters>}``: ``_target_`` names a built-in source (a module of this
package: ``two_link``, ``serial``, ``urdf``) or a user's own class by its import path (``dh_arm.DHTable``); the
other keys are that source's parameters, which its class takes as keyword arguments and checks itself
(ConfigError naming ``robot.<key>``; :func:`selpres.registry.construct` refuses a key it does not take). A source
offers ``arm()``, the arm it describes, and ``reads_files()``, the files whose content the arm depends on: their
stamps key the task, so an edited file is never served stale (``selpres.data.task``). Adding a robot format is
one module here exporting ``SOURCE`` and one YAML in ``configs/robot/``; nothing else is edited.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from selpres.arms.two_link import Arm
from selpres.errors import ConfigError
from selpres.registry import Choice, Registry

SOURCES = Registry("robot._target_", "selpres.arms.sources", "SOURCE")


class ArmSource:
    """What a source offers (subclassing is optional: any class with ``arm()`` is a source)."""

    def arm(self) -> Arm:
        raise NotImplementedError

    def reads_files(self) -> Iterable[Path]:
        """The files the arm is read from (none: the node's parameters are the whole arm)."""
        return ()


def as_choice(node: Mapping[str, Any], key: str = "robot") -> Choice:
    """The source a plain robot node names. ``kind`` is accepted where ``_target_`` is not given: the spelling
    of an arm's canonical description (``arm.to_config()``) and of robot configs before issue 25, whose unset
    (None) keys of other kinds are dropped."""
    if not isinstance(node, Mapping):
        raise ConfigError(key, node, "a robot node {_target_: two_link|serial|urdf|package.module.Class, ...}")
    params = {str(k): v for k, v in node.items() if k not in ("_target_", "kind")}
    if "_target_" in node:
        if "kind" in node:
            kind = node["kind"]
            raise ConfigError(
                f"{key}.kind", kind, f"unset: the arm source is {key}._target_ now ({key}={kind} picks its node)"
            )
        return Choice(node["_target_"], params)
    if "kind" in node:
        return Choice(node["kind"], {k: v for k, v in params.items() if v is not None})
    raise ConfigError(f"{key}._target_", None, f"an arm source: {SOURCES.allowed()}")


def source_of(robot: Choice | Mapping[str, Any]) -> Any:
    """The source object of a robot spec (a Choice, or a plain node with ``_target_``)."""
    choice = robot if isinstance(robot, Choice) else as_choice(robot)
    return SOURCES.build(choice.target, choice.params)


def make_arm(robot: Choice | Mapping[str, Any]) -> Arm:
    """The arm a robot spec describes (ConfigError naming ``robot.<key>``; a URDF's errors name the file)."""
    return source_of(robot).arm()


def files_read(source: Any, params: Mapping[str, Any]) -> list[Path]:
    """The files ``source`` reads: what it declares (``reads_files()``), and every parameter that names an existing
    file, so a user's source that forgets to declare its ``path`` is still never served stale."""
    declared = getattr(source, "reads_files", lambda: ())()
    named = [Path(v).expanduser() for v in params.values() if isinstance(v, str) and v and _is_file(v)]
    out: list[Path] = []
    for p in [*map(Path, declared), *named]:
        if p not in out:
            out.append(p)
    return out


def _is_file(text: str) -> bool:
    try:
        return Path(text).expanduser().is_file()
    except (OSError, ValueError):  # a name too long or with a NUL: not a file
        return False
