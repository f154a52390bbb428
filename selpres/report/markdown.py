"""Number formats, Markdown tables and CSV text: how every section writes what it found."""

from __future__ import annotations

import csv
import io


def fmt(x, nd: int = 4) -> str:
    return "n/a" if x is None else f"{x:.{nd}f}"


def mean_std(s: dict, nd: int = 4) -> str:
    if s["mean"] is None:
        return "n/a"
    return fmt(s["mean"], nd) + (f" ± {fmt(s['std'], nd)}" if s["std"] is not None else "")


def ci(s: dict, nd: int = 4) -> str:
    lo, hi = s["ci95"]
    return "n/a" if lo is None else f"[{fmt(lo, nd)}, {fmt(hi, nd)}]"


def table(head: list[str], body: list[list[str]]) -> str:
    """A Markdown table: the header, the rule, one line per row of cells."""
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(cells) + " |" for cells in body]
    return "\n".join(lines)


def to_csv(rows: list[dict]) -> str:
    """Rows as CSV; the columns are the union of the rows' keys in first-seen order, None as empty."""
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    return buf.getvalue()
