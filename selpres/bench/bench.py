"""Benchmark selpres on this machine, every row measured side by side in one run.

    selpres-bench               # full (several minutes)
    selpres-bench --quick       # short version (about a minute: fewer epochs and repeats)
    python -m selpres.bench.bench     # the same, without the console entry point

Sections: the training engines alone; the whole job (``selpres.run.train.train`` end to end at R = 1, 30, 1000
beside the engine alone at the same R); the per-epoch shuffles (the native bucket sort against numpy's argsort
of the same hashes); the priority orders' selection cost; the stage-wise orders' cost of choosing
(``selpres.presentation.selection``: one enlargement batched against a per-replica loop, and whole jobs' "select"
phase against "train"); the native kernel's build; exemplar-set
generation. A "replica-run" is one conventional run of the paper: 150 epochs x 1002 single-pattern
updates of a 6-13-2 sigmoid net (SGD lr 0.15, momentum 0.9). Slow configurations are timed over a few
epochs and extrapolated to 150 (the ``ep`` column says how many were timed); times are medians. Engine
rows use random data in the real shapes (6 inputs, 2 outputs); job rows use the real configs. The batch
optimizers (``BatchEngine``, one step per epoch, ``configs/optim/<name>.yaml``) follow the online engine rows
on the same axis: a replica-run is then 150 epochs of 1002 presentations and 150 steps.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch

from selpres.run.config import CONFIG_DIR, compose_train

SIZES = (6, 13, 2)
N, EPOCHS, LR, MOM = 1002, 150, 0.15, 0.9
PACKAGE_PARENT = Path(__file__).resolve().parents[2]  # on PYTHONPATH of the child processes
JOB_PARTS = ("train", "eval", "shuffle", "log", "checkpoint", "prepare", "loop")  # results.json wall_seconds


def data(n: int = N, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    return (
        torch.rand(n, SIZES[0], generator=g, dtype=torch.float64),
        0.1 + 0.8 * torch.rand(n, SIZES[-1], generator=g, dtype=torch.float64),
    )


def median_seconds(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
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


def bench_idiomatic(table: EngineTable, epochs: int, repeats: int) -> None:
    from torch import nn
    from torch.utils.data import DataLoader, TensorDataset

    X, Y = data()
    times = []
    for rep in range(repeats):
        torch.manual_seed(rep)
        model = nn.Sequential(nn.Linear(6, 13), nn.Sigmoid(), nn.Linear(13, 2), nn.Sigmoid()).double()
        opt = torch.optim.SGD(model.parameters(), lr=LR, momentum=MOM)
        loader = DataLoader(TensorDataset(X, Y), batch_size=1, shuffle=True)
        t = time.perf_counter()
        for _ in range(epochs):
            for xb, yb in loader:
                loss = nn.functional.mse_loss(model(xb), yb)
                opt.zero_grad()
                loss.backward()
                opt.step()
        times.append(time.perf_counter() - t)
    table.record("idiomatic DataLoader", 1, 1, epochs, statistics.median(times))


def time_epochs(make, R: int, epochs: int, repeats: int):
    """(engine, median seconds) of ``epochs`` epochs of R replicas on random data in the real shapes, a fresh
    engine ``make(params)`` per repeat: the updates alone (no shuffles, scoring or logging)."""
    from selpres.engines.model import init_replica_params

    X, Y = data()
    g = torch.Generator().manual_seed(1)
    orders = [torch.argsort(torch.rand(R, N, generator=g), dim=1) for _ in range(epochs)]
    params = init_replica_params(SIZES, list(range(R)))
    times = []
    for _ in range(repeats):
        eng = make(params)
        t = time.perf_counter()
        for o in orders:
            eng.train_epoch(X, Y, o)
        times.append(time.perf_counter() - t)
    return eng, statistics.median(times)


def bench_engine(
    table: EngineTable, name: str, R: int, epochs: int, repeats: int, threads=None, note: str = ""
) -> float:
    """One online engine's updates alone; returns ms per replica-run."""
    from selpres.engines.online import make_engine

    make = lambda p: make_engine(name, SIZES, p, LR, MOM, 1, threads=threads)
    eng, sec = time_epochs(make, R, epochs, repeats)
    label = f"{name} engine" if name != "fast" else f"fast engine ({type(eng).__name__})"
    return table.record(label, R, getattr(eng, "threads", 1), epochs, sec, note)


def bench_engines(table: EngineTable, quick: bool, native: bool) -> None:
    q = quick
    bench_idiomatic(table, epochs=2 if q else 3, repeats=1 if q else 2)
    bench_engine(table, "reference", 1, epochs=2 if q else 3, repeats=1 if q else 2)
    # the reference trains replicas one after another, so its cost per replica-run does not fall with R
    bench_engine(table, "reference", 10, epochs=1, repeats=1, note="(R=100, 1000: the same per replica-run)")
    for R, ep in [(1, 3), (10, 3), (100, 2), (1000, 1)]:
        ep, rep = (1 if q and R == 1000 else ep), (1 if q or R >= 100 else 2)
        bench_engine(table, "torch", R, epochs=ep, repeats=rep)
    if native:
        for R, ep, rep in [(1, 150, 5), (10, 150, 3), (100, 150, 3), (1000, 30, 3)]:
            if q:
                ep, rep = min(ep, 30 if R < 1000 else 5), min(rep, 3 if R < 100 else 1)
            bench_engine(table, "native", R, ep, rep, threads=1)
            if R > 1:
                bench_engine(table, "native", R, ep, rep)


BATCH_OPTIMIZERS = ("quickprop", "delta_bar_delta", "rprop", "adam")  # configs/optim/<name>.yaml


def bench_batch_engines(table: EngineTable, quick: bool, configs: Path) -> None:
    """The batch optimizers in ``BatchEngine`` (one step per epoch, as ``optim=<name>`` runs them), in the
    engine table beside the online rows: the same random data and presentations, so ms per replica-run and
    the ratio compare directly. The note gives ms per epoch of all R replicas. Timed at one thread (as the
    sensitivity sweep's jobs run) and, at R = 1000, at torch's default threads."""
    from selpres.run.train import job_engine

    default_threads = torch.get_num_threads()
    for name in BATCH_OPTIMIZERS:
        cfg = compose_train(configs, [f"optim={name}"])
        # job_engine reads only the problem's topology and initial weights: the engine a job builds
        make = lambda p, cfg=cfg: job_engine(cfg, SimpleNamespace(sizes=SIZES, init_params=p))
        plan = [(1, 30, 3, 1), (30, 10, 3, 1), (1000, 1 if quick else 3, 1, 1)]
        if default_threads > 1:
            plan.append((1000, 1 if quick else 3, 1, default_threads))
        for R, epochs, repeats, threads in plan:
            torch.set_num_threads(threads)
            try:
                _, sec = time_epochs(make, R, epochs, 1 if quick else repeats)
            finally:
                torch.set_num_threads(default_threads)
            table.record(f"batch {name}", R, threads, epochs, sec, f"{sec / epochs * 1e3:.2f} ms/epoch")


# ------------------------------------------------------------------------------------------- the whole job


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
    "import json, sys; from selpres.bench.bench import train_job; "
    "r = train_job(sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]); "
    "print(json.dumps({k: r[k] for k in ('wall_seconds', 'train_call_seconds', 'engine', 'status')}))"
)


def run_job_process(configs: Path, overrides: list[str], out_dir: Path) -> dict:
    """One job in a fresh Python process, as ``python train.py`` runs it (cold caches, its own threads)."""
    path = os.pathsep.join(p for p in (str(PACKAGE_PARENT), os.environ.get("PYTHONPATH")) if p)
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


# --------------------------------------------------------------------------------- shuffles and orders


def bench_shuffles(quick: bool) -> None:
    """Per-epoch shuffles of R replicas at n = 1002: numpy's argsort of the hashes (the fallback) and the
    native bucket sort (``kernels/shuffle.c``), called in turn in one run after checking that both give the
    same orders."""
    from selpres.presentation import sampler as S
    from selpres.presentation.schedule import build_schedule

    native = S.native_shuffles()[0] is not None
    print(
        "\nshuffles: one epoch's orders of all replicas, n = 1002 (epoch_orders in numpy: an argsort of the hashes;"
        + (" epoch_orders native)" if native else f" native unavailable: {S.native_shuffles()[1]})")
    )
    numpy_only = lambda: (None, "numpy row")
    sch = build_schedule([1.0], [EPOCHS], N)
    for R in (1, 30, 1000):
        g = torch.Generator().manual_seed(R)
        samplers = [S.SelectivePresentationSampler(torch.randperm(N, generator=g), sch, s) for s in range(R)]
        for s in samplers:
            s.set_epoch(7)

        buffer = torch.empty(R * N, dtype=torch.int64)  # reused every epoch, as a job does

        def in_numpy():
            real, S.native_shuffles = S.native_shuffles, numpy_only
            try:
                return S.epoch_orders(samplers, buffer)
            finally:
                S.native_shuffles = real

        ways = {"numpy": in_numpy}
        if native:
            ways["native"] = lambda: S.epoch_orders(samplers, buffer)
        want = ways["numpy"]().clone()  # (a view of the buffer the next call reuses)
        if not all(torch.equal(want, f()) for f in ways.values()):
            raise AssertionError("the native shuffles differ from numpy's argsort of the hashes")
        times = {k: [] for k in ways}
        for _ in range(max(3, (20 if quick else 60) // max(1, R // 100))):
            for k, f in ways.items():
                times[k].append(median_seconds(f, 1))
        med = {k: statistics.median(v) for k, v in times.items()}
        best = med["native" if native else "numpy"]
        cols = "  ".join(f"{k} {v * 1e3:8.3f}" for k, v in med.items())
        print(
            f"shuffle     R={R:<5} ms/epoch: {cols}   ({best * EPOCHS / R * 1e3:.3f} ms per replica-run)  "
            + "  ".join(f"x{med['numpy'] / v:.2f} {k}" for k, v in med.items() if k != "numpy"),
            flush=True,
        )


def bench_orders(quick: bool) -> None:
    """Selection cost of each priority order (random 6-D inputs): one order at n = 1002 and 1e5, and the
    1000 orders of an R = 1000 job at n = 1002 computed together (``priority_orders``)."""
    from selpres.presentation.orders import ORDERS, priority_order, priority_orders
    from selpres.seeding import generator

    print("\npriority orders: the selection cost, paid once per replica and job")
    for n in (N, 100_000):
        X, _ = data(n, seed=3)
        for kind in ORDERS:
            reps = 3 if n == N else 1
            sec = median_seconds(lambda: priority_order(X, kind, generator(0, "subset"), 2), reps)
            print(f"order       {kind:<11} n={n:<7} one order {sec * 1e3:10.2f} ms  (median of {reps})", flush=True)
            if n == N:
                gens = [generator(s, "subset") for s in range(1000)]
                sec = median_seconds(lambda: priority_orders(X, kind, gens, 2), 1)
                print(
                    f"order       {kind:<11} n={n:<7} R=1000     {sec * 1e3:10.2f} ms  (priority_orders: "
                    f"{sec:.3f} ms per replica)",
                    flush=True,
                )


def _per_replica_enlargement(params, X, Y, orders, kept: int, added: int) -> torch.Tensor:
    """The obvious way to enlarge by loss, for comparison: one nn.Module forward and one stable sort per
    replica (the chosen in error order)."""
    from selpres.engines.model import BPN, load_into

    net, rows = BPN(SIZES), []
    with torch.no_grad():
        for r in range(len(orders)):
            err = (load_into(net, params, r)(X) - Y).square().sum(1)
            tail = orders[r, kept:]
            by_error = torch.sort(err[tail], descending=True, stable=True).indices
            rows.append(torch.cat([orders[r, :kept], tail[by_error]]))
    return torch.stack(rows)


def bench_selection(quick: bool, configs: Path) -> bool:
    """The stage-wise orders' cost of choosing. One enlargement (loss_high, the paper's first: 50 of 952
    candidates added) scored batched (``selpres.presentation.selection``) beside a per-replica loop, and one reselect
    draw, at R = 1, 30, 1000; then whole selective 6-13-2 jobs at R = 30 and 1000 (R = 30 only with
    --quick) per order: the "select" clock phase against "train", and the charged presentations against
    the trained ones. Returns False if a job failed."""
    from selpres.engines.model import init_replica_params
    from selpres.engines.online import make_engine
    from selpres.presentation.orders import priority_orders, strata
    from selpres.presentation.selection import enlarge_by_loss, errors_of, one_thread, reselected_orders
    from selpres.seeding import generator

    print(
        "\nstage-wise orders: the cost of choosing, per enlargement (n = 1002, 50 of 952 candidates added; "
        "one torch thread, as in a job)"
    )
    X, Y = data(N, seed=3)
    for R in (1, 30, 1000):
        params = init_replica_params(SIZES, list(range(R)))
        orders = torch.stack(priority_orders(X, "stratified", [generator(s, "subset") for s in range(R)], 2))
        eng, seeds = make_engine("fast", SIZES, params, 0.15, 0.9, 1), list(range(R))  # as a job scores
        batched = functools.partial(lambda o, e: enlarge_by_loss(o, errors_of(e, X, Y), 50, 50, True), orders, eng)
        loop = functools.partial(_per_replica_enlargement, params, X, Y, orders, 50, 50)
        with one_thread():  # as a job chooses
            if not torch.equal(batched()[:, :100].sort(1).values, loop()[:, :100].sort(1).values):
                raise AssertionError("the batched enlargement chose other patterns than the per-replica loop")
            batched, loop = median_seconds(batched, 3), median_seconds(loop, 3)
            redraw = median_seconds(functools.partial(reselected_orders, strata(X, 2), seeds, 1), 3)
        print(
            f"select      loss_high   R={R:<5} batched {batched * 1e3:9.2f} ms  per-replica loop "
            f"{loop * 1e3:9.2f} ms  x{loop / batched:.1f}   reselect draw {redraw * 1e3:8.2f} ms",
            flush=True,
        )
    ok = True
    with tempfile.TemporaryDirectory(prefix="selpres-bench-") as tmp:
        for R in (30,) if quick else (30, 1000):
            for order in ("stratified", "loss_high", "reselect"):
                overrides = ["schedule=selective", "topology=6-13-2", f"replicas={R}", f"schedule.order={order}"]
                out = Path(tmp) / f"{order}-R{R}"
                try:
                    run_job_process(configs, overrides, out)
                    res = json.loads((out / "results.json").read_text())
                except (RuntimeError, ValueError, json.JSONDecodeError) as exc:
                    print(f"{order} R={R}: {exc}")
                    ok = False
                    continue
                ws = res["wall_seconds"]
                sel = ws.get("select", 0.0)
                print(
                    f"select job  {order:<11} R={R:<5} select {sel:7.3f} s  train {ws['train']:7.3f} s  "
                    f"select/train {sel / ws['train']:6.1%}   "
                    f"presentations {res['training_presentations']:,} trained + "
                    f"{res['selection_presentations']:,} charged per replica",
                    flush=True,
                )
    return ok


# --------------------------------------------------------------------------------- build and data


def bench_compile() -> None:
    """First-use build time of the native kernel: cold (empty cache) and cached (a new process's load)."""
    code = (
        "import time,torch;from selpres.native import load;t=time.perf_counter();"
        "load((6,13,2));print(time.perf_counter()-t)"
    )
    env = dict(os.environ, PYTHONPATH=str(PACKAGE_PARENT))
    with tempfile.TemporaryDirectory() as tmp:
        env["SELPRES_CACHE_DIR"] = tmp
        out = []
        for _ in range(2):
            p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
            out.append(float(p.stdout.strip()) if p.returncode == 0 else float("nan"))
    print(f"\nnative kernel build (6-13-2): cold {out[0]:.2f} s, cached {out[1] * 1e3:.1f} ms (load of the .so)")


def bench_exemplar_generation(quick: bool, configs: Path) -> None:
    """The exemplar set (1,050,625 candidates, one batched forward-dynamics call) against a per-row
    Python loop over the same grid (math module, the closed-form 2x2 solve), extrapolated from a slice."""
    from omegaconf import OmegaConf

    from selpres.arms.two_link import TwoLinkArm
    from selpres.data.paper import build_exemplar_set, grid_axis

    rcfg, dcfg = OmegaConf.load(configs / "robot/two_link.yaml"), OmegaConf.load(configs / "data/paper.yaml")
    arm = TwoLinkArm.from_config(rcfg)
    reps = 3 if quick else 7
    ex = build_exemplar_set(arm, dcfg)
    batched = median_seconds(lambda: build_exemplar_set(arm, dcfg), reps)

    m1, m2, l1, l2, g, a = rcfg.m1, rcfg.m2, rcfg.l1, rcfg.l2, rcfg.g, dcfg.accel_limit
    axes = {k: grid_axis(dcfg[k].lo, dcfg[k].hi, dcfg[k].step).tolist() for k in ("theta", "dtheta", "tau1", "tau2")}
    states = [
        (q1, w1, q2, w2)
        for q1 in axes["theta"]
        for w1 in axes["dtheta"]
        for q2 in axes["theta"]
        for w2 in axes["dtheta"]
    ]
    torques = [(t1, t2) for t1 in axes["tau1"] for t2 in axes["tau2"]]
    total = len(states) * len(torques)
    limit = 40 if quick else 120  # states timed; the rest extrapolated
    kept, t0 = 0, time.perf_counter()
    for q1, w1, q2, w2 in states[:limit]:
        for t1, t2 in torques:
            c2, s2 = math.cos(q2), math.sin(q2)
            h11 = l2 * l2 * m2 + 2 * l1 * l2 * m2 * c2 + l1 * l1 * (m1 + m2)
            h12 = l2 * l2 * m2 + l1 * l2 * m2 * c2
            h22 = l2 * l2 * m2
            b1 = (
                -m2 * l1 * l2 * s2 * w2 * w2
                - 2 * m2 * l1 * l2 * s2 * w1 * w2
                + m2 * l2 * g * math.cos(q1 + q2)
                + (m1 + m2) * l1 * g * math.cos(q1)
            )
            b2 = m2 * l1 * l2 * s2 * w1 * w1 + m2 * l2 * g * math.cos(q1 + q2)
            det = h11 * h22 - h12 * h12
            a1 = (h22 * (t1 - b1) - h12 * (t2 - b2)) / det
            a2 = (h11 * (t2 - b2) - h12 * (t1 - b1)) / det
            kept += abs(a1) <= a and abs(a2) <= a
    loop = (time.perf_counter() - t0) * len(states) / limit
    print(f"\nexemplar set: {total:,} candidates -> {len(ex.X)} patterns")
    print(f"  batched torch (build_exemplar_set)  {batched * 1e3:9.1f} ms  (median of {reps})")
    print(
        f"  per-row Python loop                 {loop * 1e3:9.1f} ms  (extrapolated from {limit} of "
        f"{len(states)} states)  ratio x {loop / batched:.0f}"
    )


# ------------------------------------------------------------------------------------------------ main


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

    table = EngineTable()
    if args.job_repeats < 1:
        ap.error(f"--job-repeats={args.job_repeats}: expected a whole number >= 1")
    if args.jobs_only:
        return 0 if bench_jobs(table, q, args.configs.resolve(), args.job_repeats) else 1
    bench_engines(table, q, native)
    bench_batch_engines(table, q, args.configs.resolve())
    jobs_ok = bench_jobs(table, q, args.configs.resolve(), args.job_repeats)
    bench_shuffles(q)
    bench_orders(q)
    jobs_ok = bench_selection(q, args.configs.resolve()) and jobs_ok
    if native:
        bench_compile()
    bench_exemplar_generation(q, args.configs)
    print(f"\nload average at end {os.getloadavg()[0]:.2f} (other processes on the machine slow every number)")
    return 0 if jobs_ok else 1


if __name__ == "__main__":
    sys.exit(main())
