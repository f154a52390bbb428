"""The learning task a robot/data spec defines: the exemplar set U, the test sets and the scaler.

The one place the pipeline gets its data, for every data route (``selpres.data.routes``, by ``data.kind``:
``grid``, the paper's section 5.1; ``sampled``, any arm, any n; ``file``, the user's table).

``task_shape`` says what the network must look like (its input and output names) without making any
data, so topology errors come before any work. ``Task.info`` records what was made (kind, route, draws,
acceptance rate, the arm and its source, the data hash) for the log and results.json.

Takes specs, not configs: the robot as a ``selpres.registry.Choice`` (its source and parameters) and the data as a
``selpres.data.spec.DataSpec`` (``selpres.run.specs`` makes both). Built once per (robot, data) and cached, so the
jobs of an in-process sweep (Hydra's basic launcher) build the data once, and kept on disk (``selpres.data.cache``),
so the next job's process loads it; cached tensors are never modified in place. A task read from files (what the
arm's source and the data route declare they read: :func:`task_files`) is keyed by their stamps and never stored,
so an edited file is read again; a user's source or route class outside the package is keyed by its module's content
too.
Problems a config causes here (a filter that keeps nothing, ranges with nothing to draw test patterns from) are
ConfigErrors naming the key.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import json
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from selpres.arms.sources import as_choice, files_read, source_of
from selpres.data import export as E
from selpres.data import paper as D
from selpres.data.cache import cached
from selpres.data.routes import ROUTES, keys_of
from selpres.data.spec import DataSpec
from selpres.errors import ConfigError
from selpres.patterns import ExemplarSet, Scaler, TestSets
from selpres.registry import Choice

log = logging.getLogger("selpres")


def route_keys() -> dict[str, tuple[str, ...]]:
    """Built-in data.kind -> the keys that route reads besides the common ones (its ``Keys``)."""
    return {name: keys_of(ROUTES.get(name)) for name in ROUTES.names}


@dataclass(frozen=True)
class Shape:
    """What the network must look like for a task: its inputs and outputs by name, and what set them."""

    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    source: str  # "robot=puma560 (6 joints)", "data=file (my.csv)"
    inputs_text: str = ""  # how a message lists them ("q1..q6, dq1..dq6, ddq1..ddq6")
    outputs_text: str = ""

    def describe(self) -> str:
        ins = self.inputs_text or _listing(self.input_names)
        outs = self.outputs_text or _listing(self.output_names)
        return f"{len(self.input_names)} inputs ({ins}) and {len(self.output_names)} outputs ({outs})"


def _listing(names: tuple[str, ...]) -> str:
    return ", ".join(names) if len(names) <= 8 else f"{', '.join(names[:3])}, …, {names[-1]}"


@dataclass(frozen=True)
class Task:
    """Exemplar inputs/targets (raw units), the 10 test patterns and the held-out set, the scaler, the
    names of the columns, and ``info``: what was made and how (for the log and results.json)."""

    exemplar: ExemplarSet
    tests: TestSets
    scaler: Scaler
    input_names: tuple[str, ...] = D.INPUT_NAMES
    output_names: tuple[str, ...] = D.TARGET_NAMES
    info: dict = field(default_factory=dict)
    arm: dict | None = None  # the arm's canonical description (to_config), None for a data file
    wrench: torch.Tensor | None = None  # the constant wrench k of a sampled set (None: zero)
    commanded: tuple[torch.Tensor, ...] | None = None  # the boxes' bounds (x lo, x hi, y lo, y hi), if any

    @property
    def n(self) -> int:
        return len(self.exemplar)

    def fit_scaler(self, data_cfg) -> Scaler:
        """The scaler ``data_cfg.scaling`` asks for on this exemplar set; ConfigError if it asks for the
        commanded boxes and the task has none (a data file, a sampled set without a torque box)."""
        mode = str(data_cfg["scaling"]["mode"])
        if mode == "commanded" and self.commanded is None:
            why = (
                "a file has no commanded ranges"
                if self.info.get("kind") == "file"
                else "with data.tau=null there is no commanded torque box to scale the targets by"
            )
            raise ConfigError("data.scaling.mode", "commanded", f"exemplar: {why}")
        return Scaler.fit(self.exemplar, data_cfg["scaling"], self.commanded)

    def scaled_tests(self) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
        """name -> (inputs scaled, targets in Nm): what the network is scored on."""
        return {
            name: (self.scaler.transform_x(p.X), p.Y)
            for name, p in (("test10", self.tests.test10), ("heldout", self.tests.heldout))
        }


def task_shape(robot: Choice, data: DataSpec) -> Shape:
    """The network's inputs and outputs for this task, from the arm (built, not simulated) or the data
    file's header; raises ConfigError (naming robot.*, data.* or the file), makes no data."""
    return ROUTES.build(data.kind, {}).shape(robot, data)


def task_files(robot: Choice, data: DataSpec) -> list[Path]:
    """The files the task is read from: those the arm's source reads (``selpres.arms.sources.files_read``; none
    when the route uses no arm) and those the data route reads (a data file)."""
    route = ROUTES.build(data.kind, {})
    arm_files = files_read(source_of(robot), robot.params) if route.USES_ARM else []
    return [*arm_files, *route.reads_files(data)]


def _own_code(cls: type | None) -> str:
    """sha256 of a user's module (an arm source or a data route outside selpres, whose code the cache key holds
    already), else ""."""
    if cls is None or cls.__module__.split(".")[0] == "selpres":
        return ""
    try:
        return hashlib.sha256(Path(inspect.getsourcefile(cls)).read_bytes()).hexdigest()
    except (TypeError, OSError):  # no source file (a compiled module): keyed by its path only
        return ""


def load_task(robot: Choice | Mapping[str, Any], data: DataSpec | Mapping[str, Any]) -> Task:
    """The task of a robot and a data spec (what ``selpres.run`` hands this room), or of a job's recorded robot and
    data nodes (results.json's ``config["robot"]``, ``config["data"]``: plain mappings); cached; raises ConfigError,
    writes nothing."""
    robot = robot if isinstance(robot, Choice) else as_choice(robot)
    data = data if isinstance(data, DataSpec) else DataSpec.of(data)
    stamp = [(str(p), p.stat().st_mtime_ns, p.stat().st_size) for p in task_files(robot, data) if p.is_file()]
    robot_json = json.dumps({"_target_": robot.target, **robot.params}, sort_keys=True)
    route = ROUTES.get(data.kind)
    source = type(source_of(robot)) if route.USES_ARM and "." in robot.target else None
    code = _own_code(source) + _own_code(route if "." in data.kind else None)
    return _task(robot_json, json.dumps(data.as_dict(), sort_keys=True), json.dumps(stamp), code)


@functools.lru_cache(maxsize=4)
def _task(robot_json: str, data_json: str, files: str, code: str) -> Task:
    """``files``: the (path, mtime, size) of the files read, so an edited file is read again; ``code``: the
    digests of a user's source and route modules."""
    params = json.loads(robot_json)
    robot, data = Choice(params.pop("_target_"), params), DataSpec.of(json.loads(data_json))

    def build() -> Task:
        task = ROUTES.build(data.kind, {}).build(robot, data)
        task.info["hash"] = E.config_hash(robot, data)
        return task

    if json.loads(files):  # the user's files: reading them is most of the cost, and the key holds their
        task = build()  # stamps, not their contents (selpres.data.cache)
        task.info["cache"] = "not stored (read from a file)"
    else:
        task = cached(robot_json + code, data_json, build, Task)
    task.info["route_class"] = ROUTES.path_of(data.kind)  # the class that made it (a user's own by its path)
    i = task.info
    kept = (
        f" kept of {i['candidates']:,} candidates (acceptance {i['acceptance_rate']:.3g})" if "candidates" in i else ""
    )
    log.info(
        "exemplar set: %s patterns%s, %s; test10 %d, held-out %d%s",
        f"{task.n:,}",
        kept,
        i["source"],
        len(task.tests.test10),
        len(task.tests.heldout),
        "; loaded from the data cache (SELPRES_DATA_CACHE=off builds it)" if i["cache"].startswith("hit") else "",
    )
    return task


def check_test_split(data_cfg, n: int) -> tuple[int, int]:
    """(test patterns, of which from the exemplar set), checked against n."""
    n_test, n_ex = int(data_cfg.test_patterns), int(data_cfg.test_from_exemplar)
    if n_ex > n:
        raise ConfigError("data.test_from_exemplar", n_ex, f"at most the exemplar set's size n = {n}")
    return n_test, n_ex
