"""``python -m selpres.report DIR [--out DIR]``: the Table 1 report of a sweep (also ``selpres-report``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from selpres.report import __doc__ as package_doc
from selpres.report.build import write_report
from selpres.report.jobs import job_folders


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m selpres.report", description=package_doc.split("\n\n")[0])
    ap.add_argument("dir", type=Path, help="sweep directory, e.g. outputs/sweeps/table1")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: DIR/report)")
    a = ap.parse_args(argv)
    if not a.dir.is_dir():
        print(f"error: {a.dir} is not a directory (expected a sweep folder such as outputs/sweeps/table1)",
              file=sys.stderr)
        return 2
    if not job_folders(a.dir):
        print(f"error: no job folders (results.json or .hydra/) under {a.dir}", file=sys.stderr)
        return 2
    out = a.out if a.out is not None else a.dir / "report"
    md, files = write_report(a.dir, out)
    print(md, end="")
    print(f"report written to {out}/ ({', '.join(files)})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
