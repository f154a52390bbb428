"""The modern study's cells (:mod:`selpres_studies.modern`): its design file (roles, claims, the stall rule and the
statistic, display names), how a job's arm, regime and method are read from its results.json (the method as every
report section names it, ``selpres.report.method_labels``, within its arm and regime), and each (arm, regime, method)
cell's seeds, costs, wall seconds, held-out curves, stalls and hidden units."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

from selpres.report import Context, is_stalled, method_labels, optim_target
from selpres.report import job_cost as _job_cost
from selpres_studies._design import read_design

METRICS = (("rms", "held-out RMS", "Nm"), ("nmse", "held-out nMSE", ""))
DESIGN_FILE = Path(__file__).with_name("modern.yaml")  # modern.yaml: the study's roles and display names


@dataclass(frozen=True)
class Design:
    """The study's roles and display names (``modern.yaml``): which recorded method is the reference and which the
    compute-matched partner, the rows' order, and how arms, optimizers and activations are shown."""

    reference: str
    partner: str
    order: tuple[str, ...] = ()
    claims: dict = field(default_factory=dict)  # method -> its own published claim: comparable | lossless | speedup
    matched_within: float = 0.1  # a method within this share of the partner's cost is compared with it
    stall_share: float = 0.2  # stalled: final held-out RMS >= this share of the mean predictor's (selpres.run.stalls)
    trim: float = 0.2  # the converged error: this trimmed mean of the paired differences of the runs that did not stall
    remedies: dict = field(default_factory=dict)  # hidden units of a remedy -> the units of the regime it remedies
    arms: dict = field(default_factory=dict)
    optimizers: dict = field(default_factory=dict)
    activations: dict = field(default_factory=dict)

    @classmethod
    def load(cls, path: Path = DESIGN_FILE) -> Design:
        return read_design(cls, path)

    def methods(self, found) -> list[str]:
        """The methods of a sweep in the rows' order: the listed ones first, then the others by name."""
        found = set(found)
        listed = [m for m in self.order if m in found]
        return listed + sorted(found - set(listed))

    def rivals(self, found) -> list[str]:
        """Every method that may be compared with the partner: all but the reference and the partner itself
        (:func:`verdict_rows` keeps those whose cost is the partner's)."""
        return [m for m in self.methods(found) if m not in (self.reference, self.partner)]


DESIGN = Design.load()


def arm_of(cfg: dict, design: Design = DESIGN) -> str:
    r = cfg["robot"]
    key = r.get("name") or (r.get("path") and Path(r["path"]).stem) or r.get("_target_") or r.get("kind")
    return design.arms.get(str(key), str(key))


def regime_of(cfg: dict, design: Design = DESIGN) -> str:
    o, act = cfg["optim"], cfg.get("model", {}).get("activation", "sigmoid")
    name, b = optim_target(o), o["batch_size"]
    if name == "sgd" and b == 1 and act == "sigmoid" and o.get("lr_schedule", "constant") == "constant":
        return f"paper: sigmoid, online SGD (lr {o['lr']:g}, momentum {o.get('momentum') or 0:g})"
    # the rate is left out: it is chosen per arm (on a validation draw), and shown in the table's lr column; so is its
    # clock (a method's, as its authors run it: SeTa's cosine on the epochs is the regime's cosine)
    shape = "cosine" if o.get("lr_schedule") == "cosine_epochs" else o.get("lr_schedule")
    sched = f", {shape} lr" if shape else ""
    return f"{design.optimizers.get(name, name)} (batch {b}{sched}), {design.activations.get(act, act)}"


@functools.lru_cache(maxsize=8)
def _heldout_variance(robot_json: str, data_json: str) -> tuple[float, ...]:
    import json

    from selpres import load_task

    task = load_task(json.loads(robot_json), json.loads(data_json))
    return tuple(task.tests.heldout.Y.var(0, unbiased=False).tolist())


def heldout_nmse(job) -> dict[int, float]:
    """Per seed, held-out nMSE overall. Reads ``replica_results[r]["final"]["heldout"]["nmse"]["overall"]``
    where results.json holds it (selpres.run.floor, issue 21); else the same quantity from the per-joint RMS
    and the variance of the held-out targets, rebuilt from the job's config (one helper: swap it when every
    results.json carries nMSE)."""
    import json

    out, var = {}, None
    for rep in job.replicas:
        fin = rep["final"]
        if fin is None or fin["heldout"]["nm"].get("overall") is None:
            continue
        if "nmse" in fin["heldout"] and fin["heldout"]["nmse"].get("overall") is not None:
            out[rep["seed"]] = fin["heldout"]["nmse"]["overall"]
            continue
        if var is None:
            cfg = job.results["config"]
            var = _heldout_variance(json.dumps(cfg["robot"], sort_keys=True), json.dumps(cfg["data"], sort_keys=True))
        joints = [k for k in fin["heldout"]["nm"] if k != "overall"]
        per = [fin["heldout"]["nm"][j] ** 2 / v for j, v in zip(joints, var) if v > 0]
        out[rep["seed"]] = sum(per) / len(per)
    return out


@dataclass
class Cell:
    arm: str
    regime: str
    method: str
    costs: list[float] = field(default_factory=list)
    rms: dict[int, float] = field(default_factory=dict)
    nmse: dict[int, float] = field(default_factory=dict)
    engines: set[str] = field(default_factory=set)
    lrs: set[float] = field(default_factory=set)
    work: list[float] = field(default_factory=list)  # per job: the method's own wall seconds (job_work)
    curves: dict[int, list[tuple[float, float, float]]] = field(default_factory=dict)  # seed -> (cost, s, RMS)
    stalled: dict[int, bool] = field(default_factory=dict)  # seed -> stalled (design.stall_share of the floor)
    dead: dict[int, int] = field(default_factory=dict)  # seed -> dead hidden units at the end (results.json stalls)
    linear: dict[int, int] = field(default_factory=dict)  # seed -> linear ("always on") hidden units at the end
    hidden: int | None = None  # hidden units per net

    @property
    def cost(self) -> float | None:
        return sum(self.costs) / len(self.costs) if self.costs else None

    @property
    def wall(self) -> float | None:
        return sum(self.work) / len(self.work) if self.work else None

    def values(self, metric: str) -> dict[int, float]:
        return self.rms if metric == "rms" else self.nmse

    def converged(self, metric: str) -> dict[int, float]:
        """The seeds that did not stall (and whose stall is known), with their final value of ``metric``."""
        return {s: v for s, v in self.values(metric).items() if self.stalled.get(s) is False}


def job_cost(res: dict) -> float:
    """Total cost in presentations: training plus forward passes charged for choosing, each replica's as measured,
    averaged (``selpres.report.groups.job_cost``)."""
    return _job_cost(res)


def job_work(res: dict) -> float | None:
    """The method's own wall seconds in a job (all its replicas at once): choosing (scoring, k-means, selection),
    shuffling and training; not preparing the data, evaluating, logging or checkpointing, which every method
    shares."""
    sec = res.get("wall_seconds") or {}
    parts = [sec.get(k) for k in ("select", "shuffle", "train")]
    return sum(v for v in parts if isinstance(v, (int, float))) if any(v is not None for v in parts) else None


def job_curves(res: dict) -> dict[int, list[tuple[float, float, float]]]:
    """Per seed, the held-out curve as (cost so far, the method's seconds so far, held-out curve RMS in Nm): the
    points where the held-out set was scored and the job recorded its seconds (``work_seconds``)."""
    out: dict[int, list] = {}
    for rec in res.get("curves") or []:
        if rec.get("heldout_rms_nm") is None or rec.get("work_seconds") is None:
            continue
        for seed, v in zip(res["seeds"], rec["heldout_rms_nm"]):
            if v is not None and math.isfinite(v):
                out.setdefault(seed, []).append((float(rec["presentations"]), float(rec["work_seconds"]), v))
    return out


def cells(ctx: Context, design: Design = DESIGN) -> dict[tuple[str, str, str], Cell]:
    """Every finished job's replicas in its (arm, regime, method) cell, the method labelled as in every section
    (jobs of one name that differ in another setting within an arm and regime are apart). A seed seen in two jobs
    of one cell keeps the first job's numbers (jobs in folder order, as the report's groups pool them)."""
    done = sorted(
        (j for j in ctx.jobs if j.status in ("complete", "diverged") and j.results), key=lambda j: str(j.path)
    )
    axes = {id(j): (arm_of(j.results["config"], design), regime_of(j.results["config"], design)) for j in done}
    labels = method_labels(done, within=lambda j: axes[id(j)])
    out: dict[tuple[str, str, str], Cell] = {}
    for job in done:
        res, cfg = job.results, job.results["config"]
        key = (*axes[id(job)], labels[id(job)])
        c = out.setdefault(key, Cell(*key))
        c.costs.append(job_cost(res))
        if job_work(res) is not None:
            c.work.append(job_work(res))
        for seed, curve in job_curves(res).items():
            c.curves.setdefault(seed, curve)
        c.engines.add(res.get("engine", "?"))
        c.lrs.add(cfg["optim"]["lr"])
        for rep in job.replicas:
            v = rep["final"]["heldout"]["nm"]["overall"] if rep["final"] else None
            if v is not None and math.isfinite(v):
                c.rms.setdefault(rep["seed"], v)
        for seed, v in heldout_nmse(job).items():
            c.nmse.setdefault(seed, v)
        job_stalls(c, res, job.replicas, design.stall_share)
    return out


def job_stalls(c: Cell, res: dict, replicas: list[dict], share: float) -> None:
    """Each seed's stall (its final held-out RMS against ``share`` of the floor: :func:`selpres.run.stalls.is_stalled`)
    and, where results.json has its ``stalls``, its dead and linear hidden units; into the cell (a seed already there
    keeps the first job's, as its errors do)."""
    floor = ((res.get("floor") or {}).get("heldout") or {}).get("nm", {}).get("overall")
    for rep in replicas:
        rms = rep["final"]["heldout"]["nm"]["overall"] if rep["final"] else None
        flag = is_stalled(rms, floor, share)
        if flag is not None:
            c.stalled.setdefault(rep["seed"], flag)
    record = res.get("stalls") or {}
    for entry in record.get("replicas") or []:
        if entry.get("dead") is not None and entry["seed"] not in c.dead:
            c.dead[entry["seed"]], c.linear[entry["seed"]] = entry["dead"], entry["linear"]
    c.hidden = record.get("hidden_units", c.hidden)


def _order(methods: list[str]):
    """Rows by arm, the paper's regime first, then the methods in the design's order."""
    return lambda key: (key[0], not key[1].startswith("paper"), key[1], methods.index(key[2]))


def _arm_regimes(cs: dict, design: Design) -> list[tuple[str, str]]:
    methods = design.methods(m for _, _, m in cs)
    return sorted({(a, r) for a, r, _ in cs}, key=lambda k: _order(methods)((*k, methods[0])))
