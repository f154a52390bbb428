"""The report: its sections in order, rendered to one Markdown file plus the CSV and PNG files behind it.

Every section but one is a study's. A study (Table 1, modern, selection, sensitivity, ...) is one module of
:mod:`selpres.studies`, found by :data:`STUDIES` (a registry: the package's public modules, listed without importing
them), exporting ``SECTION(ctx) -> Section | list[Section] | None`` (None: the study does not apply to this sweep)
composed of this package's blocks, and optionally ``ORDER``, the order of its methods' rows. So a new study is one
module there and no list here; the library and ``import selpres.report`` import no study until a report is built,
and nothing here names a study's methods. The one generic section, the runs (every job folder and its status),
closes every report.

Order: the sections of the studies that apply, the study the sweep ran (its recorded ``experiment=NAME``) first,
the others by name; then the runs. Rows of methods follow the ``ORDER`` of the study the sweep ran, else of the
first study (by name) that has one (:func:`study_order`).
"""

from __future__ import annotations

import importlib
import sys
from dataclasses import dataclass
from pathlib import Path

from selpres.registry import Registry
from selpres.report.compare import Options
from selpres.report.context import Context, Section, experiment_of
from selpres.report.markdown import to_csv
from selpres.report.sections import runs
from selpres.storage import atomic_write

STUDIES = Registry("report.study", "selpres.studies", "SECTION")
# the sections every report ends with, whatever its study; a section with nothing to show is left out
GENERIC_SECTIONS = [runs.section]


def _by_lead(experiment: str | None) -> list[str]:
    """The studies' names, the one the sweep ran first, the others by name."""
    return sorted(STUDIES.names, key=lambda name: (name != experiment, name))


def study_order(experiment: str | None) -> tuple[str, ...]:
    """The order of the methods' rows: the ``ORDER`` of the study the sweep ran, else of the first study (by name)
    that exports one; () when none does (methods by name)."""
    for name in _by_lead(experiment):
        order = getattr(importlib.import_module(f"{STUDIES.package}.{name}"), "ORDER", None)
        if order is not None:
            return tuple(order)
    return ()


def study_sections(ctx: Context) -> list[Section]:
    """The sections of every study that applies to the sweep: the one it ran first, then the others by name."""
    out = []
    for name in _by_lead(ctx.experiment):
        made = built(STUDIES.get(name), ctx)
        out += made if isinstance(made, list) else [made] if made is not None else []
    return out


def built(make, ctx: Context, name: str | None = None) -> Section | list[Section] | None:
    """What ``make(ctx)`` gives, or in its place one line saying it could not be built and why: whatever a job
    wrote that the load checks (selpres.report.validate) let through, the rest of the report is written. ``name``:
    what the line calls the section (by default its module's name); a study builds each of its sections so."""
    try:
        return make(ctx)
    except Exception as e:
        name = name or make.__module__.rsplit(".", 1)[-1]
        line = f"the {name} section could not be built from these results: {type(e).__name__}: {e}"
        print(f"warning: {line}", file=sys.stderr)
        return Section(f"{name} (not built)", [line])


def write_text(path: Path, text: str) -> None:
    atomic_write(path, lambda f: f.write(text.encode()))


@dataclass
class Report:
    """A sweep's sections, built once: rendered to report.md, and read again by the README generator."""

    ctx: Context
    sections: list[Section]

    @classmethod
    def build(cls, sweep: Path, options: Options | None = None) -> Report:
        ctx = Context.load(sweep, options, study_order(experiment_of(sweep)))
        generic = [s for make in GENERIC_SECTIONS if (s := built(make, ctx)) is not None]
        return cls(ctx, study_sections(ctx) + generic)

    @property
    def title(self) -> str:
        """The report's title: the first section's that gives one (a study's), else "Sweep report"."""
        return next((s.heading for s in self.sections if s.heading), "Sweep report")

    @property
    def markdown(self) -> str:
        return "\n\n".join([f"# {self.title}: `{self.ctx.sweep}`", *(s.markdown() for s in self.sections)]) + "\n"

    @property
    def has_readme(self) -> bool:
        """Whether a section of the report writes a README block (``--readme``)."""
        return any(s.readme for s in self.sections)

    def readme_block(self, command: str) -> str:
        """The README block of the first section that writes one; ``command``: what made it, named in it."""
        return next(s.readme(self, command) for s in self.sections if s.readme)

    def rows(self, csv_name: str) -> list[dict]:
        """The rows behind one CSV file of the report (e.g. "verdict.csv")."""
        return next(s.csv[csv_name] for s in self.sections if csv_name in s.csv)

    def write(self, out: Path) -> list[str]:
        """report.md, every section's CSV files and figures into ``out``; returns the names written."""
        out.mkdir(parents=True, exist_ok=True)
        files = ["report.md"]
        for s in self.sections:
            for name, rows in s.csv.items():
                write_text(out / name, to_csv(rows))
                files.append(name)
        for s in self.sections:
            for name, (_, draw) in s.figures.items():
                try:
                    draw(out / name)
                except OSError:  # the disk refused the file: the report fails in one line (__main__), no gap
                    raise
                except Exception as e:  # the rest of the report is still written (see built)
                    print(f"warning: {name} not drawn: {type(e).__name__}: {e}", file=sys.stderr)
                    continue
                files.append(name)
        write_text(out / "report.md", self.markdown)
        return files


def write_report(sweep: Path, out: Path, options: Options | None = None) -> str:
    """Build the report of ``sweep`` and write it into ``out``; returns its Markdown."""
    report = Report.build(sweep, options)
    report.write(out)
    return report.markdown
