"""The report: its sections in order, rendered to one Markdown file plus the CSV and PNG files behind it.

Every section but the generic ones is a study's. The studies are plug-ins the report is given by import path
(:mod:`selpres.report.plugins`: the command line's ``--sections``, else the ones the sweep names, else the ones
installed), each exporting ``SECTION(ctx)`` composed of this package's blocks; nothing here names or imports a
study before it is given. The one generic section, the runs (every job folder and its status), closes every
report.

Order: the sections of the studies that apply, the study the sweep ran (its recorded ``experiment=NAME``) first,
the others in the order given; then the runs. Rows of methods follow the ``ORDER`` of the study the sweep ran,
else of the first study that has one (:func:`selpres.report.plugins.study_order`).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from selpres.report import plugins
from selpres.report.compare import Options
from selpres.report.context import Context, Section, experiment_of
from selpres.report.markdown import to_csv
from selpres.report.sections import runs, sweep
from selpres.storage import atomic_write

# the sections every report ends with, whatever its study; a section with nothing to show is left out
GENERIC_SECTIONS = [sweep.section, runs.section]


def study_sections(ctx: Context, found: list[plugins.Study]) -> list[Section]:
    """The sections of every study of ``found`` that applies to the sweep, the one it ran first; a plug-in that
    could not be imported is one line saying so."""
    out = []
    for study in plugins.by_lead(found, ctx.experiment):
        if study.error is not None:
            line = f"the report plug-in {study.path} could not be imported ({study.error}); {plugins.INSTALL}"
            print(f"warning: {line}", file=sys.stderr)
            out.append(Section(f"{study.name} (not built)", [line]))
            continue
        made = built(lambda ctx, study=study: study.module.SECTION(ctx), ctx, study.name)
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
    def build(cls, sweep: Path, options: Options | None = None, sections: list[str] | None = None) -> Report:
        """The report of ``sweep``; ``sections``: the study plug-ins to show (import paths), in place of the ones
        the sweep names or that are installed (:func:`selpres.report.plugins.given`)."""
        found = plugins.studies(plugins.given(sweep, sections))
        ctx = Context.load(sweep, options, plugins.study_order(found, experiment_of(sweep)))
        generic = [s for make in GENERIC_SECTIONS if (s := built(make, ctx)) is not None]
        return cls(ctx, study_sections(ctx, found) + generic)

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


def write_report(sweep: Path, out: Path, options: Options | None = None, sections: list[str] | None = None) -> str:
    """Build the report of ``sweep`` and write it into ``out``; returns its Markdown. ``sections``: the study
    plug-ins to show by import path (default: the sweep's, else the installed ones)."""
    report = Report.build(sweep, options, sections)
    report.write(out)
    return report.markdown
