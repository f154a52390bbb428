"""A task's data written out and read back: ``.npz`` plus one CSV per set, each stamped with the hash of the robot
and data config that made it (``selpres-export`` writes them; ``load_exported`` refuses a file made under another
config), and that hash itself, which also names a task in results.json.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping, Sequence
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np
import torch

from selpres.arms.sources import as_choice, make_arm
from selpres.data.file import file_digest
from selpres.data.paper import INPUT_NAMES, TARGET_NAMES
from selpres.data.spec import DataSpec
from selpres.patterns import ExemplarSet, Patterns, TestSets
from selpres.registry import Choice
from selpres.storage import atomic_write, stable_hash


class DataMismatchError(ValueError):
    """An exported data file was made with a different robot/data config than the one in use."""


def _plain(cfg: Any, fold: bool = True) -> Any:
    """A spec (``DataSpec``, a robot ``Choice``) or a mapping (a composed config's node too: any Mapping and
    Sequence) in its canonical form for hashing: ints folded into floats (``fold``), so ``m2: 3`` and ``m2: 3.0``
    hash alike, enums by name."""
    if isinstance(cfg, Choice):
        cfg = {"_target_": cfg.target, **cfg.params}
    elif isinstance(cfg, DataSpec):  # the flat node: common keys and the route's
        cfg = cfg.as_dict()
    elif dataclasses.is_dataclass(cfg) and not isinstance(cfg, type):
        cfg = dataclasses.asdict(cfg)
    if isinstance(cfg, Mapping):
        return {str(k): _plain(v, fold) for k, v in cfg.items()}
    if isinstance(cfg, Sequence) and not isinstance(cfg, (str, bytes)):
        return [_plain(v, fold) for v in cfg]
    if fold and isinstance(cfg, (int, float)) and not isinstance(cfg, bool):
        return float(cfg)
    if isinstance(cfg, Enum):  # typed configs hold enums (e.g. scaling.mode): hash their names
        return cfg.name
    return cfg


def data_kind(data_cfg: Any) -> str:
    """grid, sampled or file (a data config without ``kind`` is the paper's grid)."""
    try:
        kind = data_cfg["kind"]
    except (KeyError, AttributeError):
        return "grid"
    return str(getattr(kind, "value", kind))


def _set_keys(node: Any) -> Any:
    """Drop unset (None) keys: the keys another kind uses, which a composed config holds and a YAML lacks."""
    if isinstance(node, dict):
        return {k: _set_keys(v) for k, v in node.items() if v is not None}
    return node


def config_hash(robot_cfg: Any, data_cfg: Any) -> str:
    """Identity of the data: a stable hash of what made it. The arm enters canonically, by
    ``make_arm(robot).to_config()`` (a URDF's content, not its path; no arm for a data file); a data
    file by the sha256 of its bytes instead of its path; unset keys are left out and ints folded into
    floats, so a composed config, its YAML and ``m2: 3`` vs ``3.0`` hash alike."""
    data = _set_keys(_plain(data_cfg))
    if data_kind(data_cfg) == "file":
        data["path"] = file_digest(data_cfg["path"])
        robot = None
    else:
        spec = robot_cfg if isinstance(robot_cfg, Choice) else as_choice(_plain(robot_cfg, fold=False))
        robot = _plain(make_arm(spec).to_config())
    return stable_hash({"robot": robot, "data": data})


def _table(p: Patterns, wrench: torch.Tensor | None) -> np.ndarray:
    cols = [p.X, p.Y] + ([] if wrench is None else [wrench.expand(len(p), -1)])
    return torch.cat(cols, 1).cpu().numpy().astype(np.float64)


def export(
    path_stem: str | os.PathLike,
    exemplar: ExemplarSet,
    tests: TestSets,
    robot_cfg: Any,
    data_cfg: Any,
    *,
    input_names: tuple[str, ...] = INPUT_NAMES,
    target_names: tuple[str, ...] = TARGET_NAMES,
    arm: dict | None = None,
    wrench: torch.Tensor | None = None,
) -> dict[str, Path]:
    """Write ``<stem>.npz`` and ``<stem>_{exemplar,test10,heldout}.csv`` (``%.17g``: exact float64
    round trip). The CSVs start with ``# config_hash=...`` and, when an arm made the data,
    ``# arm=<its to_config() as JSON>``; then the header: the input names, the target names and, for a
    non-zero wrench k, its six constant columns ``k_fx..k_mz`` (eq. 4's force, then moment, base frame)."""
    stem = Path(path_stem)
    h = config_hash(robot_cfg, data_cfg)
    if wrench is not None and not bool(wrench.ne(0).any()):
        wrench = None
    from selpres.data.sampled import WRENCH_NAMES  # the wrench's column names belong to the sampled routes

    columns = tuple(input_names) + tuple(target_names) + (WRENCH_NAMES if wrench is not None else ())
    n_in = len(input_names)
    tables = {
        name: _table(p, wrench)
        for name, p in (("exemplar", exemplar), ("test10", tests.test10), ("heldout", tests.heldout))
    }
    arrays: dict[str, np.ndarray] = {}
    for name, t in tables.items():
        arrays[f"{name}_X"], arrays[f"{name}_Y"] = t[:, :n_in], t[:, n_in : n_in + len(target_names)]
    arrays["test10_from_exemplar"] = tests.test10_from_exemplar.cpu().numpy().astype(bool)
    arrays["input_names"] = np.array(input_names)
    arrays["target_names"] = np.array(target_names)
    arrays["config_hash"] = np.array(h)
    arrays["robot_config"] = np.array(json.dumps(_plain(robot_cfg), sort_keys=True))
    arrays["data_config"] = np.array(json.dumps(_plain(data_cfg), sort_keys=True))
    if arm is not None:
        arrays["arm"] = np.array(json.dumps(arm, sort_keys=True))
    if wrench is not None:
        arrays["wrench"] = wrench.cpu().numpy()

    paths = {"npz": stem.with_name(stem.name + ".npz")}
    atomic_write(paths["npz"], lambda f: np.savez(f, **arrays))
    arm_line = f"# arm={json.dumps(arm, sort_keys=True)}\n" if arm else ""
    header = f"# config_hash={h}\n" + arm_line + ",".join(columns)
    for name, t in tables.items():
        paths[name] = stem.with_name(f"{stem.name}_{name}.csv")
        atomic_write(
            paths[name], lambda f, t=t: np.savetxt(f, t, fmt="%.17g", delimiter=",", header=header, comments="")
        )
    return paths


def _check_hash(found: str, robot_cfg: Any, data_cfg: Any, path: Any) -> None:
    want = config_hash(robot_cfg, data_cfg)
    if found != want:
        raise DataMismatchError(
            f"{path} was made with config_hash={found}, but the current robot/data config has config_hash={want}; "
            "re-export the data (scripts/export_data.py) or use the matching config"
        )


def load_exported(path_npz: str | os.PathLike, robot_cfg: Any, data_cfg: Any) -> dict[str, np.ndarray]:
    """Arrays of an ``export`` npz; raises DataMismatchError if it was made with another robot/data config."""
    with np.load(path_npz, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    _check_hash(str(arrays["config_hash"]), robot_cfg, data_cfg, path_npz)
    return arrays


def load_csv(
    path: str | os.PathLike, robot_cfg: Any = None, data_cfg: Any = None
) -> tuple[str, tuple[str, ...], np.ndarray]:
    """(config_hash, column names, float64 table) of an exported CSV; checks the hash when configs are given."""
    comments = []
    with open(path) as f:
        line = f.readline().strip()
        while line.startswith("#"):
            comments.append(line)
            line = f.readline().strip()
    names = tuple(line.split(","))
    if not comments or not comments[0].startswith("# config_hash="):
        raise ValueError(f"{path}: first line should be '# config_hash=...', got {(comments or [line])[0]!r}")
    h = comments[0].split("=", 1)[1]
    if robot_cfg is not None or data_cfg is not None:
        _check_hash(h, robot_cfg, data_cfg, path)
    table = np.loadtxt(path, delimiter=",", skiprows=len(comments) + 1, dtype=np.float64, ndmin=2)
    return h, names, table
