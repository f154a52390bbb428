"""The report: its sections in order, rendered to one Markdown file plus the CSV and PNG files behind it.

A new section (sensitivity, error–cost plane, selection verdicts, ...) is a module in ``sections/`` with
``section(ctx) -> Section``, added to :data:`SECTIONS` where it should appear.
"""

from __future__ import annotations

from pathlib import Path

from selpres.report.context import Context, Section
from selpres.report.markdown import to_csv
from selpres.report.sections import plots, runs, table1, time_to_target, verdict
from selpres.storage import atomic_write

SECTIONS = [table1.section, verdict.section, time_to_target.section, plots.section, runs.section]


def build(ctx: Context) -> list[Section]:
    return [make(ctx) for make in SECTIONS]


def render(ctx: Context, sections: list[Section]) -> str:
    return "\n\n".join([f"# Table 1 reproduction: `{ctx.sweep}`", *(s.markdown() for s in sections)]) + "\n"


def _write_text(path: Path, text: str) -> None:
    atomic_write(path, lambda f: f.write(text.encode()))


def write_report(sweep: Path, out: Path) -> tuple[str, list[str]]:
    """Write report.md, every section's CSV files and figures into ``out``; returns (the Markdown, the
    names of the files written)."""
    ctx = Context.load(sweep)
    sections = build(ctx)
    out.mkdir(parents=True, exist_ok=True)
    files = ["report.md"]
    for s in sections:
        for name, rows in s.csv.items():
            _write_text(out / name, to_csv(rows))
            files.append(name)
    for s in sections:
        for name, (_, draw) in s.figures.items():
            draw(out / name)
            files.append(name)
    md = render(ctx, sections)
    _write_text(out / "report.md", md)
    return md, files
