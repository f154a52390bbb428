"""Loading: every job folder under a sweep, finished or not, as a :class:`Job`.

A folder counts as a job when it holds a ``results.json`` or a Hydra record (``.hydra/``), so a killed or
still-running job is listed as missing instead of vanishing from the report.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

from selpres.report import validate
from selpres.storage import RESULTS


@dataclass
class Job:
    """One job folder of the sweep."""

    path: Path  # the job folder
    status: str  # complete | diverged | failed | missing | unreadable
    schedule: str | None  # its method's label: :attr:`method`, told apart by settings (selpres.report.groups)
    topology: str | None
    results: dict | None = None  # the full results.json of a complete/diverged job
    error: str | None = None
    notes: list[str] = field(default_factory=list)  # what was read as missing or not complete (selpres.report.validate)
    method: str | None = None  # the method that ran (:func:`method_of`), before any label; None: ``schedule``

    def __post_init__(self):
        if self.method is None:
            self.method = self.schedule

    @property
    def replicas(self) -> list[dict]:
        return self.results["replica_results"] if self.results else []

    @property
    def engine(self) -> dict:
        """{"engine": what ran, "engine_requested": what was asked for, "engine_fallback": None or why the
        native kernel was not used}. Results written before the fallback was recorded carry only
        ``engine``, which then stands for both (an unrecorded fallback cannot be recovered)."""
        res = self.results or {}
        ran = res.get("engine")
        return {
            "engine": ran,
            "engine_requested": res.get("engine_requested", ran),
            "engine_fallback": res.get("engine_fallback"),
        }


def method_of(res: dict) -> str:
    """A job's method as it ran: its schedule's recorded name, and the import paths of a user's classes that ran
    (``selector.user_classes``: its selector or order), ``infobatch[my_pruning.UniformPruning]``, so a user's
    policy run from InfoBatch's schedule file is not InfoBatch. Results written before the selector was recorded:
    the import paths the config names (a built-in is a plain name or a path into ``selpres``)."""
    name = res["schedule"]["name"]
    sel = res.get("selector")
    own = sel.get("user_classes", []) if isinstance(sel, dict) else user_classes(res.get("config") or {})
    return f"{name}[{', '.join(own)}]" if own else name


def user_classes(cfg: dict) -> list[str]:
    """The import paths of a user's classes a config names for its method (``schedule.pruning._target_``,
    ``schedule.order``)."""
    s = cfg.get("schedule") or {}
    named = [(s.get("pruning") or {}).get("_target_"), s.get("order")]
    return [v for v in named if isinstance(v, str) and "." in v and not v.startswith("selpres.")]


def _hydra_identity(folder: Path) -> tuple[str | None, str | None]:
    """(method, topology) of a job without usable results: from .hydra/config.yaml (the method as
    :func:`method_of` names it from a config), else the folder name (Hydra names a job folder
    by its overrides)."""
    cfg = folder / ".hydra" / "config.yaml"
    if cfg.exists():
        try:
            import yaml

            c = yaml.safe_load(cfg.read_text()) or {}
            name = (c.get("schedule") or {}).get("name")
            own = user_classes(c)
            method = f"{name}[{', '.join(own)}]" if own and name else name
            return method, (c.get("topology") or {}).get("layers")
        except Exception:  # fall back to the folder name
            pass
    m_s = re.search(r"(?:^|,)schedule=([^,]+)", folder.name)
    m_t = re.search(r"(?:^|,)topology=([^,]+)", folder.name)
    return (m_s.group(1) if m_s else None), (m_t.group(1) if m_t else None)


def job_folders(sweep: Path) -> list[Path]:
    """Folders holding a results.json or a Hydra job record (.hydra/), anywhere under the sweep."""
    found = {p.parent for p in sweep.rglob(RESULTS)}
    found |= {p.parent for p in sweep.rglob(".hydra") if p.is_dir()}
    return sorted(f for f in found if f != sweep or (f / RESULTS).exists())


def load_job(folder: Path) -> Job:
    path = folder / RESULTS
    if not path.exists():
        s, t = _hydra_identity(folder)
        return Job(folder, "missing", s, t, error="no results.json (killed, or still running)")
    try:
        res = json.loads(path.read_bytes())
    except (OSError, ValueError) as e:  # truncated, random bytes, not UTF-8 (UnicodeDecodeError is a ValueError)
        s, t = _hydra_identity(folder)
        why = f"not UTF-8 text (byte {e.start})" if isinstance(e, UnicodeDecodeError) else str(e)
        return Job(folder, "unreadable", s, t, error=f"results.json unreadable: {why}")
    problem = _not_results(res)
    if problem:
        s, t = _hydra_identity(folder)
        return Job(folder, "unreadable", s, t, error=f"results.json unreadable: {problem}")
    status = res.get("status")
    if status in ("complete", "diverged"):
        notes = validate.finite_replicas(res)
        if n := validate.finite_curves(res):
            notes.append(f"{n:,} curve values not finite (read as missing)")
        return Job(folder, status, method_of(res), res["topology"], results=res, notes=notes)
    s, t = _hydra_identity(folder)
    err = res.get("error", "no error recorded")
    if res.get("kind"):
        err = f"{res['kind']}: {err}"
    return Job(folder, "failed" if status == "failed" else f"unknown status {status!r}", s, t, error=err)


def _not_results(res) -> str | None:
    """Why a parsed results.json is not one the report can read (None: it is), so the report lists it and goes
    on: a finished job's fields are checked by :mod:`selpres.report.validate`."""
    if not isinstance(res, dict):
        return f"a JSON {type(res).__name__}, not an object"
    if res.get("status") not in ("complete", "diverged"):
        return None  # failed / unknown: listed by status, nothing more is read
    problems = validate.problems_of(res)
    return f"status {res['status']!r} but {validate.describe(problems)}" if problems else None


def load_jobs(sweep: Path) -> list[Job]:
    return [load_job(f) for f in job_folders(sweep)]
