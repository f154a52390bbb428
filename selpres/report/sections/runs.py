"""Every job folder with its status (complete, diverged, failed, missing), and the grid cells with none.

A (topology, method) cell with no folder is listed only when the sweep is a grid: its ``multirun.yaml`` sweeps
two or more keys (Table 1's ``schedule=... topology=...``; ``experiment=large``'s arm x n x schedule). One list of
design points (each its own topology and schedule, e.g. ``experiment=modern``) is no grid: crossing it listed 24
cells no job was meant to fill. Without a ``multirun.yaml`` (folders gathered by hand) every cell is expected.

Below the table, what the jobs ran on (results.json ``provenance``, :mod:`selpres.run.provenance`): one line when
every job ran on the same versions and machine; a warning naming each version that differs (selpres's version,
commit and uncommitted changes, Python, torch, numpy, the native kernels' compiler and instruction set, a kernel
built two ways) with its jobs, and a note for machines that differ (platform, CPUs); jobs whose results.json records
none are counted."""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf

from selpres.report.context import Context, Section, multirun_hydra
from selpres.report.groups import method_rank, topology_rank
from selpres.report.jobs import Job
from selpres.report.markdown import engine_text, fmt, table


def _diverged_epoch(rep: dict):
    return (rep.get("diverged") or {}).get("epoch")


def crossed(sweep: Path) -> bool:
    """Whether the sweep is a grid (see the module's docstring)."""
    hydra = multirun_hydra(sweep)
    if hydra is None:  # folders gathered by hand (or unreadable): every cell is expected, as before
        return True
    swept = set((OmegaConf.select(hydra, "sweeper.params") or {}).keys())
    for o in OmegaConf.select(hydra, "overrides.task") or []:
        key, _, value = str(o).partition("=")
        if "," in value or value.startswith(("range(", "choice(", "glob(")):
            swept.add(key.lstrip("+~"))
    # a grid has at least two swept dimensions (Table 1: schedule x topology; experiment=large: design/arm, which
    # sets the topology, x data.n x schedule); one list of design points (experiment=modern, sensitivity) is none,
    # and seed blocks repeat the cells, they add none (experiment=modern sweeps seed=0,1000: 76 phantom cells)
    return len(swept - {"seed"}) >= 2


def runs_rows(jobs: list[Job], groups, topologies, methods, sweep: Path, order: tuple[str, ...] = ()) -> list[dict]:
    """Every job folder with its status, by topology then method (in a study's ``order``), plus (topology, method)
    cells of the sweep's grid with no folder."""

    def rank(j: Job) -> tuple:
        return topology_rank(j.topology or "?"), method_rank(j.schedule or "?", order), str(j.path)

    rows = []
    for j in sorted(jobs, key=rank):
        row = {
            "job": _name(j, sweep),
            "schedule": j.schedule,
            "topology": j.topology,
            "status": j.status,
            "error": j.error,
        }
        if j.results:
            reps = j.replicas
            bad = [r for r in reps if r["status"] != "complete"]
            kinds = {k: sum(r["status"] == k for r in bad) for k in dict.fromkeys(r["status"] for r in bad)}
            row.update(
                replicas=f"{len(reps) - len(bad)}/{len(reps)}"
                + (f" ({', '.join(f'{n} {k}' for k, n in kinds.items())})" if bad else ""),
                seeds=f"{min(r['seed'] for r in reps)}..{max(r['seed'] for r in reps)}" if reps else "",
                **j.engine,
                wall_total_s=j.results["wall_seconds"]["total"],
                provenance=_summary(j.results.get("provenance")),
            )
            diverged = [
                f"seed {r['seed']} diverged at epoch {_diverged_epoch(r)}" for r in bad if "not_finite" not in r
            ]
            if diverged or j.notes:
                row["error"] = "; ".join(diverged + j.notes)
        rows.append(row)
    for t in topologies if crossed(sweep) else ():
        for m in methods:
            if (t, m) not in groups:
                rows.append(
                    {
                        "job": "(no folder)",
                        "schedule": m,
                        "topology": t,
                        "status": "missing",
                        "error": "no job folder for this cell of the grid",
                    }
                )
    return rows


def _name(j: Job, sweep: Path) -> str:
    return str(j.path.relative_to(sweep)) if j.path != sweep else "."


def _fields(p: dict) -> tuple[dict[str, str], dict[str, str]]:
    """(versions, machine) of a provenance record, each field as the report prints it."""
    src, native = p.get("selpres") or {}, p.get("native")
    commit = src.get("commit")
    where = f"commit {str(commit)[:12]}{', uncommitted changes' if src.get('dirty') else ''}" if commit else "no commit"
    # the compiler and the instruction set; which kernels and flags: _kernel_builds (a process that ran several jobs,
    # a sweep worker, records every library it loaded, so jobs differ in which kernels they list, not in how built)
    build = f"{native.get('compiler')} ({native.get('instruction_set')})" if isinstance(native, dict) else "none loaded"
    versions = {
        "selpres": f"{src.get('version')} ({where})",
        "Python": str(p.get("python")),
        "torch": str(p.get("torch")),
        "numpy": str(p.get("numpy")),
        "native kernels": build,
    }
    machine = {"platform": str(p.get("platform")), "CPUs": str(p.get("cpus"))}
    return versions, machine


def _summary(p) -> str:
    """One job's provenance in one line (runs.csv)."""
    if not isinstance(p, dict):
        return "not recorded"
    versions, machine = _fields(p)
    return "; ".join(f"{k} {v}" for k, v in {**versions, **machine}.items())


def _jobs(n: int) -> str:
    return f"{n} job{'s' * (n != 1)}"


def _kernel_builds(recorded: list[tuple[Job, dict]], sweep: Path) -> list[str]:
    """A native kernel built two ways across the jobs: its library's name ends in a hash of what built it
    (``selpres_6-13-2_<hash>.so``). A process lists every library it loaded (a sweep worker: earlier jobs' kernels
    too; one process may load a variant beside the usual build), so a job's builds of a kernel are a set, and two
    jobs differ only where their sets share no build: then they cannot have run the same one."""
    by_kernel: dict[str, dict[frozenset, list[str]]] = {}
    for j, p in recorded:
        native = p.get("native")
        builds: dict[str, set[str]] = {}
        for lib in native.get("libraries") or [] if isinstance(native, dict) else []:
            kernel, _, built = str(lib).removesuffix(".so").rpartition("_")
            builds.setdefault(kernel, set()).add(built)
        for kernel, hashes in builds.items():
            by_kernel.setdefault(kernel, {}).setdefault(frozenset(hashes), []).append(_name(j, sweep))
    return [
        f"native kernel {kernel}: {_values_and_jobs({'build ' + ', '.join(sorted(h)): n for h, n in sets.items()})}"
        for kernel, sets in sorted(by_kernel.items())
        if any(not (a & b) for a in sets for b in sets)
    ]


def _values_and_jobs(by_value: dict[str, list[str]]) -> str:
    """Each value with its count of jobs, the most common first; the others name their jobs (three at most)."""
    ranked = sorted(by_value.items(), key=lambda kv: -len(kv[1]))
    said = [f"{ranked[0][0]} ({_jobs(len(ranked[0][1]))})"] + [
        f"{v} ({_jobs(len(names))}: " + ", ".join(f"`{n}`" for n in names[:3]) + (", …" if len(names) > 3 else "") + ")"
        for v, names in ranked[1:]
    ]
    return "; ".join(said)


def provenance_lines(jobs: list[Job], sweep: Path) -> list[str]:
    """What the jobs ran on: one line if all agree, else a warning per version and a note per machine field that
    differs, naming the jobs of every value but the most common."""
    recorded = [
        (j, j.results["provenance"]) for j in jobs if j.results and isinstance(j.results.get("provenance"), dict)
    ]
    lines = []
    if recorded:
        split = [(j, *_fields(p)) for j, p in recorded]
        same, differ = {}, {"versions": [], "machines": []}
        for kind, at in (("versions", 1), ("machines", 2)):
            for key in split[0][at]:
                by_value: dict[str, list[str]] = {}
                for row in split:
                    by_value.setdefault(row[at][key], []).append(_name(row[0], sweep))
                if len(by_value) == 1:
                    same[key] = next(iter(by_value))
                    continue
                differ[kind].append(f"{key}: {_values_and_jobs(by_value)}")
        common = ", ".join(f"{k} {v}" for k, v in same.items())
        lines.append(
            f"**What ran.** {len(recorded)} job{'s' * (len(recorded) > 1)}" + (f": {common}." if common else ".")
        )
        differ["versions"] += _kernel_builds(recorded, sweep)
        lines += [f"- warning: the jobs ran on different versions: {d}" for d in differ["versions"]]
        lines += [f"- note: the jobs ran on different machines: {d}" for d in differ["machines"]]
    unrecorded = sum(1 for j in jobs if j.results and not isinstance(j.results.get("provenance"), dict))
    if unrecorded:
        one = unrecorded == 1
        lines.append(f"- {unrecorded} finished job{'' if one else 's'} record{'s' if one else ''} no provenance (a "
                     "selpres before issue 39 wrote the results.json)")  # fmt: skip
    return lines


def runs_markdown(rows: list[dict], warnings: list[str]) -> str:
    head = [
        "job",
        "schedule",
        "topology",
        "status",
        "replicas complete",
        "seeds",
        "engine that ran",
        "wall s",
        "errors / notes",
    ]
    body = []
    for r in rows:
        fallback = r.get("engine_fallback") and f"engine fallback: {r['engine_fallback']}"
        err = "; ".join(n for n in (r.get("error"), fallback) if n).replace("\n", " ").replace("|", "\\|")
        body.append(
            [
                f"`{r['job']}`",
                str(r.get("schedule")),
                str(r.get("topology")),
                r["status"],
                r.get("replicas", ""),
                r.get("seeds", ""),
                engine_text(r, 0) if r.get("engine") else "",
                fmt(r.get("wall_total_s"), 1) if r.get("wall_total_s") else "",
                err[:300] + ("…" if len(err) > 300 else ""),
            ]
        )
    return table(head, body) + "".join(f"\n\n- warning: {w}" for w in warnings)


def section(ctx: Context) -> Section:
    rows = runs_rows(ctx.jobs, ctx.groups, ctx.topologies, ctx.methods, ctx.sweep, ctx.order)
    what_ran = provenance_lines(ctx.jobs, ctx.sweep)
    return Section("Runs", [runs_markdown(rows, ctx.warnings), *(["\n".join(what_ran)] if what_ran else [])],
                   csv={"runs.csv": rows})  # fmt: skip
