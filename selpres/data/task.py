"""The learning task a robot/data config defines: the exemplar set U, the test sets and the scaler.

The one place the pipeline gets its data, for every kind of ``data`` config:

* ``grid`` (``data=paper``): the paper's section 5.1 on the two-link arm of eq. (6), unchanged (1002
  patterns, the 10-pattern and held-out test sets of ``selpres.data.paper``);
* ``sampled`` (``data=sampled``): any arm (any ``robot._target_``: ``selpres.arms.sources``), any n, drawn by
  ``selpres.data.sampled`` (route forward or inverse, uniform or Sobol points); test sets drawn the same way
  from their own seed;
* ``file`` (``data=file``): the user's table (``selpres.data.file``), split into exemplar and held-out
  rows by ``data.test_seed``; the 10-pattern test set takes ``test_from_exemplar`` rows of the exemplar
  set and the rest from the held-out rows.

``task_shape`` says what the network must look like (its input and output names) without making any
data, so topology errors come before any work. ``Task.info`` records what was made (kind, route, draws,
acceptance rate, the arm, the data hash) for the log and results.json.

Takes specs, not configs: the robot as a ``selpres.registry.Choice`` (its source and parameters) and the data as a
``selpres.data.spec.DataSpec`` (``selpres.run.specs`` makes both). Built once per (robot, data) and cached, so the
jobs of an in-process sweep (Hydra's basic launcher) build the data once, and kept on disk (``selpres.data.cache``),
so the next job's process loads it; cached tensors are never modified in place. A task read from files (what the
arm's source declares it reads, a data file: :func:`task_files`) is keyed by their stamps and never stored, so an
edited file is read again; a user's source class outside the package is keyed by its module's content too.
Problems a config causes here (a filter that keeps nothing, ranges with nothing to draw test patterns from) are
ConfigErrors naming the key.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import json
import logging
from dataclasses import dataclass, field, replace
from pathlib import Path

import torch

from selpres.arms.sources import SOURCES, files_read, make_arm, source_of
from selpres.arms.two_link import TwoLinkArm, cfg_get
from selpres.data import export as E
from selpres.data import file as F
from selpres.data import paper as D
from selpres.data import sampled as S
from selpres.data.cache import cached
from selpres.data.spec import DataSpec
from selpres.errors import ConfigError
from selpres.registry import Choice
from selpres.seeding import derive_seed

log = logging.getLogger("selpres")

DATA_KEYS = {  # the keys of DataSpec each kind reads; the others must stay unset
    "grid": ("theta", "dtheta", "tau1", "tau2", "accel_limit"),
    "sampled": ("n", "route", "draw", "seed", "q", "dq", "tau", "wrench", "accel_limit"),
    "file": ("path", "inputs", "outputs"),
}


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

    exemplar: D.ExemplarSet
    tests: D.TestSets
    scaler: D.Scaler
    input_names: tuple[str, ...] = D.INPUT_NAMES
    output_names: tuple[str, ...] = D.TARGET_NAMES
    info: dict = field(default_factory=dict)
    arm: dict | None = None  # the arm's canonical description (to_config), None for a data file
    wrench: torch.Tensor | None = None  # the constant wrench k of a sampled set (None: zero)
    commanded: tuple[torch.Tensor, ...] | None = None  # the boxes' bounds (x lo, x hi, y lo, y hi), if any

    @property
    def n(self) -> int:
        return len(self.exemplar)

    def fit_scaler(self, data_cfg) -> D.Scaler:
        """The scaler ``data_cfg.scaling`` asks for on this exemplar set; ConfigError if it asks for the
        commanded boxes and the task has none (a data file, a sampled set without a torque box)."""
        mode = str(cfg_get(cfg_get(data_cfg, "scaling"), "mode"))
        if mode == "commanded" and self.commanded is None:
            why = (
                "a file has no commanded ranges"
                if self.info.get("kind") == "file"
                else "with data.tau=null there is no commanded torque box to scale the targets by"
            )
            raise ConfigError("data.scaling.mode", "commanded", f"exemplar: {why}")
        return D.Scaler.fit(self.exemplar, data_cfg, self.commanded)

    def scaled_tests(self) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
        """name -> (inputs scaled, targets in Nm): what the network is scored on."""
        return {
            name: (self.scaler.transform_x(p.X), p.Y)
            for name, p in (("test10", self.tests.test10), ("heldout", self.tests.heldout))
        }


def task_shape(robot: Choice, data: DataSpec) -> Shape:
    """The network's inputs and outputs for this task, from the arm (built, not simulated) or the data
    file's header; raises ConfigError (naming robot.*, data.* or the file), makes no data."""
    if data.kind == "file":
        ins, outs = F.check_columns(data.path, data.inputs, data.outputs)
        return Shape(ins, outs, f"data=file ({data.path})")
    arm = make_arm(robot)
    if data.kind == "grid":
        if not isinstance(arm, TwoLinkArm):
            raise ConfigError(
                "data.kind",
                "grid",
                f"sampled (data=sampled) for robot={arm.name} ({arm.dof} joints): "
                "the paper's grid (data=paper) is defined for robot=two_link only",
            )
        return Shape(D.INPUT_NAMES, D.TARGET_NAMES, "robot=two_link (2 joints, data=paper)")
    N = arm.dof
    S.boxes(arm, data)  # data.q, dq, tau, wrench against the arm's joints
    return Shape(
        S.input_names(N),
        S.output_names(N),
        f"robot={arm.name} ({N} joints)",
        f"q1..q{N}, dq1..dq{N}, ddq1..ddq{N}",
        f"tau1..tau{N}",
    )


def task_files(robot: Choice, data: DataSpec) -> list[Path]:
    """The files the task is read from: those the arm's source reads (``selpres.arms.sources.files_read``;
    none for a data file's task, which has no arm) and the data file."""
    arm_files = [] if data.kind == "file" else files_read(source_of(robot), robot.params)
    return [*arm_files, *data.reads_files()]


def _own_code(robot: Choice) -> str:
    """sha256 of a user's source module (outside selpres, whose code the cache key holds already), else ""."""
    cls = type(source_of(robot)) if "." in robot.target else None
    if cls is None or cls.__module__.split(".")[0] == "selpres":
        return ""
    try:
        return hashlib.sha256(Path(inspect.getsourcefile(cls)).read_bytes()).hexdigest()
    except (TypeError, OSError):  # no source file (a compiled module): keyed by its path only
        return ""


def load_task(robot: Choice, data: DataSpec) -> Task:
    """The task of a robot/data spec (cached); raises ConfigError, writes nothing."""
    stamp = [(str(p), p.stat().st_mtime_ns, p.stat().st_size) for p in task_files(robot, data) if p.is_file()]
    robot_json = json.dumps({"_target_": robot.target, **robot.params}, sort_keys=True)
    code = "" if data.kind == "file" else _own_code(robot)
    return _task(robot_json, json.dumps(data.as_dict(), sort_keys=True), json.dumps(stamp), code)


@functools.lru_cache(maxsize=4)
def _task(robot_json: str, data_json: str, files: str, code: str) -> Task:
    """``files``: the (path, mtime, size) of the files read, so an edited file is read again; ``code``: the
    digest of a user's source module."""
    params = json.loads(robot_json)
    robot, data = Choice(params.pop("_target_"), params), DataSpec.of(json.loads(data_json))

    def build() -> Task:
        task = {"grid": _grid, "sampled": _sampled, "file": _file}[data.kind](robot, data)
        task.info["hash"] = E.config_hash(robot, data)
        return task

    if json.loads(files):  # the user's files: reading them is most of the cost, and the key holds their
        task = build()  # stamps, not their contents (selpres.data.cache)
        task.info["cache"] = "not stored (read from a file)"
    else:
        task = cached(robot_json + code, data_json, build, Task)
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


def _check_test_split(data_cfg, n: int) -> tuple[int, int]:
    """(test patterns, of which from the exemplar set), checked against n."""
    n_test, n_ex = int(data_cfg.test_patterns), int(data_cfg.test_from_exemplar)
    if n_ex > n:
        raise ConfigError("data.test_from_exemplar", n_ex, f"at most the exemplar set's size n = {n}")
    return n_test, n_ex


def _grid(robot: Choice, data_cfg: DataSpec) -> Task:
    """The paper's section 5.1, exactly as Table 1 was computed."""
    arm = make_arm(robot)
    exemplar = D.build_exemplar_set(arm, data_cfg)
    n = len(exemplar)
    if n == 0:
        raise ConfigError(
            "data.accel_limit",
            data_cfg.accel_limit,
            f"a filter that keeps at least one of the {exemplar.n_candidates:,} grid candidates of "
            "data.theta/dtheta/tau1/tau2 (none has both |θ̈| within it: widen the limit or move the ranges)",
        )
    _check_test_split(data_cfg, n)
    heldout = D.heldout_count(data_cfg.heldout, n, f"n = {n}")
    data_cfg = replace(data_cfg, heldout=heldout)
    try:
        tests = D.make_test_sets(arm, data_cfg, exemplar, seed=data_cfg.test_seed)
    except ValueError as e:  # the continuous ranges leave nothing to draw test patterns from
        raise ConfigError("data", "theta/dtheta/tau1/tau2 ranges", str(e)) from None
    info = {
        "kind": "grid",
        "source": "the paper's grid on robot=two_link",
        "candidates": exemplar.n_candidates,
        "acceptance_rate": n / exemplar.n_candidates,
        "n": n,
        "arm": arm.to_config(),
        "arm_source": SOURCES.path_of(robot.target),
    }
    task = Task(exemplar, tests, None, info=info, arm=arm.to_config(), commanded=D.grid_bounds(data_cfg))
    return replace(task, scaler=task.fit_scaler(data_cfg))


def _sampled(robot: Choice, data_cfg: DataSpec) -> Task:
    """Any arm, any n: ``selpres.data.sampled``'s route and points; test sets from ``data.test_seed``."""
    arm = make_arm(robot)
    box = S.boxes(arm, data_cfg)
    route, draw, n = data_cfg.route, data_cfg.draw, int(data_cfg.n)
    log.info("%s", S.describe(box, route))
    drawn = S.sample(arm, box, route, S.stream(data_cfg, arm.dof, "exemplar"), n)
    exemplar = D.ExemplarSet(drawn.X, drawn.tau, n_candidates=drawn.candidates)
    n_test, n_ex = _check_test_split(data_cfg, n)
    gen = torch.Generator().manual_seed(int(data_cfg.test_seed))
    idx = torch.randperm(n, generator=gen)[:n_ex]
    points = S.stream(data_cfg, arm.dof, "tests")
    outside = S.sample(arm, box, route, points, n_test - n_ex)
    heldout = S.sample(arm, box, route, points, D.heldout_count(data_cfg.heldout, n, f"n = {n}"))
    test10 = D.Patterns(torch.cat((exemplar.X[idx], outside.X)), torch.cat((exemplar.Y[idx], outside.tau)))
    tests = D.TestSets(test10, torch.arange(n_test) < n_ex, D.Patterns(heldout.X, heldout.tau))
    info = {
        "kind": "sampled",
        "source": f"robot={arm.name}, route {route}, {draw} points",
        "route": route,
        "draw": draw,
        "n": n,
        "candidates": drawn.candidates,
        "acceptance_rate": n / drawn.candidates,
        "heldout_candidates": heldout.candidates,
        "arm": arm.to_config(),
        "arm_source": SOURCES.path_of(robot.target),
        "wrench": None if box.wrench is None else box.wrench.tolist(),
        "boxes": {k: None if v is None else v.tolist() for k, v in (("q", box.q), ("dq", box.dq), ("tau", box.tau))},
        **({"urdf": arm.source} if getattr(arm, "source", None) else {}),
    }
    task = Task(
        exemplar,
        tests,
        None,
        S.input_names(arm.dof),
        S.output_names(arm.dof),
        info,
        arm.to_config(),
        box.wrench,
        S.commanded_bounds(box),
    )
    return replace(task, scaler=task.fit_scaler(data_cfg))


def _file(robot: Choice, data_cfg: DataSpec) -> Task:
    """The user's table: held-out rows chosen by ``data.test_seed``, the rest (in file order) is U."""
    path = data_cfg.path
    ins, outs = F.check_columns(path, data_cfg.inputs, data_cfg.outputs)
    table = F.load_columns(path, [*ins, *outs])
    sc = data_cfg.scaling
    squeezed = F.check_ranges(path, [*ins, *outs], table, len(outs), *(float(sc[k]) for k in ("margin", "lo", "hi")))
    for w in squeezed:
        log.warning("%s", w)
    rows = table.shape[0]
    held_n = D.heldout_count(data_cfg.heldout, rows, f"the {rows} rows of {path}")
    n_test, n_ex = int(data_cfg.test_patterns), int(data_cfg.test_from_exemplar)
    if rows - held_n < max(1, n_ex) or held_n < n_test - n_ex:
        raise F.DataFileError(
            path,
            "rows",
            f"{rows:,}: too few to hold out data.heldout={data_cfg.heldout} "
            f"({held_n} rows, at least {n_test - n_ex} for the test patterns) and train on "
            f"the rest (at least {max(1, n_ex)} rows)",
        )
    perm = torch.randperm(rows, generator=torch.Generator().manual_seed(derive_seed(int(data_cfg.test_seed), "split")))
    held, train = perm[:held_n].sort().values, perm[held_n:].sort().values
    X, Y = table[:, : len(ins)], table[:, len(ins) :]
    exemplar = D.ExemplarSet(X[train].contiguous(), Y[train].contiguous(), n_candidates=rows)
    n = len(exemplar)
    gen = torch.Generator().manual_seed(int(data_cfg.test_seed))
    idx_ex = torch.randperm(n, generator=gen)[:n_ex]
    idx_out = held[torch.randperm(held_n, generator=gen)[: n_test - n_ex]]
    test10 = D.Patterns(torch.cat((exemplar.X[idx_ex], X[idx_out])), torch.cat((exemplar.Y[idx_ex], Y[idx_out])))
    tests = D.TestSets(test10, torch.arange(n_test) < n_ex, D.Patterns(X[held].contiguous(), Y[held].contiguous()))
    info = {
        "kind": "file",
        "source": f"data=file {path}",
        "path": str(path),
        "sha256": F.file_digest(path),
        "rows": rows,
        "heldout": held_n,
        "n": n,
        "inputs": list(ins),
        "outputs": list(outs),
        "warnings": squeezed,  # columns an outlier collapses (selpres.data.file.check_ranges)
    }
    task = Task(exemplar, tests, None, ins, outs, info)
    return replace(task, scaler=task.fit_scaler(data_cfg))
