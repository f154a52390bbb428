"""Is the hand-written TensorBoard writer worth keeping? ``selpres.run.tracking`` against torch's
``SummaryWriter`` on the commands users run: whole jobs in fresh processes, pair by pair.

Each round runs the same conventional 6-13-2 job twice, once as selpres writes TensorBoard and once with the
tracker swapped for :class:`SummaryWriterTracker` (the same scalars and hparams through
``torch.utils.tensorboard``), and reports the process's wall time (imports included, what ``python train.py``
costs) and the ``train()`` call's. ``python -m selpres_bench.tracking [--rounds N] [--replicas 1 1000]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from selpres.run.config import CONFIG_DIR
from selpres.run.tracking import Tracker, hparams_and_metrics
from selpres_bench.common import CHILD_PATH

_CHILD = (
    "import json, sys, time; t0 = time.perf_counter(); from selpres_bench import tracking as T; "
    "r = T.child(sys.argv[1], json.loads(sys.argv[2]), sys.argv[3], sys.argv[4]); "
    "print(json.dumps({'call': r['train_call_seconds'], 'after_start': time.perf_counter() - t0}))"
)


class SummaryWriterTracker(Tracker):
    """The tracker's scalars and hparams written by torch's SummaryWriter instead (the library's way)."""

    def __init__(self, logdir: Path, enabled: bool = True, per_replica: bool = True):
        super().__init__(logdir, enabled=False, per_replica=per_replica)
        self.enabled = enabled
        if enabled:
            from torch.utils.tensorboard import SummaryWriter

            self.logdir.mkdir(parents=True, exist_ok=True)
            self.writer = SummaryWriter(str(self.logdir))

    def _write(self, scalars, step):
        for tag, v in scalars:
            self.writer.add_scalar(tag, v, int(step))

    def close(self, hparams: dict, metrics: dict) -> None:
        if self.writer is None:
            return
        self.writer.add_hparams(*hparams_and_metrics(hparams, metrics), run_name=".")
        self.writer.close()
        self.writer = None


def child(configs: str, overrides: list[str], out_dir: str, variant: str) -> dict:
    """One job in this (fresh) process, with selpres's tracker or the SummaryWriter one."""
    from selpres_bench.jobs import train_job

    if variant == "summarywriter":
        import selpres.run.train as loop

        loop.Tracker = SummaryWriterTracker
    return train_job(configs, overrides, out_dir)


def _run(overrides: list[str], out: Path, variant: str) -> dict:
    path = os.pathsep.join(p for p in (CHILD_PATH, os.environ.get("PYTHONPATH")) if p)
    t = time.perf_counter()
    p = subprocess.run(
        [sys.executable, "-c", _CHILD, str(CONFIG_DIR), json.dumps(overrides), str(out), variant],
        env=dict(os.environ, PYTHONPATH=path),
        capture_output=True,
        text=True,
    )
    if p.returncode != 0:
        raise SystemExit(f"{variant} job failed:\n{p.stderr[-2000:]}")
    res = json.loads(p.stdout.strip().splitlines()[-1])
    res["process"] = time.perf_counter() - t
    return res


def rows(rounds: int = 3, replicas: tuple[int, ...] = (1, 1000)) -> list[str]:
    lines = [f"TensorBoard writer: selpres.run.tracking vs torch's SummaryWriter, conventional 6-13-2, {rounds} rounds"]
    with tempfile.TemporaryDirectory() as tmp:
        for R in replicas:
            overrides = ["schedule=conventional", f"replicas={R}"]
            got: dict[str, list[dict]] = {"selpres": [], "summarywriter": []}
            for r in range(rounds):
                for variant in got:
                    got[variant].append(_run(overrides, Path(tmp) / f"{variant}-R{R}-{r}", variant))
            for key, what in (("process", "whole process"), ("call", "train() call")):
                a = [g[key] for g in got["selpres"]]
                b = [g[key] for g in got["summarywriter"]]
                ratios = [y / x for x, y in zip(a, b)]
                lines.append(
                    f"  R={R:<5} {what:<14} selpres {statistics.median(a):6.2f} s  SummaryWriter "
                    f"{statistics.median(b):6.2f} s  = x{statistics.median(ratios):.2f} "
                    f"(rounds x{min(ratios):.2f}-{max(ratios):.2f})"
                )
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--replicas", type=int, nargs="+", default=[1, 1000])
    args = ap.parse_args(argv)
    print("\n".join(rows(args.rounds, tuple(args.replicas))))


if __name__ == "__main__":
    main()
