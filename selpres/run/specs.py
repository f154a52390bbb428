"""The composed config turned into plain Python, once, for the rooms below ``run`` (which never see omegaconf).

``plain`` is the one "to plain values" helper: interpolations resolved, enums as their names, nested nodes as dicts
and lists. ``robot_spec`` and ``data_spec`` give the task's two specs: the robot node as a
``selpres.registry.Choice`` (its ``_target_`` and parameters; ``selpres.arms.sources`` builds the arm) and the data
node as a ``selpres.data.spec.DataSpec``.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import Enum
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf

from selpres.arms.sources import as_choice
from selpres.data.spec import DataSpec
from selpres.registry import Choice


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
    """The robot node as (``_target_``, parameters): ConfigError naming ``robot._target_`` when it names none."""
    return as_choice(plain(node))


def data_spec(node: Any) -> DataSpec:
    return DataSpec.of(plain(node))


def task_specs(cfg: Any) -> tuple[Choice, DataSpec]:
    """(robot, data) of a composed training config: what ``selpres.data.task.load_task`` takes."""
    return robot_spec(cfg.robot), data_spec(cfg.data)
