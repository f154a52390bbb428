"""Benchmark selpres on this machine, every row measured side by side in one run.

    selpres-bench               # full (several minutes)
    selpres-bench --quick       # short version (about a minute: fewer epochs and repeats)
    python -m selpres_bench     # the same, without the console entry point

Sections: the training engines alone; mini-batch training of the modern Adam designs (``selpres_bench.minibatch``:
the native kernel against the torch mini-batch engine and torch.func's stacked models, eager and compiled); the
whole job (``selpres.run.train.train`` end to end at R = 1, 30, 1000
beside the engine alone at the same R); the per-epoch shuffles (the native bucket sort against numpy's argsort
of the same hashes); the priority orders' selection cost; the stage-wise orders' cost of choosing
(``selpres.presentation.selection``: one enlargement batched against a per-replica loop, and whole jobs' "select"
phase against "train"); SeTa's selection (``selpres_bench.pruning``: its exact k-means in C against numpy, one call
and whole jobs); the native kernel's build; exemplar-set
generation; the command line's start-up (``selpres_bench.startup``); TensorBoard written by selpres against
torch's SummaryWriter (``selpres_bench.tracking``, full run only). A "replica-run" is one conventional run
of the paper: 150 epochs x 1002 single-pattern
updates of a 6-13-2 sigmoid net (SGD lr 0.15, momentum 0.9). Slow configurations are timed over a few
epochs and extrapolated to 150 (the ``ep`` column says how many were timed); times are medians. Engine
rows use random data in the real shapes (6 inputs, 2 outputs); job rows use the real configs. The batch
optimizers (``BatchEngine``, one step per epoch, ``configs/optim/<name>.yaml``) follow the online engine rows
on the same axis: a replica-run is then 150 epochs of 1002 presentations and 150 steps.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

import numpy as np
import torch

from selpres.run.config import CONFIG_DIR
from selpres_bench.build import bench_compile, bench_exemplar_generation
from selpres_bench.common import EPOCHS, SIZES, EngineTable, N
from selpres_bench.engines import bench_batch_engines, bench_engines
from selpres_bench.jobs import bench_jobs
from selpres_bench.minibatch import rows as minibatch_rows
from selpres_bench.presentation import bench_orders, bench_selection, bench_shuffles
from selpres_bench.pruning import rows as pruning_rows
from selpres_bench.sampler import bench_sampler
from selpres_bench.startup import rows as startup_rows
from selpres_bench.tracking import rows as tracking_rows


def main(argv: list[str] | None = None) -> int:
    """The ``selpres-bench`` command: every section in turn; 0, or 1 if a job-level run failed."""
    ap = argparse.ArgumentParser(
        prog="selpres-bench", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--quick", action="store_true", help="fewer epochs and repeats (about a minute)")
    ap.add_argument(
        "--jobs-only", action="store_true", help="only the job-level section (with --job-repeats: its spread)"
    )
    ap.add_argument(
        "--startup-only",
        action="store_true",
        help="only the start-up rows (python train.py and --help against import torch)",
    )
    ap.add_argument(
        "--job-repeats", type=int, default=1, metavar="N", help="run each job-level job N times (default 1)"
    )
    ap.add_argument(
        "--configs",
        type=Path,
        default=CONFIG_DIR,
        help=f"the Hydra config directory the job rows compose (default: {CONFIG_DIR})",
    )
    args = ap.parse_args(argv)
    if not (args.configs / "train.yaml").is_file():
        ap.error(f"--configs={args.configs}: no train.yaml there; expected the repository's configs/ directory")
    q = args.quick
    from selpres.native import KernelUnavailable, load

    print(
        f"python {platform.python_version()}, torch {torch.__version__}, numpy {np.__version__}, "
        f"{os.cpu_count()} CPUs, torch threads {torch.get_num_threads()}, "
        f"load average at start {os.getloadavg()[0]:.2f}"
    )
    print(
        f"replica-run = {EPOCHS} epochs x {N} patterns, 6-13-2, batch 1; times are medians; ratio = idiomatic / this\n"
    )
    try:
        load(SIZES)
        native = True
    except KernelUnavailable as exc:
        print(f"native kernel unavailable: {exc} (native rows skipped; the fast engine is torch)")
        native = False

    if args.startup_only:
        print("\n".join(startup_rows(3 if q else 5)))
        return 0
    table = EngineTable()
    if args.job_repeats < 1:
        ap.error(f"--job-repeats={args.job_repeats}: expected a whole number >= 1")
    if args.jobs_only:
        return 0 if bench_jobs(table, q, args.configs.resolve(), args.job_repeats) else 1
    bench_engines(table, q, native)
    bench_batch_engines(table, q, args.configs.resolve())
    print("\n" + "\n".join(minibatch_rows(q)))  # mini-batch Adam: native kernel, torch engine, vmap (issue 28)
    jobs_ok = bench_jobs(table, q, args.configs.resolve(), args.job_repeats)
    bench_shuffles(q)
    bench_sampler(q)  # the Sampler in a DataLoader loop against RandomSampler (a row, not a pass or fail)
    bench_orders(q)
    jobs_ok = bench_selection(q, args.configs.resolve()) and jobs_ok
    for line in pruning_rows(q, args.configs.resolve()):  # SeTa's k-means: C against numpy, one call and whole jobs
        print(line, flush=True)
    if native:
        bench_compile()
    bench_exemplar_generation(q, args.configs)
    print("\n" + "\n".join(startup_rows(3 if q else 5)))
    if not q:  # whole jobs at R = 1 and 1000, twice a round: minutes
        print("\n" + "\n".join(tracking_rows(3)))
    print(f"\nload average at end {os.getloadavg()[0]:.2f} (other processes on the machine slow every number)")
    return 0 if jobs_ok else 1


if __name__ == "__main__":
    sys.exit(main())
