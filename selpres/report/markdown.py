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


def pvalue(x: float | None) -> str:
    return "n/a" if x is None else ("<0.0001" if x < 1e-4 else f"{x:.4f}")


def diff_text(r: dict, prefix: str) -> str:
    """A paired difference of a :func:`selpres.report.compare.paired_columns` row: mean and 95 % interval."""
    if r.get(f"{prefix}_diff_mean") is None:
        return "n/a"
    return f"{r[f'{prefix}_diff_mean']:+.4f} " + signed_interval(r[f"{prefix}_ci_lo"], r[f"{prefix}_ci_hi"])


def pvalues_text(r: dict, prefix: str, holm: bool) -> str:
    """ "t-test p / TOST p" of such a row; the Holm-adjusted ones with ``holm``."""
    suffix = "_holm" if holm else ""
    return f"{pvalue(r.get(f'{prefix}_p{suffix}'))} / {pvalue(r.get(f'{prefix}_tost_p{suffix}'))}"


def signed_interval(lo: float | None, hi: float | None, nd: int = 4) -> str:
    """An interval of differences, signs always shown: whether it straddles 0 is read at a glance."""
    return "[n/a]" if lo is None else f"[{lo:+.{nd}f}, {hi:+.{nd}f}]"


def engine_text(r: dict, reason: int = 60) -> str:
    """The engine that ran; after a fallback also what was asked for, with the first ``reason`` characters
    of the fallback's reason (0: none). A time means little without the name of what produced it."""
    ran, asked, why = r.get("engine"), r.get("engine_requested"), r.get("engine_fallback")
    if not why:  # ran as asked ("fast" resolving to native is no fallback)
        return str(ran)
    why = why.strip().splitlines()[0] if reason and why.strip() else ""
    why = why[:reason] + ("…" if len(why) > reason else "")
    return f"{ran} ({asked} requested" + (f": {why})" if why else ")")


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
