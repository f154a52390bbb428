"""``python -m selpres.report DIR [--out DIR] [--margin 5%] [--holm] [--readme README.md]``: the report of a
sweep (also the ``selpres-report`` command)."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from selpres.errors import ConfigError
from selpres.report.build import Report
from selpres.report.compare import Margin, Options
from selpres.report.jobs import job_folders
from selpres.report.readme import BEGIN, END, ReadmeError, read_readme, update_readme

DESCRIPTION = (
    "The report of a sweep from its job folders' results.json: report.md, its CSV files and figures. The studies' "
    "sections come from the plug-ins the sweep names (its multirun.yaml) or that are installed; --sections chooses."
)


def _error(msg: str) -> int:
    print(f"error: {msg}", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m selpres.report", description=DESCRIPTION)
    ap.add_argument("dir", type=Path, help="sweep directory, e.g. outputs/sweeps/table1")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: DIR/report)")
    ap.add_argument(
        "--readme",
        type=Path,
        default=None,
        metavar="FILE",
        help=f"also rewrite the block between {BEGIN} and {END} in FILE with the one this report's study "
        "writes (Table 1's: its numbers and verdicts; nothing is written if the markers are missing)",
    )
    ap.add_argument(
        "--sections",
        action="append",
        default=None,
        metavar="MODULE",
        help="a study plug-in whose sections the report shows, by import path: a module exporting SECTION(ctx) or "
        "a package of such modules (repeatable; default: the ones the sweep names, recorded in its multirun.yaml, "
        "else the ones installed: the repository's studies, with make setup)",
    )
    ap.add_argument(
        "--margin",
        default="5%",
        help="equivalence margin m of the verdicts: a percentage of the mean final RMS, over the paired "
        "seeds, of the method each verdict is about (Table 1's reference; in the selection verdict the "
        "staged run) (default 5%%) or a value in Nm (e.g. 0.002)",
    )
    ap.add_argument(
        "--holm",
        action="store_true",
        help="Holm-adjust the paired tests' p-values within each family (one metric across the "
        "verdict table; the selection verdict table)",
    )
    ap.add_argument(
        "--budget",
        type=int,
        default=None,
        metavar="N",
        help="a sweep's best: the lowest error within N presentations (default: the Pareto set only)",
    )
    a = ap.parse_args(argv)
    try:
        options = Options(margin=Margin.parse(a.margin), holm=a.holm, budget=a.budget)
    except ConfigError as e:
        return _error(str(e))
    if not a.dir.is_dir():
        return _error(f"{a.dir} is not a directory (expected a sweep folder such as outputs/sweeps/table1)")
    if not job_folders(a.dir):
        return _error(f"no job folders (results.json or .hydra/) under {a.dir}")
    if a.readme is not None:
        try:
            read_readme(a.readme)  # refuse before writing anything
        except ReadmeError as e:
            return _error(str(e))
    out = a.out if a.out is not None else a.dir / "report"
    report = Report.build(a.dir, options, a.sections)
    if a.readme is not None and not report.has_readme:
        return _error(
            f"--readme {a.readme}: no study of the report of {a.dir} writes a README block (Table 1's does, "
            "for its grid of the paper's methods; a sweep that labels its methods by swept settings is not "
            "that grid); run the report without --readme, or with it on a Table 1 sweep such as "
            "outputs/sweeps/table1"
        )
    try:
        files = report.write(out)
    except OSError as e:  # a full disk, a read-only folder (selpres.storage names the file): the results untouched
        return _error(f"cannot write {e.filename or out}: {e.strerror or e} (errno {e.errno}); run the report again")
    print(report.markdown, end="")
    print(f"report written to {out}/ ({', '.join(files)})", file=sys.stderr)
    if a.readme is not None:
        flags = [f"--margin {shlex.quote(a.margin)}"] if a.margin != "5%" else []
        flags += ["--holm"] if a.holm else []
        flags += [f"--sections {shlex.quote(m)}" for m in a.sections or []]
        command = " ".join(
            ["python -m selpres.report", shlex.quote(str(a.dir)), *flags, "--readme", shlex.quote(str(a.readme))]
        )
        try:
            changed = update_readme(a.readme, report.readme_block(command))
        except OSError as e:
            return _error(f"cannot write {e.filename or a.readme}: {e.strerror or e} (errno {e.errno})")
        state = "rewritten" if changed else "already up to date"
        print(f"{a.readme}: Table 1 block {state}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
