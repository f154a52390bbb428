"""What every section of selpres-bench shares: the paper's shapes, random data in them, medians, the engine table."""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

import torch

import selpres
import selpres_bench

SIZES = (6, 13, 2)
N, EPOCHS, LR, MOM = 1002, 150, 0.15, 0.9
# on PYTHONPATH of the child processes: the folders selpres and this package are imported from (a checkout's root and
# its studies/)
CHILD_PATH = os.pathsep.join(
    dict.fromkeys(str(Path(m.__file__).resolve().parents[1]) for m in (selpres, selpres_bench))
)
JOB_PARTS = ("train", "eval", "shuffle", "log", "checkpoint", "prepare", "loop")  # results.json wall_seconds


def data(n: int = N, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    return (
        torch.rand(n, SIZES[0], generator=g, dtype=torch.float64),
        0.1 + 0.8 * torch.rand(n, SIZES[-1], generator=g, dtype=torch.float64),
    )


def median_seconds(fn, repeats: int, clock=time.perf_counter) -> float:
    """Median seconds per call of ``fn`` by ``clock`` (wall; ``time.thread_time``: this thread's CPU)."""
    times = []
    for _ in range(repeats):
        t = clock()
        fn()
        times.append(clock() - t)
    return statistics.median(times)


class EngineTable:
    """Engine rows: ms per replica-run and the ratio to the first row (the idiomatic loop)."""

    def __init__(self) -> None:
        self.rows: list[dict] = []

    def record(self, label, R, threads, epochs, seconds, note="") -> float:
        """``seconds``: median wall time of ``epochs`` epochs of all R replicas; returns ms per replica-run"""
        per_run = seconds * EPOCHS / epochs / R
        self.rows.append(dict(label=label, R=R, per_run=per_run))
        base = self.rows[0]["per_run"]
        if epochs < EPOCHS:
            note = (note + f" extrapolated from {epochs} epochs").strip()
        print(
            f"{label:<22} R={R:<5} thr={threads!s:<3} ep={epochs:<4} {per_run * 1e3:>10.2f} ms/replica-run "
            f"{R * N * epochs / seconds:>12.3g} pres/s  x{base / per_run:>8.1f}  {note}",
            flush=True,
        )
        return per_run * 1e3
