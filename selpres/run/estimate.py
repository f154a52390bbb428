"""Refusals from estimates, before anything is allocated: memory that this machine does not have, and plans
that would take absurdly long (``replicas=1000000000``, ``'schedule.epochs=[1000000000,30,30,30,30]'``,
``schedule=matched schedule.budget=1e15``). Each is one ConfigError naming the key, the estimate and the limit.

Memory, in bytes (calibrated on this machine by peak RSS, ``python train.py replicas=R 'schedule.epochs=[1,1,1,1,1]'``:
R = 2,000: 573 MB, R = 8,000: 1,008 MB, R = 100,000: 8,579 MB, i.e. ~76-82 KB a replica at n = 1,002 on the native
engine; the model below gives 84 KB, an overestimate by a few per cent):

- per replica: its priority order and sampler state, the orders buffer and selection's copies, ~72 bytes per
  pattern of U (9 int64 arrays of n), its weights, momentum and gradients (8 float64 copies of W), ~4 KB of
  Python objects and its final results;
- per scored epoch (the history a job keeps, and writes as JSON at the end): ~400 bytes a record, and
  ~3 × (32 + 25) bytes a replica (three curves: Python floats, then their JSON text);
- torch evaluation (engine=torch/reference, batch methods and the mini-batch engine): replica blocks of at most
  R / 8 on the largest test set, [block, N, widest layer] float64 activations twice, plus [R, N, outputs] outputs.

The limit is what this process may still allocate: ``MemAvailable`` (/proc/meminfo), or the cgroup's limit, or
what the process's own caps leave (``ulimit -v``: RLIMIT_AS less the address space it has mapped, VmSize;
``ulimit -d``: RLIMIT_DATA less its data segment, VmData), whichever is lowest; ``SELPRES_MEMORY_LIMIT`` (bytes)
sets it, for a machine shared with other work (and for tests). An allocation that fails all the same (torch
raises RuntimeError "can't allocate memory", not MemoryError) is the same one-line refusal (selpres.run.job).

Time: a lower bound, at speeds no engine here reaches (10 us an epoch for the loop's bookkeeping, 0.1 ns per
weight per presentation and replica, ~10x faster than the native kernel's one-off timing); a plan whose lower
bound exceeds ``MAX_DAYS`` is refused as a typo rather than started.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from selpres.errors import ConfigError
from selpres.run.specs import ScheduleSpec

PER_PATTERN = 72  # bytes per replica per pattern of U
PER_WEIGHT = 8 * 8  # bytes per replica per weight (8 float64 copies)
PER_REPLICA = 4096  # bytes of Python objects per replica
PER_RECORD = 400  # bytes per history record, besides its per-replica numbers
PER_RECORD_REPLICA = 3 * (32 + 25)  # three curves: Python floats, then JSON text
SECONDS_PER_EPOCH = 10e-6  # lower bounds on the time of a job (see the module's docstring)
SECONDS_PER_WEIGHT_PRESENTATION = 0.1e-9
MAX_DAYS = 365
ENV = "SELPRES_MEMORY_LIMIT"


def available_memory() -> tuple[int, str]:
    """(bytes this job may allocate, where that figure comes from)."""
    env = os.environ.get(ENV)
    if env:
        return int(float(env)), f"{ENV}"
    best: tuple[int, str] | None = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    best = (int(line.split()[1]) * 1024, "MemAvailable in /proc/meminfo")
    except OSError:
        pass
    if best is None:
        try:
            best = (os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES"), "free physical memory")
        except (ValueError, OSError):
            best = (1 << 62, "unknown")
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(path) as f:
                limit = f.read().strip()
        except OSError:
            continue
        if limit.isdigit() and int(limit) < best[0]:
            best = (int(limit), f"the cgroup limit ({path})")
    for room in _rlimit_rooms():
        if room[0] < best[0]:
            best = room
    return best


def _rlimit_rooms() -> list[tuple[int, str]]:
    """(bytes left, why) under this process's RLIMIT_AS and RLIMIT_DATA, where set."""
    import resource

    try:
        with open("/proc/self/status") as f:
            status = {k: v.split() for k, _, v in (line.partition(":") for line in f)}
    except OSError:
        status = {}
    rooms = []
    for name, field, shell in (("RLIMIT_AS", "VmSize", "ulimit -v"), ("RLIMIT_DATA", "VmData", "ulimit -d")):
        soft, _ = resource.getrlimit(getattr(resource, name))
        if soft == resource.RLIM_INFINITY:
            continue
        used = int(status[field][0]) * 1024 if status.get(field) else 0
        rooms.append((max(0, soft - used), f"{name} ({shell}) {gb(soft)} less the {gb(used)} this process maps"))
    return rooms


def gb(b: float) -> str:
    """Bytes as people read them (decimal units)."""
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("KB", 1e3)):
        if b >= size / 10:
            return f"{b / size:,.1f} {unit}"
    return f"{b:,.0f} bytes"


@dataclass(frozen=True)
class Estimate:
    replica_bytes: float  # everything that grows with R, per replica
    history_bytes: float  # the history (grows with epochs and R)
    eval_bytes: float  # torch evaluation's working arrays
    fixed_bytes: float  # data and test sets
    seconds: float  # a lower bound
    records: int  # history records (scored epochs, the untrained network included)

    @property
    def total(self) -> float:
        return self.replica_bytes + self.history_bytes + self.eval_bytes + self.fixed_bytes


def estimate(
    replicas: int,
    sizes: tuple[int, ...],
    n: int,
    total_epochs: int,
    presentations: int,
    test_patterns: int = 0,
    torch_eval: bool = False,
    heldout_every: int = 0,
) -> Estimate:
    weights = sum((a + 1) * b for a, b in zip(sizes, sizes[1:]))
    per_replica = PER_PATTERN * n + PER_WEIGHT * weights + PER_REPLICA
    records = total_epochs + 1
    history = records * (PER_RECORD + PER_RECORD_REPLICA * replicas)
    if heldout_every:
        history += records / heldout_every * 8 * replicas
    ev = 0.0
    if torch_eval and test_patterns:
        block = min(replicas, max(1, (1 << 20) // max(1, test_patterns * max(sizes)), -(-replicas // 8)))
        ev = 8 * test_patterns * (2 * block * max(sizes) + replicas * sizes[-1])
    fixed = 8 * (n + test_patterns) * (sizes[0] + sizes[-1]) * 3
    seconds = total_epochs * SECONDS_PER_EPOCH + presentations * replicas * weights * SECONDS_PER_WEIGHT_PRESENTATION
    return Estimate(replicas * per_replica, history, ev, fixed, seconds, records)


def refuse_unfit(make: Callable[[int], Estimate], replicas: int, schedule_key: str, schedule_value) -> None:
    """ConfigError when ``make(replicas)`` exceeds the machine's memory or MAX_DAYS, naming ``replicas`` when
    one replica of the plan would fit and the schedule's key when even that would not."""
    est, one = make(replicas), make(1)
    limit, source = available_memory()
    blame = lambda over: (schedule_key, schedule_value) if over(one) or replicas == 1 else ("replicas", replicas)
    if est.total > limit:
        key, value = blame(lambda e: e.total > limit)
        if key == "replicas":
            per = (est.replica_bytes + est.eval_bytes + est.history_bytes) / replicas
            why = f"~{gb(per)} a replica" + (f", torch evaluation {gb(est.eval_bytes)}" if est.eval_bytes else "")
        else:
            why = f"its history of {one.records:,} scored epochs alone is {gb(est.history_bytes)}"
        raise ConfigError(
            key,
            value,
            f"a job that fits in memory: it needs an estimated {gb(est.total)} ({why}), this machine has "
            f"{gb(limit)} available ({source})",
        )
    if est.seconds > MAX_DAYS * 86400:
        key, value = blame(lambda e: e.seconds > MAX_DAYS * 86400)
        raise ConfigError(
            key,
            value,
            f"a job that can finish: it would take at least {est.seconds / 86400:,.0f} days even at speeds no "
            f"engine here reaches (limit {MAX_DAYS} days; selpres/run/estimate.py)",
        )


def refuse_before_task(replicas: int, layers: str, planned: ScheduleSpec) -> None:
    """The checks that need no data: replicas against memory at its smallest per replica (one pattern of U,
    no history), and a plan of more epochs than the history can hold, so ``replicas=1000000000`` is refused
    before the task is built or a list of seeds is made. ``planned``: the schedule as written."""
    from selpres.engines.model import parse_topology

    try:
        sizes = parse_topology(layers)
    except Exception:
        return  # check_topology names it
    epochs, budget = planned.epochs, planned.budget
    total = sum(int(e) for e in epochs) if epochs is not None and budget is None else 0
    key, value = ("schedule.epochs", list(epochs)) if total else ("schedule.budget", budget)
    refuse_unfit(lambda r: estimate(r, sizes, 1, total, 0), int(replicas), key, value)


@dataclass(frozen=True)
class Work:
    """What a job will hold and do, once its task is known: ``replicas`` of a network of ``sizes`` on ``n``
    patterns, ``planned`` as written (the key a refusal names), the plan on this n (``schedule``: its epochs and
    presentations), the largest test set, held-out scores every ``heldout_every`` epochs, and whether scoring runs
    in torch (its working arrays)."""

    replicas: int
    sizes: tuple[int, ...]
    planned: ScheduleSpec
    schedule: Any
    n: int
    test_patterns: int
    heldout_every: int
    torch_eval: bool


def refuse_job(w: Work) -> None:
    """The full estimate, once the exemplar set's size and the schedule are known (before any replica)."""
    s = w.planned.node  # what sets the plan's length: a budget, the epochs listed, or ΣN_i (the parametric schedule)
    name = next((k for k in ("budget", "epochs", "total_epochs") if s.get(k) is not None), "epochs")
    key, value = f"schedule.{name}", list(s[name]) if name == "epochs" and s.get(name) is not None else s.get(name)
    epochs, presentations = w.schedule.total_epochs, w.schedule.presentations
    make = lambda r: estimate(r, w.sizes, w.n, epochs, presentations, w.test_patterns, w.torch_eval, w.heldout_every)
    refuse_unfit(make, int(w.replicas), key, value)
