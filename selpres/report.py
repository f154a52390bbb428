"""Table 1 of the paper from a sweep's ``results.json`` files: tables, verdicts, time-to-target, plots.

    python -m selpres.report outputs/sweeps/table1 [--out DIR]     (default DIR = <sweep>/report)

Read top to bottom: ``load_jobs`` finds every job folder under the sweep (finished, diverged, failed or
missing); ``aggregate`` groups them by (topology, schedule) and pools their replicas by seed; the
``*_rows`` functions build the tables as lists of dicts (one CSV row each); ``*_markdown`` render them;
``plot_*`` draw the figures; ``write_report`` puts it all in the output folder.

Conventions: diverged replicas are left out of every mean and interval but counted; comparisons with
``selective`` are paired by seed (only seeds complete in both); intervals are Student-t 95 % intervals
from :mod:`selpres.stats`.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from selpres.stats import summarize
from selpres.storage import RESULTS, atomic_write

REFERENCE = "selective"  # the method every verdict compares against the others
BASELINE = "conventional"  # the method whose final curve value is the time-to-target target
METHOD_ORDER = ["conventional", "selective", "matched", "random_growth"]
SETS = (("test10", "test-10"), ("heldout", "held-out"))
UNITS = (("nm", "Nm"), ("scaled", "scaled"))

# The paper's Table 1. T_con/t = 1002·150 = 150,300 (the paper prints "1,50,000t"); RMS units unstated.
PAPER = {
    "conventional": {
        "p": 0, "sizes": [1002], "epochs": [150], "presentations": 150_300, "printed": "1,50,000t",
        "rms": {"6-4-2": 0.0554, "6-8-2": 0.1039, "6-13-2": 0.0872},
    },
    "selective": {
        "p": 4, "sizes": [50, 100, 400, 800, 1002], "epochs": [30] * 5, "presentations": 70_560,
        "printed": "70,560t",
        "rms": {"6-4-2": 0.0581, "6-8-2": 0.0659, "6-13-2": 0.0824},
    },
}
PAPER_UNITS_NOTE = "paper (units unstated)"


# ------------------------------------------------------------------------------------------- load
@dataclass
class Job:
    """One job folder of the sweep."""

    path: Path  # the job folder
    status: str  # complete | diverged | failed | missing | unreadable
    schedule: str | None
    topology: str | None
    results: dict | None = None  # the full results.json of a complete/diverged job
    error: str | None = None

    @property
    def replicas(self) -> list[dict]:
        return self.results["replica_results"] if self.results else []


def _hydra_identity(folder: Path) -> tuple[str | None, str | None]:
    """(schedule name, topology) of a job without usable results: from .hydra/config.yaml, else the folder name."""
    cfg = folder / ".hydra" / "config.yaml"
    if cfg.exists():
        try:
            import yaml

            c = yaml.safe_load(cfg.read_text()) or {}
            return (c.get("schedule") or {}).get("name"), (c.get("topology") or {}).get("layers")
        except Exception:  # noqa: BLE001 - fall back to the folder name
            pass
    m_s = re.search(r"(?:^|,)schedule=([^,]+)", folder.name)
    m_t = re.search(r"(?:^|,)topology=([^,]+)", folder.name)
    return (m_s.group(1) if m_s else None), (m_t.group(1) if m_t else None)


def _job_folders(sweep: Path) -> list[Path]:
    """Folders holding a results.json or a Hydra job record (.hydra/), anywhere under the sweep."""
    found = {p.parent for p in sweep.rglob(RESULTS)} | {p.parent for p in sweep.rglob(".hydra") if p.is_dir()}
    return sorted(f for f in found if f != sweep or (f / RESULTS).exists())


def load_job(folder: Path) -> Job:
    path = folder / RESULTS
    if not path.exists():
        s, t = _hydra_identity(folder)
        return Job(folder, "missing", s, t, error="no results.json (killed, or still running)")
    try:
        res = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        s, t = _hydra_identity(folder)
        return Job(folder, "unreadable", s, t, error=f"results.json unreadable: {e}")
    status = res.get("status")
    if status in ("complete", "diverged"):
        return Job(folder, status, res["schedule"]["name"], res["topology"], results=res)
    s, t = _hydra_identity(folder)
    err = res.get("error", "no error recorded")
    if res.get("kind"):
        err = f"{res['kind']}: {err}"
    return Job(folder, "failed" if status == "failed" else f"unknown status {status!r}", s, t, error=err)


def load_jobs(sweep: Path) -> list[Job]:
    return [load_job(f) for f in _job_folders(sweep)]


# -------------------------------------------------------------------------------------- aggregate
@dataclass
class Group:
    """All replicas of one (topology, schedule) pooled over the jobs that ran it."""

    topology: str
    schedule: str
    jobs: list[Job] = field(default_factory=list)
    used: list[Job] = field(default_factory=list)  # jobs whose replicas are pooled
    by_seed: dict[int, dict] = field(default_factory=dict)  # seed -> replica result
    curves: dict[int, list[tuple[int, int, float]]] = field(default_factory=dict)  # seed -> [(epoch, pres, heldout)]
    warnings: list[str] = field(default_factory=list)

    @property
    def sched(self) -> dict | None:
        return self.used[0].results["schedule"] if self.used else None

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

    def wall(self) -> dict:
        """Summed over the pooled jobs: train seconds, total seconds, replicas; per replica-run = train / R."""
        train = sum(j.results["wall_seconds"]["train"] for j in self.used)
        total = sum(j.results["wall_seconds"]["total"] for j in self.used)
        reps = sum(j.results["replicas"] for j in self.used)
        return {"train": train, "total": total, "per_replica": train / reps if reps else None}


def _sched_key(s: dict) -> tuple:
    return (tuple(s["sizes"]), tuple(s["epochs"]), tuple(s.get("extra_presentations") or []), s.get("order"))


def _add_job(g: Group, job: Job) -> None:
    g.jobs.append(job)
    if job.results is None:
        return
    if g.used and _sched_key(job.results["schedule"]) != _sched_key(g.sched):
        g.warnings.append(f"{job.path.name}: a different {g.schedule} schedule than {g.used[0].path.name}; not pooled")
        return
    # replica r of a job with seed s is the run with seed s + r, so jobs pool by seed: the union of their
    # seeds, each seed once (a seed seen twice must give the same numbers, else it is a warning)
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


def _same_final(a: dict, b: dict, rel: float = 1e-9) -> bool:
    x = ((a.get("final") or {}).get("heldout") or {}).get("nm", {}).get("overall")
    y = ((b.get("final") or {}).get("heldout") or {}).get("nm", {}).get("overall")
    return (x is None and y is None) or (x is not None and y is not None and abs(x - y) <= rel * max(abs(x), abs(y)))


def _method_rank(name: str) -> tuple:
    return (METHOD_ORDER.index(name) if name in METHOD_ORDER else len(METHOD_ORDER), name)


def _topology_rank(t: str) -> tuple:
    return tuple(int(x) if x.isdigit() else 0 for x in t.split("-")), t


# settings that never make two jobs different methods: bookkeeping, or what a group pools over
_NOT_A_METHOD = ("seed", "replicas", "name", "threads", "overwrite", "engine", "topology.", "logging.", "checkpoint.", "eval.")


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        out.update(_flat(v, key + ".") if isinstance(v, dict) else {key: json.dumps(v)})
    return out


def label_methods(jobs: list[Job]) -> None:
    """A job's method is its schedule's name; when jobs of one name differ in other settings (a sweep over
    stage sizes, epochs, lr, ...), the settings that differ are added to the name, so they are not pooled."""
    by_name: dict[str, list[tuple[Job, dict]]] = {}
    for j in jobs:
        if j.results and "config" in j.results:
            flat = {k: v for k, v in _flat(j.results["config"]).items() if not k.startswith(_NOT_A_METHOD)}
            by_name.setdefault(j.schedule, []).append((j, flat))
    for name, members in by_name.items():
        keys = sorted({k for _, f in members for k in f})
        varying = [k for k in keys if len({f.get(k) for _, f in members}) > 1]
        for j, f in members:
            if varying:
                j.schedule = name + " " + " ".join(f"{k}={f.get(k)}".replace('"', "").replace(" ", "") for k in varying)


def aggregate(jobs: list[Job]) -> tuple[dict[tuple[str, str], Group], list[str], list[str]]:
    """Groups keyed (topology, method), and the sorted topologies and methods seen in the sweep."""
    label_methods(jobs)
    groups: dict[tuple[str, str], Group] = {}
    for job in sorted(jobs, key=lambda j: str(j.path)):
        key = (job.topology or "?", job.schedule or "?")
        _add_job(groups.setdefault(key, Group(*key)), job)
    topologies = sorted({t for t, _ in groups}, key=_topology_rank)
    methods = sorted({m for _, m in groups}, key=_method_rank)
    return groups, topologies, methods


# ----------------------------------------------------------------------------------------- tables
def _fmt(x, nd: int = 4) -> str:
    return "n/a" if x is None else f"{x:.{nd}f}"


def _mean_std(s: dict, nd: int = 4) -> str:
    if s["mean"] is None:
        return "n/a"
    return _fmt(s["mean"], nd) + (f" ± {_fmt(s['std'], nd)}" if s["std"] is not None else "")


def _ci(s: dict, nd: int = 4) -> str:
    lo, hi = s["ci95"]
    return "n/a" if lo is None else f"[{_fmt(lo, nd)}, {_fmt(hi, nd)}]"


def replicas_text(g: Group) -> str:
    n, bad = len(g.by_seed), g.n_diverged
    return f"{n - bad}/{n}" + (f" ({bad} diverged)" if bad else "")


def matches_paper(g: Group) -> str:
    """'yes' when the schedule is the paper's (conventional, selective, random_growth's stages, matched budget)."""
    s = g.sched
    ref = {"random_growth": "selective"}.get(g.schedule, g.schedule)
    if s is None:
        return ""
    if g.schedule == "matched":
        return "yes" if s["presentations"] == PAPER["selective"]["presentations"] else "no"
    if ref not in PAPER:
        return "n/a"
    return "yes" if (s["sizes"], s["epochs"]) == (PAPER[ref]["sizes"], PAPER[ref]["epochs"]) else "no"


def table1_rows(groups, topologies, methods) -> list[dict]:
    """One row per (method, topology): schedule, cost, wall time, paper RMS and our RMS statistics."""
    rows = []
    for m in methods:
        for t in topologies:
            g = groups.get((t, m))
            row = {"method": m, "topology": t}
            if g is None or g.sched is None:
                row["replicas"] = "no results"
                rows.append(row)
                continue
            s, w = g.sched, g.wall()
            row.update(
                p=s["p"], sizes=" ".join(map(str, s["sizes"])), epochs=" ".join(map(str, s["epochs"])),
                extra_presentations=sum(s.get("extra_presentations") or [0]),
                presentations=s["presentations"], paper_presentations=PAPER.get(m, {}).get("presentations"),
                cost_ratio_vs_equal_epochs=s["cost_ratio"], paper_setting=matches_paper(g),
                replicas=replicas_text(g), n_complete=len(g.complete_seeds), n_diverged=g.n_diverged,
                wall_train_per_replica_s=w["per_replica"], wall_train_job_s=w["train"], wall_total_job_s=w["total"],
                paper_rms=PAPER.get(m, {}).get("rms", {}).get(t),
            )
            for set_, _ in SETS:
                for unit, _ in UNITS:
                    st = summarize(g.values(set_, unit).values())
                    k = f"{set_}_{unit}"
                    row.update({f"{k}_n": st["n"], f"{k}_mean": st["mean"], f"{k}_std": st["std"],
                                f"{k}_ci_lo": st["ci95"][0], f"{k}_ci_hi": st["ci95"][1]})
            rows.append(row)
    return rows


def _stat_of(row: dict, k: str) -> dict:
    return {"mean": row.get(f"{k}_mean"), "std": row.get(f"{k}_std"),
            "ci95": [row.get(f"{k}_ci_lo"), row.get(f"{k}_ci_hi")]}


def table1_markdown(rows: list[dict]) -> str:
    """The paper's layout: attributes down the side, one column per (method, topology)."""
    def cell(r, label):
        if r.get("presentations") is None:
            return "—" if label != "replicas complete" else r.get("replicas", "")
        m = r["method"]
        paper = PAPER.get(m)
        if label == "p":
            return str(r["p"]) if r["p"] else "-"
        if label == "size of the set n_i":
            return r["sizes"]
        if label == "no. of epochs N_i":
            return r["epochs"] + (f" (+{r['extra_presentations']} presentations)" if r["extra_presentations"] else "")
        if label == "total time T (ours)":
            return f"{r['presentations']:,}t"
        if label == "total time T (paper)":
            return (f"{paper['presentations']:,}t" + (f" (printed {paper['printed']})" if m == "conventional" else "")
                    if paper else "not in paper")
        if label == "paper's n_i, N_i (or budget)?":
            return r["paper_setting"]
        if label == "wall s per replica-run (job train / total)":
            return (f"{r['wall_train_per_replica_s']:.3g} ({r['wall_train_job_s']:.3g} / {r['wall_total_job_s']:.3g})")
        if label == "replicas complete":
            return r["replicas"]
        if label == "rms error, paper¹":
            return _fmt(r["paper_rms"]) if r["paper_rms"] is not None else "—"
        set_, unit, what = LABEL_KEYS[label]
        st = _stat_of(r, f"{set_}_{unit}")
        return _mean_std(st) if what == "ms" else _ci(st)

    header = ["Table 1"] + [f"{r['method']} {r['topology']}" for r in rows]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label in TABLE1_LABELS:
        lines.append("| " + " | ".join([label] + [cell(r, label) for r in rows]) + " |")
    return "\n".join(lines)


LABEL_KEYS = {}
for _set, _sname in SETS:
    for _unit, _uname in UNITS:
        LABEL_KEYS[f"{_sname} RMS {_uname}, mean ± std"] = (_set, _unit, "ms")
        LABEL_KEYS[f"{_sname} RMS {_uname}, 95 % CI"] = (_set, _unit, "ci")
TABLE1_LABELS = [
    "p", "size of the set n_i", "no. of epochs N_i", "total time T (ours)", "total time T (paper)", "paper's n_i, N_i (or budget)?",
    "wall s per replica-run (job train / total)", "replicas complete", "rms error, paper¹", *LABEL_KEYS,
]


def reading(s: dict, ref_mean: float | None, unit: str = "Nm", name: str = REFERENCE) -> str:
    """Plain words for a paired difference name − other (negative = ``name`` has the lower error)."""
    if s["n"] < 2 or s["ci95"][0] is None:
        return f"too few pairs ({s['n']}) for an interval"
    lo, hi = s["ci95"]
    if lo <= 0 <= hi:
        return "no detectable difference"
    d = s["mean"]
    pct = f" ({abs(d) / ref_mean * 100:.1f} %)" if ref_mean else ""
    return f"{name} {'better' if d < 0 else 'worse'} by {abs(d):.4f} {unit}{pct}"


def paired(a: dict[int, float], b: dict[int, float]) -> tuple[dict, float | None]:
    """Summary of a[s] − b[s] over the seeds in both, and the mean of b over those seeds."""
    seeds = sorted(set(a) & set(b))
    st = summarize(a[s] - b[s] for s in seeds)
    return st, (sum(b[s] for s in seeds) / len(seeds) if seeds else None)


def _base(method: str) -> str:
    """The schedule name a method label starts with ("selective schedule.sizes=[…]" -> "selective")."""
    return method.split(" ", 1)[0]


def comparisons(methods: list[str]) -> list[tuple[str, str]]:
    """(a, b) pairs to compare as a − b: every selective variant against every other method; a sweep of
    selective variants alone compares each variant with the first."""
    refs = [m for m in methods if _base(m) == REFERENCE]
    others = [m for m in methods if _base(m) != REFERENCE]
    if others:
        return [(r, o) for r in refs for o in others]
    return [(r, refs[0]) for r in refs[1:]]


def verdict_rows(groups, topologies, methods) -> list[dict]:
    """Selective against every other method, per topology, paired by seed, held-out and test-10 (Nm)."""
    rows = []
    for t in topologies:
        for a, b in comparisons(methods):
            ga, gb = groups.get((t, a)), groups.get((t, b))
            row = {"topology": t, "comparison": f"{a} vs {b}"}
            if ga is None or gb is None or ga.sched is None or gb.sched is None:
                missing = a if ga is None or ga.sched is None else b
                row["reading_heldout"] = f"no results for {missing}"
                rows.append(row)
                continue
            row["cost_ratio"] = ga.sched["presentations"] / gb.sched["presentations"]
            for set_, _ in SETS:
                st, ref = paired(ga.values(set_), gb.values(set_))
                row.update({f"{set_}_pairs": st["n"], f"{set_}_diff_mean": st["mean"], f"{set_}_diff_std": st["std"],
                            f"{set_}_ci_lo": st["ci95"][0], f"{set_}_ci_hi": st["ci95"][1],
                            f"{set_}_other_mean": ref, f"reading_{set_}": reading(st, ref, name=_base(a))})
            rows.append(row)
    return rows


def verdict_markdown(rows: list[dict]) -> str:
    head = ["topology", "comparison", "cost ratio", "pairs", "held-out Δ Nm, mean [95 % CI]", "held-out reading",
            "test-10 Δ Nm, mean [95 % CI]", "test-10 reading"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        def d(set_):
            if r.get(f"{set_}_diff_mean") is None:
                return "n/a"
            return f"{r[f'{set_}_diff_mean']:+.4f} " + _ci({"ci95": [r[f"{set_}_ci_lo"], r[f"{set_}_ci_hi"]]})
        lines.append("| " + " | ".join([
            r["topology"], r["comparison"], _fmt(r.get("cost_ratio"), 3),
            str(r.get("heldout_pairs", 0)), d("heldout"), r.get("reading_heldout", ""),
            d("test10"), r.get("reading_test10", ""),
        ]) + " |")
    return "\n".join(lines)


def mean_curve(g: Group) -> list[tuple[int, float, dict]]:
    """[(cumulative presentations, mean held-out curve RMS Nm, summarize(...))] over complete seeds, by epoch."""
    pts: dict[int, tuple[int, list[float]]] = {}
    for s in g.complete_seeds:
        for ep, pres, v in g.curves.get(s, []):
            pts.setdefault(ep, (pres, []))[1].append(v)
    out = []
    for ep in sorted(pts):
        pres, vals = pts[ep]
        st = summarize(vals)
        out.append((pres, st["mean"], st))
    return out


def time_to_target_rows(groups, topologies, methods) -> list[dict]:
    """Presentations each method needs until its mean held-out curve first reaches a target: the
    conventional run's final value (the issue's question), and each selective variant's final value (how
    long the other methods take to get as far as selective presentation does: the speed-up in honest form)."""
    rows = []
    targets = ([BASELINE] if BASELINE in methods else []) + [m for m in methods if _base(m) == REFERENCE]
    for target_method in targets:
        for t in topologies:
            tgt = groups.get((t, target_method))
            tgt_curve = mean_curve(tgt) if tgt else []
            base = groups.get((t, BASELINE))
            base_curve = mean_curve(base) if base else []
            if not tgt_curve:
                rows.append({"target_method": target_method, "topology": t, "method": "all",
                             "reached": f"no {target_method} held-out curve: no target"})
                continue
            base_cost, target = (base_curve[-1][0] if base_curve else None), tgt_curve[-1][1]
            for m in methods:
                g = groups.get((t, m))
                curve = mean_curve(g) if g else []
                row = {"target_method": target_method, "topology": t, "method": m, "target_heldout_curve_rms_nm": target,
                       f"{BASELINE}_presentations": base_cost, "final_curve_rms_nm": curve[-1][1] if curve else None,
                       "method_presentations": g.sched["presentations"] if g and g.sched else None}
                hit = next((i for i, (_, v, _) in enumerate(curve) if v <= target), None)
                if not curve:
                    row["reached"] = "no curve"
                elif hit is None:
                    row["reached"] = "not reached"
                else:
                    pres = curve[hit][0]
                    row.update(reached="yes", presentations_to_target=pres,
                               previous_curve_point=curve[hit - 1][0] if hit else 0,
                               fraction_of_conventional_cost=pres / base_cost if base_cost else None)
                rows.append(row)
    return rows


def time_to_target_markdown(rows: list[dict]) -> str:
    head = ["target", "topology", "method", "target (Nm)", "presentations to target", "(previous curve point)",
            f"fraction of {BASELINE} cost", "final curve RMS (Nm)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        if r.get("reached") == "yes":
            hit = [f"{r['presentations_to_target']:,}", f"{r['previous_curve_point']:,}",
                   _fmt(r["fraction_of_conventional_cost"], 3)]
        else:
            hit = [r.get("reached", ""), "", ""]
        lines.append("| " + " | ".join([f"{r['target_method']}'s final", r["topology"], r["method"],
                                         _fmt(r.get("target_heldout_curve_rms_nm")), *hit,
                                         _fmt(r.get("final_curve_rms_nm"))]) + " |")
    return "\n".join(lines)


def runs_rows(jobs: list[Job], groups, topologies, methods, sweep: Path) -> list[dict]:
    """Every job folder with its status, plus (topology, method) cells of the sweep's grid with no folder at all."""
    rows = []
    for j in sorted(jobs, key=lambda j: (_topology_rank(j.topology or "?"), _method_rank(j.schedule or "?"), str(j.path))):
        row = {"job": str(j.path.relative_to(sweep)) if j.path != sweep else ".", "schedule": j.schedule,
               "topology": j.topology, "status": j.status, "error": j.error}
        if j.results:
            reps = j.replicas
            bad = sum(r["status"] != "complete" for r in reps)
            row.update(replicas=f"{len(reps) - bad}/{len(reps)}" + (f" ({bad} diverged)" if bad else ""),
                       seeds=f"{min(r['seed'] for r in reps)}..{max(r['seed'] for r in reps)}" if reps else "",
                       engine=j.results.get("engine"), wall_total_s=j.results["wall_seconds"]["total"])
            if bad:
                row["error"] = "; ".join(f"seed {r['seed']} diverged at epoch {(r.get('diverged') or {}).get('epoch')}"
                                         for r in reps if r["status"] != "complete")
        rows.append(row)
    for t in topologies:
        for m in methods:
            if (t, m) not in groups:
                rows.append({"job": "(no folder)", "schedule": m, "topology": t, "status": "missing",
                             "error": "no job folder for this cell of the grid"})
    return rows


def runs_markdown(rows: list[dict], warnings: list[str]) -> str:
    head = ["job", "schedule", "topology", "status", "replicas complete", "seeds", "engine", "wall s", "errors / notes"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        err = (r.get("error") or "").replace("\n", " ").replace("|", "\\|")
        lines.append("| " + " | ".join([
            f"`{r['job']}`", str(r.get("schedule")), str(r.get("topology")), r["status"], r.get("replicas", ""),
            r.get("seeds", ""), str(r.get("engine") or ""), _fmt(r.get("wall_total_s"), 1) if r.get("wall_total_s") else "",
            err[:300] + ("…" if len(err) > 300 else ""),
        ]) + " |")
    lines += [f"\n- warning: {w}" for w in warnings]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ plots
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_curves(groups, topologies, methods, path: Path) -> None:
    """Held-out curve RMS (Nm) against cumulative presentations; one panel per topology."""
    plt = _plt()
    from matplotlib.ticker import FuncFormatter

    fig, axes = plt.subplots(1, len(topologies), figsize=(5.2 * len(topologies), 4.2), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, t in zip(axes[0], topologies):
        for i, m in enumerate(methods):
            g = groups.get((t, m))
            curve = mean_curve(g) if g else []
            if not curve:
                continue
            c = colors[i % len(colors)]
            x = [p for p, _, _ in curve]
            ax.plot(x, [v for _, v, _ in curve], color=c, label=f"{m} (n={len(g.complete_seeds)})")
            lo = [st["ci95"][0] if st["ci95"][0] is not None else v for _, v, st in curve]
            hi = [st["ci95"][1] if st["ci95"][1] is not None else v for _, v, st in curve]
            ax.fill_between(x, [max(v, 1e-12) for v in lo], hi, color=c, alpha=0.2, lw=0)
            if m == REFERENCE and g.sched:
                ends = [sum(g.sched["presentations_per_stage"][: k + 1]) for k in range(len(g.sched["sizes"]) - 1)]
                for e in ends:
                    ax.axvline(e, color=c, ls=":", lw=0.8)
            paper = PAPER.get(m, {})
            if t in paper.get("rms", {}):
                ax.plot([paper["presentations"]], [paper["rms"][t]], marker="_", ms=18, mew=2.5, color=c, ls="none",
                        label=f"{PAPER_UNITS_NOTE}: {m}")
        ax.set_yscale("log")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}k"))
        ax.set_title(f"{t}")
        ax.set_xlabel("cumulative presentations (units of t)")
        ax.set_ylabel("held-out curve RMS (Nm)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("Held-out RMS vs cost: mean over seeds, band = 95 % t-interval of the mean; "
                 f"dotted = {REFERENCE} stage boundaries", fontsize=9)
    fig.tight_layout()
    _save_fig(fig, path)
    plt.close(fig)


def plot_cost(groups, topologies, methods, path: Path) -> None:
    """Presentations per method, and measured wall seconds per replica-run per (topology, method)."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    pres = {}
    for m in methods:
        for t in topologies:
            g = groups.get((t, m))
            if g and g.sched:
                pres.setdefault(m, g.sched["presentations"])
    a1.bar(list(pres), list(pres.values()), color="tab:blue", label="ours")
    for k, m in enumerate(pres):
        if m in PAPER:
            a1.plot([k], [PAPER[m]["presentations"]], marker="_", ms=30, mew=2, color="k",
                    label="paper" if k == 0 or "paper" not in a1.get_legend_handles_labels()[1] else None)
    a1.set_ylabel("presentations T/t")
    a1.set_title("cost in presentations")
    a1.legend(fontsize=8)
    width = 0.8 / max(1, len(methods))
    for i, m in enumerate(methods):
        ys = [(groups[(t, m)].wall()["per_replica"] or 0) if (t, m) in groups and groups[(t, m)].used else 0
              for t in topologies]
        a2.bar([k + i * width for k in range(len(topologies))], ys, width, label=m)
    a2.set_xticks([k + width * (len(methods) - 1) / 2 for k in range(len(topologies))], topologies)
    a2.set_ylabel("train seconds / replica (job train time ÷ replicas)")
    a2.set_title("measured wall time per replica-run")
    a2.legend(fontsize=8)
    fig.tight_layout()
    _save_fig(fig, path)
    plt.close(fig)


# ------------------------------------------------------------------------------------------ write
def _atomic(path: Path, text: str) -> None:
    atomic_write(path, lambda f: f.write(text.encode()))


def _save_fig(fig, path: Path) -> None:
    atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=110))


def to_csv(rows: list[dict]) -> str:
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    return buf.getvalue()


def build_markdown(sweep: Path, t1, verdict, ttt, runs, warnings, plots: dict[str, str]) -> str:
    n_pts = "every `eval.every` epochs and at stage ends, on the first `eval.heldout_curve` held-out patterns"
    return "\n\n".join([
        f"# Table 1 reproduction: `{sweep}`",
        "## Table 1 (paper's layout, with the paper's numbers)",
        table1_markdown(t1),
        "¹ The paper's RMS error is over 10 test patterns with units unstated; it is shown next to both of our "
        "metrics (Nm and scaled). Ours: mean ± sample std over complete seeds, and the Student-t 95 % interval of "
        "the mean. *test-10* = the paper's 10-pattern metric, *held-out* = all held-out patterns. Wall time per "
        "replica-run = the job's training seconds ÷ its replicas (replicas are trained together, batched). "
        "Diverged replicas are excluded from means and counted under *replicas complete*.",
        "## Verdict: selective − other, paired by seed (final RMS, Nm)",
        verdict_markdown(verdict),
        "Δ < 0: selective has the lower error. Pairs = seeds complete in both jobs. The reading says *no detectable "
        "difference* when the 95 % t-interval of the paired mean difference contains 0; the percentage is relative "
        "to the other method's mean over the paired seeds. Cost ratio = selective presentations ÷ other's.",
        f"## Time to target (targets: {BASELINE}'s and {REFERENCE}'s final held-out curve RMS, mean over seeds)",
        time_to_target_markdown(ttt),
        f"The held-out curve is scored {n_pts}; the first curve point at or below the target is reported, with the "
        "previous curve point (the true crossing lies in between). Fraction = presentations ÷ the "
        f"{BASELINE} run's total presentations.",
        "## Plots",
        "\n\n".join(f"![{k}]({v})" for k, v in plots.items()),
        "## Runs",
        runs_markdown(runs, warnings),
    ]) + "\n"


def write_report(sweep: Path, out: Path) -> str:
    jobs = load_jobs(sweep)
    groups, topologies, methods = aggregate(jobs)
    t1 = table1_rows(groups, topologies, methods)
    verdict = verdict_rows(groups, topologies, methods)
    ttt = time_to_target_rows(groups, topologies, methods)
    runs = runs_rows(jobs, groups, topologies, methods, sweep)
    warnings = [w for g in groups.values() for w in g.warnings]
    out.mkdir(parents=True, exist_ok=True)
    plots = {"held-out RMS vs presentations": "curves.png", "cost": "cost.png"}
    plot_curves(groups, topologies, methods, out / "curves.png")
    plot_cost(groups, topologies, methods, out / "cost.png")
    md = build_markdown(sweep, t1, verdict, ttt, runs, warnings, plots)
    for name, rows in (("table1.csv", t1), ("verdict.csv", verdict), ("time_to_target.csv", ttt), ("runs.csv", runs)):
        _atomic(out / name, to_csv(rows))
    _atomic(out / "report.md", md)
    return md


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m selpres.report", description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path, help="sweep directory, e.g. outputs/sweeps/table1")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: DIR/report)")
    a = ap.parse_args(argv)
    if not a.dir.is_dir():
        print(f"error: {a.dir} is not a directory (expected a sweep folder such as outputs/sweeps/table1)",
              file=sys.stderr)
        return 2
    if not _job_folders(a.dir):
        print(f"error: no job folders (results.json or .hydra/) under {a.dir}", file=sys.stderr)
        return 2
    out = a.out if a.out is not None else a.dir / "report"
    md = write_report(a.dir, out)
    print(md, end="")
    print(f"report written to {out}/ (report.md, table1.csv, verdict.csv, time_to_target.csv, runs.csv, "
          "curves.png, cost.png)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
