"""selpres-bench: the whole job, ``train()`` end to end in a fresh process, beside the engine alone."""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from selpres.run.config import compose_train
from selpres_bench.common import CHILD_PATH, EPOCHS, JOB_PARTS, EngineTable
from selpres_bench.engines import bench_engine


def train_job(configs: str, overrides: list[str], out_dir: str) -> dict:
    """Compose ``train`` with ``overrides`` and run ``selpres.run.train.train`` into ``out_dir`` (checkpoints and
    TensorBoard included), its progress lines swallowed; returns the results dict with
    ``train_call_seconds``, the call's own wall time (results.json cannot hold it: it includes writing
    results.json). Runs in a child process."""
    import contextlib
    import io

    from selpres.run.train import train

    cfg = compose_train(configs, overrides)
    with contextlib.redirect_stdout(io.StringIO()):
        t = time.perf_counter()
        res = train(cfg, out_dir)
        res["train_call_seconds"] = time.perf_counter() - t  # results.json and weights.pt written too
    return res


_CHILD = (
    "import json, sys; from selpres_bench.jobs import train_job; "
    "r = train_job(sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]); "
    "print(json.dumps({k: r[k] for k in ('wall_seconds', 'train_call_seconds', 'engine', 'status')}))"
)


def run_job_process(configs: Path, overrides: list[str], out_dir: Path) -> dict:
    """One job in a fresh Python process, as ``python train.py`` runs it (cold caches, its own threads)."""
    path = os.pathsep.join(p for p in (CHILD_PATH, os.environ.get("PYTHONPATH")) if p)
    env = dict(os.environ, PYTHONPATH=path)
    t = time.perf_counter()
    p = subprocess.run(
        [sys.executable, "-c", _CHILD, str(configs), json.dumps(overrides), str(out_dir)],
        env=env,
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise RuntimeError(f"job {overrides} failed (exit {p.returncode}):\n{p.stderr[-2000:]}")
    res = json.loads(p.stdout.strip().splitlines()[-1])
    res["process_seconds"] = wall
    return res


def bench_jobs(table: EngineTable, quick: bool, configs: Path, repeats: int = 1) -> bool:
    """train() end to end at R = 1, 30, 1000 (conventional 6-13-2, default settings) beside the engine alone.

    Prints ms per replica-run of the whole job (the ``train()`` call) and of the engine alone (random data,
    same R and engine, extrapolated to 150 epochs), the share of each part that results.json's
    ``wall_seconds`` reports (the keys present: ``train`` is the updates alone) and ``results``, the writing
    of the job's files after it, and whole job / updates. With ``repeats`` > 1 each job runs that many
    times (fresh processes, one after another) and a line gives the ratios' spread. Returns False if a job
    failed.
    """
    print(
        "\njob level: train() end to end, conventional 6-13-2, default settings (eval, TensorBoard, "
        "checkpoints), one fresh process per job"
    )
    ok = True
    with tempfile.TemporaryDirectory(prefix="selpres-bench-") as tmp:
        for R in (1, 30, 1000):
            epochs = 30 if quick and R == 1000 else EPOCHS
            overrides = ["schedule=conventional", "topology=6-13-2", f"replicas={R}"]
            if epochs != EPOCHS:
                overrides.append(f"schedule.epochs=[{epochs}]")
            whole, bookkeeping = [], []
            for k in range(repeats):
                try:
                    res = run_job_process(configs, overrides, Path(tmp) / f"R{R}-{k}")
                except (RuntimeError, ValueError, json.JSONDecodeError) as exc:
                    print(f"R={R}: {exc}")
                    ok = False
                    continue
                ratios = _job_lines(R, epochs, res)
                whole.append(ratios[0])
                bookkeeping.append(ratios[1])
            if repeats > 1 and whole:
                spread = lambda v: f"x{min(v):.2f}-{max(v):.2f} (median {statistics.median(v):.2f})"
                print(
                    f"job         R={R:<5} {len(whole)} runs: whole job / updates {spread(whole)}, "
                    f"loop bookkeeping / updates {spread(bookkeeping)}"
                )
            eng_epochs, reps = (EPOCHS, 3) if R == 1 else (30, 3) if R == 30 else (5 if quick else 30, 1)
            bench_engine(table, "fast", R, eng_epochs, reps, note=f"engine alone beside the R={R} job")
    if quick:
        print("(--quick: the R=1000 job runs 30 of its 150 epochs, so its fixed costs weigh 5x more)")
    return ok


def _job_lines(R: int, epochs: int, res: dict) -> tuple[float, float]:
    """Print one job's line and its parts; returns (whole job / updates, loop bookkeeping / updates)."""
    ws = res["wall_seconds"]
    # the whole job is the train() call: wall_seconds' total plus writing results.json, weights.pt and
    # TensorBoard's last events, which results.json cannot time (it is written by them)
    total, updates = res["train_call_seconds"], ws["train"]
    bookkeeping = (ws["loop"] - updates) / updates  # what the loop spends besides the updates
    print(
        f"job         R={R:<5} ep={epochs:<4} {total / R * 1e3:>10.2f} ms/replica-run (whole job, {total:.2f} s; "
        f"process {res['process_seconds']:.2f} s with imports)   whole job / updates x{total / updates:.2f}   "
        f"loop bookkeeping / updates x{bookkeeping:.2f}",
        flush=True,
    )
    shares = {k: ws[k] for k in JOB_PARTS if k in ws}
    shares["results"] = total - ws["total"]
    print("   parts: " + "  ".join(f"{k} {v:.3f} s ({v / total:.0%})" for k, v in shares.items()))
    return total / updates, bookkeeping
