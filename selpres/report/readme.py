"""A README's generated block, rewritten from a report so that its numbers cannot drift from what the sweep
produced: ``python -m selpres.report DIR --readme README.md`` rewrites only the block between :data:`BEGIN` and
:data:`END` in that file, with the block the report's study writes (a section's ``readme``; Table 1's, whose
generator is the repository's studies' ``selpres_studies.table1``).
"""

from __future__ import annotations

from pathlib import Path

from selpres.report.build import write_text

BEGIN = "<!-- table1:begin -->"
END = "<!-- table1:end -->"


class ReadmeError(ValueError):
    """A README the generator cannot rewrite safely (no file, or not exactly one marker pair)."""


def _span(text: str, path: Path) -> tuple[int, int]:
    """(end of the BEGIN marker, start of the END marker): the part the generator owns."""
    nb, ne = text.count(BEGIN), text.count(END)
    if nb != 1 or ne != 1 or text.index(BEGIN) > text.index(END):
        raise ReadmeError(
            f"{path}: needs exactly one '{BEGIN}' line followed by one '{END}' line (found "
            f"{nb} begin and {ne} end marker(s)); add them around the Table 1 section"
        )
    return text.index(BEGIN) + len(BEGIN), text.index(END)


def read_readme(path: Path) -> str:
    """The README's text, refused (ReadmeError) unless it holds one marker pair: checked before anything
    is written, so a refusal leaves every file as it was."""
    if not path.is_file():
        raise ReadmeError(f"{path}: no such file (expected a README holding '{BEGIN}' … '{END}')")
    text = path.read_text()
    _span(text, path)
    return text


def with_block(text: str, block: str, path: Path) -> str:
    """``text`` with everything between the markers replaced by ``block``."""
    a, b = _span(text, path)
    return text[:a] + "\n" + block.strip("\n") + "\n" + text[b:]


def update_readme(path: Path, block: str) -> bool:
    """Rewrite the block in ``path`` with ``block``; False when it already says exactly this (the file is not
    touched)."""
    text = read_readme(path)
    new = with_block(text, block, path)
    if new == text:
        return False
    write_text(path, new)
    return True
