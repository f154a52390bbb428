"""The README's Table 1 section, generated from the report so that its numbers cannot drift from what
``make table1`` produced: ``python -m selpres.report DIR --readme README.md`` rewrites only the block
between :data:`BEGIN` and :data:`END` in that file.
"""

from __future__ import annotations

from pathlib import Path

from selpres.report.build import Report, write_text
from selpres.report.groups import BASELINE, REFERENCE
from selpres.report.markdown import ci, table
from selpres.report.paper import PAPER
from selpres.report.sections.table1 import stat_of
from selpres.report.sections.verdict import method_note

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


def _seeds_text(report: Report) -> str:
    seeds = sorted({s for g in report.ctx.groups.values() for s in g.by_seed})
    if seeds and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"seeds {seeds[0]}–{seeds[-1]}"
    return f"{len(seeds)} seeds"


def _heldout_patterns(report: Report) -> str:
    ns = {((j.results or {}).get("tests") or {}).get("heldout", {}).get("n") for j in report.ctx.jobs if j.results}
    return f", {ns.pop():,} held-out patterns" if len(ns) == 1 and None not in ns else ""


def numbers_table(report: Report) -> str:
    """Final held-out RMS (Nm), mean [95 % interval], one row per topology, one column per method."""
    t1 = {(r["method"], r["topology"]): r for r in report.rows("table1.csv")}
    methods, topologies = report.ctx.methods, report.ctx.topologies
    cost = {
        m: next((t1[(m, t)]["presentations"] for t in topologies if t1[(m, t)].get("presentations")), None)
        for m in methods
    }
    head = ["topology"] + [f"{m}, {cost[m]:,} t" if cost[m] else m for m in methods]
    head.append("paper, conv. / sel. (units unstated)")
    body = []
    for t in topologies:
        st = [stat_of(t1[(m, t)], "heldout_nm") for m in methods]
        cells = [f"{s['mean']:.4f} {ci(s)}" if s["mean"] is not None else "no results" for s in st]
        paper = " / ".join(f"{PAPER[m]['rms'][t]:.4f}" if t in PAPER[m]["rms"] else "—" for m in (BASELINE, REFERENCE))
        body.append([t, *cells, paper])
    return table(head, body)


def findings(report: Report) -> list[str]:
    """One bullet per comparison, in the verdicts' own words, and the time to target."""
    out = []
    t1 = report.rows("table1.csv")
    cost = {r["method"]: r["presentations"] for r in t1 if r.get("presentations")}
    if BASELINE in cost and REFERENCE in cost:
        out.append(
            f"**Cost.** {REFERENCE}: T = {cost[REFERENCE]:,}·t against {BASELINE}: "
            f"T_con = {cost[BASELINE]:,}·t (ratio {cost[REFERENCE] / cost[BASELINE]:.3f})."
        )
    by_comparison: dict[str, list[dict]] = {}
    for r in report.rows("verdict.csv"):
        by_comparison.setdefault(r["comparison"], []).append(r)
    for comparison, rows in by_comparison.items():
        ratio = next((f"; cost ratio {r['cost_ratio']:.3f}" for r in rows if r.get("cost_ratio")), "")
        readings = "; ".join(f"{r['topology']}: {r.get('reading_heldout', '')}" for r in rows)
        out.append(f"**{comparison}** (paired by seed, final held-out RMS{ratio}): {readings}.")
    reached = [
        r
        for r in report.rows("time_to_target.csv")
        if r["target_method"] == REFERENCE and r["method"] == BASELINE and r.get("reached") == "yes"
    ]
    if reached:
        where = "; ".join(
            f"{r['presentations_to_target']:,} presentations for {r['topology']} (previous "
            f"curve point {r['previous_curve_point']:,})"
            for r in reached
        )
        out.append(
            f"**Time to target.** {BASELINE}'s mean held-out curve first reaches {REFERENCE}'s final value at {where}."
        )
    return [f"* {line}" for line in out]


def readme_block(report: Report, command: str) -> str:
    """The generated README section: the numbers table and the findings, each from the report."""
    return "\n\n".join(
        [
            f"<!-- generated by `{command}`: edit the generator (selpres/report/readme.py), not this block -->",
            f"Final held-out RMS in Nm, mean over {_seeds_text(report)} [95 % t-interval]{_heldout_patterns(report)}:",
            numbers_table(report),
            "What the report's statistics say:",
            "\n".join(findings(report)),
            method_note(report.rows("verdict.csv"), report.ctx.options),
        ]
    )


def update_readme(path: Path, report: Report, command: str) -> bool:
    """Rewrite the block in ``path``; False when it already says exactly this (the file is not touched)."""
    text = read_readme(path)
    new = with_block(text, readme_block(report, command), path)
    if new == text:
        return False
    write_text(path, new)
    return True
