"""Grouping: a method label per job, and the replicas of each (topology, method) pooled by seed.

A method is named one way in every section and study (``jobs.method_of``, :func:`method_labels`): the schedule's
name the job recorded, a user's class that ran (its selector or order, by import path) in brackets after it, and
the settings that differ between jobs of that name. Replica r of a job with seed s is the run with seed s + r, so
jobs of one method pool by seed: the union of their seeds, each seed once (a seed seen twice must give the same
numbers, else it is a warning). No method is named here: a label is what the job recorded, and the order of rows is
a study's (its ``ORDER``, handed in).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from selpres.report.jobs import Job
from selpres.run.legacy import selector_and_cost
from selpres.storage import flatten

SETS = (("test10", "test-10"), ("heldout", "held-out"))  # results.json key, name in the report
UNITS = (("nm", "Nm"), ("scaled", "scaled"))

# settings that never make two jobs different methods: bookkeeping, or what a group pools over
_NOT_A_METHOD = (
    "seed",
    "replicas",
    "name",
    "threads",
    "overwrite",
    "engine",
    "topology.",
    "logging.",
    "checkpoint.",
    "eval.",
)


@dataclass
class Group:
    """All replicas of one (topology, schedule) pooled over the jobs that ran it."""

    topology: str
    schedule: str
    jobs: list[Job] = field(default_factory=list)
    used: list[Job] = field(default_factory=list)  # jobs whose replicas are pooled
    by_seed: dict[int, dict] = field(default_factory=dict)  # seed -> replica result
    # seed -> [(epoch, presentations, held-out curve RMS Nm)]
    curves: dict[int, list[tuple[int, int, float]]] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    @property
    def sched(self) -> dict | None:
        return self.used[0].results["schedule"] if self.used else None

    @property
    def cost(self) -> int | float | None:
        """Presentations charged in all, per replica: training plus the forward passes spent choosing (the job's
        measured cost, :func:`job_cost`)."""
        return job_cost(self.used[0].results) if self.used else None

    @property
    def complete_seeds(self) -> list[int]:
        return sorted(s for s, r in self.by_seed.items() if r["status"] == "complete")

    @property
    def n_diverged(self) -> int:
        return sum(r["status"] != "complete" for r in self.by_seed.values())

    def values(self, set_: str, unit: str = "nm", joint: str = "overall") -> dict[int, float]:
        """seed -> final metric, complete replicas with a finite value only."""
        out = {}
        for s in self.complete_seeds:
            v = ((self.by_seed[s].get("final") or {}).get(set_) or {}).get(unit, {}).get(joint)
            if v is not None and math.isfinite(v):
                out[s] = float(v)
        return out

    def engines(self) -> dict:
        """The pooled jobs' engines, joined with "+" where they differ: the timing of a group is only as
        meaningful as the name of what produced it."""
        recs = [j.engine for j in self.used]
        return {
            k: "+".join(sorted({str(r[k]) for r in recs if r[k] is not None})) or None
            for k in ("engine", "engine_requested", "engine_fallback")
        }

    def wall(self) -> dict:
        """Summed over the pooled jobs: train seconds, total seconds, replicas; per replica-run = train / R
        (replicas are trained together, so a replica-run has no time of its own)."""
        train = sum(j.results["wall_seconds"]["train"] for j in self.used)
        total = sum(j.results["wall_seconds"]["total"] for j in self.used)
        reps = sum(j.results["replicas"] for j in self.used)
        return {"train": train, "total": total, "per_replica": train / reps if reps else None}


def job_cost(res: dict) -> int | float:
    """A job's total cost per replica, in presentations: back-propagated plus charged for choosing, the mean over
    its replicas as its ledger measured it (``cost.presentations``; an older file's as
    ``selpres.run.legacy.selector_and_cost`` reads it)."""
    return selector_and_cost(res)[1]["presentations"]


def presents_all(res: dict) -> bool:
    """Whether a finished job's results are conventional training: one stage of all of U, each epoch's every pattern
    presented by the staged selector (a compute-matched run's cut last epoch too)."""
    return len(res["schedule"]["sizes"]) == 1 and selector_and_cost(res)[0].get("name") == "staged"


def replica_costs(res: dict) -> list[float]:
    """Each replica's measured cost in presentations (trained and charged), from a job's results."""
    return selector_and_cost(res)[1]["per_replica"]["spent"]


def _sched_key(s: dict) -> tuple:
    """The schedule a job was asked to run: its plan's epochs, not the epochs a budget let it reach (those differ
    between a method's seed blocks, which are one method)."""
    epochs = s.get("planned_epochs") or s["epochs"]
    return (tuple(s["sizes"]), tuple(epochs), tuple(s.get("extra_presentations") or []), s.get("order"))


def _final_heldout(rep: dict) -> float | None:
    return ((rep.get("final") or {}).get("heldout") or {}).get("nm", {}).get("overall")


def _same_final(a: dict, b: dict, rel: float = 1e-9) -> bool:
    x, y = _final_heldout(a), _final_heldout(b)
    if x is None or y is None:
        return x is None and y is None
    return abs(x - y) <= rel * max(abs(x), abs(y))


def _add_job(g: Group, job: Job) -> None:
    g.jobs.append(job)
    if job.results is None:
        return
    if g.used and _sched_key(job.results["schedule"]) != _sched_key(g.sched):
        g.warnings.append(f"{job.path.name}: a different {g.schedule} schedule than {g.used[0].path.name}; not pooled")
        return
    g.used.append(job)
    for r, rep in enumerate(job.replicas):
        if rep["seed"] in g.by_seed:
            if not _same_final(g.by_seed[rep["seed"]], rep):
                g.warnings.append(f"{job.path.name}: seed {rep['seed']} disagrees with an earlier job; kept the first")
            continue
        g.by_seed[rep["seed"]] = rep
        g.curves[rep["seed"]] = [
            (c["epoch"], c["presentations"], c["heldout_rms_nm"][r])
            for c in job.results.get("curves") or []
            if c.get("heldout_rms_nm") is not None and c["heldout_rms_nm"][r] is not None
        ]


def method_rank(name: str, order: tuple[str, ...] = ()) -> tuple:
    """Where a method's rows go: the names listed in ``order`` (a study's) first, in that order, then the rest
    by name."""
    return (order.index(name) if name in order else len(order), name)


def topology_rank(t: str) -> tuple:
    return tuple(int(x) if x.isdigit() else 0 for x in t.split("-")), t


def base(method: str) -> str:
    """The schedule name a method label starts with ("<name> schedule.sizes=[…]" -> "<name>")."""
    return method.split(" ", 1)[0]


def optim_target(optim: dict) -> str | None:
    """The optimizer a results.json config names: ``optim._target_``, or ``optim.name`` in results written before."""
    return optim.get("_target_", optim.get("name"))


def settings(job: Job) -> dict[str, str]:
    """The job's resolved config as flat key -> compact JSON text, without the keys that never make two
    jobs different methods: what a method label, a family's swept parameters and a partner at the same
    cost are read from."""
    if not (job.results and "config" in job.results):
        return {}
    flat = flatten(job.results["config"])
    if "optim.name" in flat and "optim._target_" not in flat:  # results written before optim._target_
        flat["optim._target_"] = flat.pop("optim.name")
    return {k: json.dumps(v, separators=(",", ":")) for k, v in flat.items() if not k.startswith(_NOT_A_METHOD)}


def varying(members: list[dict[str, str]]) -> list[str]:
    """The keys whose value differs between the given settings (a key absent from some counts as
    differing), sorted."""
    keys = sorted({k for f in members for k in f})
    return [k for k in keys if len({f.get(k) for f in members}) > 1]


def setting_text(f: dict[str, str], keys: list[str]) -> str:
    """ "k=v k=v" for ``keys`` set in ``f``; a key a config does not have, or has as null (not set: an
    optimizer's own parameter in another optimizer's job), is left out. Labels stay distinct: two settings
    with the same text agree on every key set in either, and on the rest neither sets it."""
    return " ".join(f"{k}={f[k]}".replace('"', "") for k in keys if f.get(k, "null") != "null")


ROBOT = "robot."  # an arm's settings: its name, kind, links, masses, ... (configs/robot/)


def arm_name(f: dict[str, str]) -> str:
    """What an arm is called in a label: ``robot.name``, else its URDF file, else its source (for an arm whose
    file sets no name; ``robot.kind`` in results from before issue 25)."""
    for key in ("robot.name", "robot.path", "robot._target_", "robot.kind"):
        if (v := json.loads(f.get(key, "null"))) is not None:
            return str(v)
    return "?"


def arm_label(members: list[tuple[Job, dict[str, str]]], keys: list[str]) -> dict[int, str]:
    """id(job) -> the robot part of its label, when the arm differs between jobs of one schedule name:
    ``robot=<name>`` instead of the arm spelled out (its links run to thousands of characters), plus any
    robot key that differs between arms of one name (a mass overridden), so labels stay distinct. Nothing
    where each topology has one arm (a sweep over arms, each with its own network): groups
    are keyed by topology already, and a label naming the arm would make a grid of (topology, method) whose
    other-arm cells do not exist."""
    robot_keys = [k for k in keys if k.startswith(ROBOT)]
    if not robot_keys:
        return {}
    per_topology: dict[str | None, set] = {}
    for j, f in members:
        per_topology.setdefault(j.topology, set()).add(tuple(f.get(k) for k in robot_keys))
    if all(len(arms) == 1 for arms in per_topology.values()):
        return {}
    by_arm: dict[str, list[dict[str, str]]] = {}
    for _, f in members:
        by_arm.setdefault(arm_name(f), []).append(f)
    labels = {}
    for j, f in members:
        name = arm_name(f)
        same_name = [k for k in varying(by_arm[name]) if k.startswith(ROBOT)]
        labels[id(j)] = " ".join(filter(None, [f"robot={name}", setting_text(f, same_name)]))
    return labels


def method_labels(jobs: list[Job], within=None) -> dict[int, str]:
    """id(job) -> its method's label, for every job with results: the method it ran (``Job.method``), and when jobs
    of that name differ in other settings (a sweep over stage sizes, epochs, lr, ...), the settings that differ, so
    they are not pooled (an arm by its name: :func:`arm_label`). ``within(job)`` -> a key: compare only jobs of one
    key (a study whose rows are split by arm and regime already), by default the whole sweep."""
    by_name: dict[tuple, list[tuple[Job, dict]]] = {}
    for j in jobs:
        if j.results and "config" in j.results:
            key = (within(j) if within else None, j.method)
            by_name.setdefault(key, []).append((j, settings(j)))
    labels = {}
    for (_, name), members in by_name.items():
        keys = varying([f for _, f in members])
        arms = arm_label(members, keys)
        others = [k for k in keys if not k.startswith(ROBOT)]
        for j, f in members:
            text = " ".join(filter(None, [setting_text(f, others), arms.get(id(j), "")]))
            labels[id(j)] = name + " " + text if text else name
    return labels


def label_methods(jobs: list[Job]) -> None:
    """Every job with results labelled by its method (:func:`method_labels` over the whole sweep)."""
    labels = method_labels(jobs)
    for j in jobs:
        if id(j) in labels:
            j.schedule = labels[id(j)]


def aggregate(
    jobs: list[Job], order: tuple[str, ...] = ()
) -> tuple[dict[tuple[str, str], Group], list[str], list[str]]:
    """Groups keyed (topology, method), and the sorted topologies and methods seen in the sweep (methods in a
    study's ``order``, see :func:`method_rank`)."""
    label_methods(jobs)
    groups: dict[tuple[str, str], Group] = {}
    for job in sorted(jobs, key=lambda j: str(j.path)):
        key = (job.topology or "?", job.schedule or "?")
        _add_job(groups.setdefault(key, Group(*key)), job)
    topologies = sorted({t for t, _ in groups}, key=topology_rank)
    methods = sorted({m for _, m in groups}, key=lambda m: method_rank(m, tuple(order)))
    return groups, topologies, methods
