"""A 4 x 2 sweep with its partners and its report, against `make table1`'s equivalent, side by side.

    python scripts/bench_sweep.py [--rounds 2] [--out /tmp/bench-sweep]

Each round runs, one after the other in fresh folders, Table 1 (``python train.py experiment=table1`` then
``selpres-report``: 12 jobs of 30 seeds, two at a time) and the n_1 x growth sweep of docs/usage.md (8 settings of
10 seeds and their 9 partners, ``partners=on``, two at a time, then its report), and prints the wall seconds of each
and their ratio. The order alternates between rounds, so a change of the machine's load mid-run is seen in both.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SWEEP = [
    "-m",
    "schedule=stages",
    "schedule.first=25,50,100,200",
    "schedule.growth=geometric,linear",
    "replicas=10",
    "partners=on",
    "hydra/launcher=local2",
    "threads=1",
]


def timed(train_args: list[str], folder: Path) -> tuple[float, float]:
    """(seconds of the sweep, seconds of its report) for ``python train.py <args>`` into ``folder``."""
    shutil.rmtree(folder, ignore_errors=True)
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "cwd": REPO, "env": os.environ.copy()}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "train.py", *train_args, f"hydra.sweep.dir={folder}"], check=False, **quiet)
    t1 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "selpres.report", str(folder)], check=True, **quiet)
    return t1 - t0, time.perf_counter() - t1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench-sweep"))
    a = ap.parse_args(argv)
    runs = {"table1": ["experiment=table1"], "4x2 sweep + partners": SWEEP}
    print(f"{'round':>5}  {'what':<22} {'train s':>8} {'report s':>9} {'total s':>8}  load")
    for k in range(a.rounds):
        order = list(runs) if k % 2 == 0 else list(runs)[::-1]
        total = {}
        for name in order:
            train_s, report_s = timed(runs[name], a.out / f"{k}-{name.split()[0]}")
            total[name] = train_s + report_s
            load = os.getloadavg()[0]
            print(f"{k:>5}  {name:<22} {train_s:8.1f} {report_s:9.1f} {total[name]:8.1f}  {load:.1f}", flush=True)
        print(f"{k:>5}  ratio sweep / table1: {total['4x2 sweep + partners'] / total['table1']:.2f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
