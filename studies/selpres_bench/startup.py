"""Start-up of the command line, measured as a user meets it: whole processes, pair by pair in one run.

Each round runs ``python -c "import torch"`` (the floor: every job needs torch), the default ``python train.py``
(a one-replica selective 6-13-2 job into a fresh folder) and ``python train.py --help``, in that order, so a
busy machine slows all three alike; the ratios are taken per round and their median reported. Target (issue 19):
both commands ≤ 1.5× the bare torch import. ``train.py`` freezes the garbage collector before the interpreter
exits (see its ``__main__``), which saves torch's objects a final walk too; so each round also times the torch
import given the same freeze, and the job's ratio to that stricter floor is printed beside the target's.
``python -m selpres_bench.startup [--rounds N]``.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]  # a source checkout's root, holding train.py
# what the user types: a checkout's train.py, else (a wheel) the module behind selpres-train, the same job
TRAIN = [str(REPO / "train.py")] if (REPO / "train.py").is_file() else ["-m", "selpres.run.main"]


def _wall(cmd: list[str]) -> float:
    t = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{done.stderr[-2000:]}")
    return time.perf_counter() - t


TORCH, FROZEN = "import torch", "import torch; gc.freeze()"


def measure(rounds: int = 5) -> dict[str, list[float]]:
    """Wall seconds per round for the three commands."""
    py = sys.executable
    out: dict[str, list[float]] = {k: [] for k in (TORCH, FROZEN, "python train.py", "python train.py --help")}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            out[TORCH].append(_wall([py, "-c", "import torch"]))
            out[FROZEN].append(_wall([py, "-c", "import gc, torch; gc.freeze()"]))
            out["python train.py"].append(_wall([py, *TRAIN, f"hydra.run.dir={tmp}/job{r}"]))
            out["python train.py --help"].append(_wall([py, *TRAIN, "--help"]))
    return out


def rows(rounds: int = 5) -> list[str]:
    """Lines for selpres-bench: median (min-max) wall per command and the per-round ratio to the torch import."""
    t = measure(rounds)
    lines = [f"start-up, {rounds} rounds, each round the four commands in turn (median, min-max):"]
    for name, vals in t.items():
        ratio = ""
        for base in (TORCH, FROZEN) if name not in (TORCH, FROZEN) else ():
            ratios = [v / b for v, b in zip(vals, t[base])]
            ratio += f"  = x{statistics.median(ratios):.2f} `{base}` (rounds x{min(ratios):.2f}-{max(ratios):.2f})"
        lines.append(f"  {name:<26} {statistics.median(vals):6.2f} s ({min(vals):.2f}-{max(vals):.2f}){ratio}")
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    print("\n".join(rows(ap.parse_args(argv).rounds)))


if __name__ == "__main__":
    main()
