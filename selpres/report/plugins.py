"""The report's plug-ins: the studies whose sections a report shows, given to it by import path (never named here).

A plug-in is a module exporting ``SECTION(ctx) -> Section | list[Section] | None`` (None: the sweep is not its
study's; build each section with :func:`selpres.report.build.built`, so one that fails is named and the rest kept)
and optionally ``ORDER`` (the order of its methods' rows), or a package of such modules: each public module of it is
a study, by name, listed without importing it. A report is given its plug-ins by the first of:

1. the command line, ``selpres-report DIR --sections pkg.mod`` (repeatable);
2. the sweep: the ``sections`` its experiment config gives the ``hydra.callbacks.report`` node
   (:class:`selpres.report.callback.ReportSections`), which Hydra records in the sweep's ``multirun.yaml``;
3. the installation: the entry points of the group ``selpres.report`` (the repository's studies, the
   ``selpres-studies`` distribution, register their package ``selpres_studies``).

The study the sweep ran (its recorded ``experiment=NAME``) leads, the others follow in the order given (a package's
by name); the rows of methods follow the ``ORDER`` of the leading study, else of the first that has one. A plug-in
that cannot be imported becomes one line of the report naming it and why; the rest is written.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

from selpres.registry import Registry

GROUP = "selpres.report"  # the entry-point group an installed distribution registers its plug-ins under
INSTALL = "the repository's studies install with `make setup` (pip install -e studies)"


@dataclass(frozen=True)
class Study:
    """One study of a plug-in: its name (the module's) and import path; ``error``: why the plug-in ``path`` could
    not be found or imported (then it stands for its whole plug-in)."""

    name: str
    path: str
    error: str | None = None

    @property
    def module(self):
        return importlib.import_module(self.path)


def recorded(sweep: Path) -> list[str]:
    """The plug-ins the sweep names (``hydra.callbacks.report.sections`` of its multirun.yaml); [] when it names
    none or has no multirun.yaml (folders gathered by hand)."""
    from omegaconf import OmegaConf

    from selpres.report.context import multirun_hydra

    hydra = multirun_hydra(sweep)
    names = None if hydra is None else OmegaConf.select(hydra, "callbacks.report.sections")
    return [str(n) for n in names or []]


def installed() -> list[str]:
    """The plug-ins installed here: the entry points of :data:`GROUP`, by their names."""
    return [ep.value for ep in sorted(entry_points(group=GROUP), key=lambda ep: ep.name)]


def given(sweep: Path, names: list[str] | None = None) -> list[str]:
    """The plug-ins of the report of ``sweep``: ``names`` (the command line's), else the sweep's, else the ones
    installed."""
    return list(names or recorded(sweep) or installed())


def _why_not(path: str) -> str | None:
    """None when ``path`` names an importable module or package, else why not (one line)."""
    try:
        found = importlib.util.find_spec(path) is not None
    except (ImportError, ValueError) as e:
        return f"{type(e).__name__}: {e}"
    return None if found else f"no module named {path!r}"


def unavailable(paths: list[str]) -> list[str]:
    """One line for each plug-in of ``paths`` that cannot be found here (imports only their parent packages)."""
    return [
        f"the report plug-in {path} is not installed here ({why}): the sweep's report will lack its sections; {INSTALL}"
        for path in paths
        if (why := _why_not(path)) is not None
    ]


def studies(paths: list[str]) -> list[Study]:
    """The studies of the plug-ins ``paths``, in their order (a package's modules by name); a plug-in that cannot
    be found or imported is one :class:`Study` carrying the reason."""
    out = []
    for path in paths:
        why = _why_not(path)
        if why is not None:
            out.append(Study(path.rpartition(".")[2], path, why))
            continue
        spec = importlib.util.find_spec(path)
        if spec.submodule_search_locations is None:  # a module: one study
            out.append(Study(path.rpartition(".")[2], path))
            continue
        try:
            names = Registry("report.sections", path, "SECTION").names
        except Exception as e:  # the package's __init__ failed
            out.append(Study(path.rpartition(".")[2], path, f"{type(e).__name__}: {e}"))
            continue
        out += [Study(name, f"{path}.{name}") for name in names]
    return out


def by_lead(found: list[Study], experiment: str | None) -> list[Study]:
    """``found`` with the study the sweep ran first, the others in their order."""
    return sorted(found, key=lambda s: s.name != experiment or s.error is not None)


def study_order(found: list[Study], experiment: str | None) -> tuple[str, ...]:
    """The order of the methods' rows: the ``ORDER`` of the study the sweep ran, else of the first (in the order
    given) that exports one; () when none does (methods by name). A study that fails to import gives none."""
    for study in by_lead(found, experiment):
        if study.error is None:
            try:
                order = getattr(study.module, "ORDER", None)
            except Exception:  # reported by the section it fails to build
                continue
            if order is not None:
                return tuple(order)
    return ()
