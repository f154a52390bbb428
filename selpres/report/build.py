"""The report: its sections in order, rendered to one Markdown file plus the CSV and PNG files behind it.

Two kinds of section. The *generic* ones (Table 1's grid, the verdicts, time to target, the plots, the runs) read
any sweep and live in ``sections/``. A *study's* section (the modern study, selection, sensitivity, ...) is one
module of :mod:`selpres.studies`, found by :data:`STUDIES` (a registry: the package's public modules, listed
without importing them), exporting ``SECTION(ctx) -> Section | list[Section] | None`` (None: the study does not
apply to this sweep). So a new study is one module there and no list here; the library and ``import
selpres.report`` import no study until a report is built.

Order: the sections of the studies that apply lead (the study the sweep ran, its recorded ``experiment=NAME``,
first; the others by name), then the generic ones: Table 1's grid and its verdicts next for Table 1's grid of
the paper's methods, last (compact) for a study of parameters.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from selpres.registry import Registry
from selpres.report.compare import Options
from selpres.report.context import Context, Section
from selpres.report.markdown import to_csv
from selpres.report.sections import plots, runs, table1, time_to_target, verdict
from selpres.storage import atomic_write

STUDIES = Registry("report.study", "selpres.studies", "SECTION")
# the generic sections, for Table 1's grid and for a study of parameters; a section with nothing to show is left out
TABLE1_SECTIONS = [table1.section, verdict.section, time_to_target.section, plots.section, runs.section]
STUDY_SECTIONS = [time_to_target.section, plots.section, table1.section, verdict.section, runs.section]


def study_sections(ctx: Context) -> list[Section]:
    """The sections of every study that applies to the sweep: the one it ran first, then the others by name."""
    names = sorted(STUDIES.names, key=lambda name: (name != ctx.experiment, name))
    out = []
    for name in names:
        made = _built(STUDIES.get(name), ctx)
        out += made if isinstance(made, list) else [made] if made is not None else []
    return out


def _built(make, ctx: Context) -> Section | None:
    """A section, or in its place one line saying it could not be built and why: whatever a job wrote that
    the load checks (selpres.report.validate) let through, the rest of the report is written."""
    try:
        return make(ctx)
    except Exception as e:
        name = make.__module__.rsplit(".", 1)[-1]
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
        ctx = Context.load(sweep, options)
        generic = TABLE1_SECTIONS if ctx.table1_like else STUDY_SECTIONS
        return cls(ctx, study_sections(ctx) + [s for make in generic if (s := _built(make, ctx)) is not None])

    @property
    def markdown(self) -> str:
        what = "Table 1 reproduction" if self.ctx.table1_like else "Sweep report"
        return "\n\n".join([f"# {what}: `{self.ctx.sweep}`", *(s.markdown() for s in self.sections)]) + "\n"

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
                except Exception as e:  # the rest of the report is still written (see _built)
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
