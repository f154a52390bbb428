"""Benchmark the training engines side by side on one machine, in one run.

    python scripts/bench_engine.py            # full (a few minutes)
    python scripts/bench_engine.py --quick    # short version (fewer epochs / repeats)

A "replica-run" is one conventional run of the paper: 150 epochs x 1002 single-pattern updates of a
6-13-2 sigmoid net (SGD lr 0.15, momentum 0.9). Slow configurations are timed over a few epochs and
extrapolated to 150 (the ``epochs`` column says how many were timed); times are medians over
``repeats``. Data are random, in the real shapes (6 inputs, 2 outputs): no dependency on selpres.data.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import torch
from torch import nn
from torch.utils.data import DataLoader, TensorDataset

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from selpres import _kernels  # noqa: E402
from selpres.engine import make_engine  # noqa: E402
from selpres.model import init_replica_params  # noqa: E402

SIZES = (6, 13, 2)
N, EPOCHS, LR, MOM = 1002, 150, 0.15, 0.9
ROWS: list[dict] = []


def data(seed=0):
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(N, SIZES[0], generator=g, dtype=torch.float64),
            0.1 + 0.8 * torch.rand(N, SIZES[-1], generator=g, dtype=torch.float64))


def record(label, R, threads, epochs, seconds, note=""):
    """``seconds``: median wall time of ``epochs`` epochs for all R replicas."""
    per_run = seconds * EPOCHS / epochs / R
    row = dict(label=label, R=R, threads=threads, epochs=epochs, per_run=per_run,
               pps=R * N * epochs / seconds, note=note)
    ROWS.append(row)
    base = ROWS[0]["per_run"] if ROWS else per_run
    print(f"{label:<22} R={R:<5} thr={threads!s:<3} ep={epochs:<4} {per_run * 1e3:>10.2f} ms/replica-run "
          f"{row['pps']:>12.3g} pres/s  x{base / per_run:>8.1f}  {note}", flush=True)


def bench_idiomatic(epochs, repeats):
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
    record("idiomatic DataLoader", 1, 1, epochs, statistics.median(times), f"extrapolated from {epochs} epochs")


def bench_engine(name, R, epochs, repeats, threads=None, note=""):
    X, Y = data()
    g = torch.Generator().manual_seed(1)
    orders = [torch.argsort(torch.rand(R, N, generator=g), dim=1) for _ in range(epochs)]
    params = init_replica_params(SIZES, list(range(R)))
    times = []
    for _ in range(repeats):
        eng = make_engine(name, SIZES, params, LR, MOM, 1, threads=threads)
        t = time.perf_counter()
        for o in orders:
            eng.train_epoch(X, Y, o)
        times.append(time.perf_counter() - t)
    thr = getattr(eng, "threads", 1)
    if epochs < EPOCHS:
        note = (note + f" extrapolated from {epochs} epochs").strip()
    record(f"{name} engine", R, thr, epochs, statistics.median(times), note)


def bench_compile():
    """First-use build time of the native kernel: cold (empty cache) and cached (a new process's load)."""
    import subprocess
    import tempfile

    code = ("import time,torch;from selpres import _kernels;t=time.perf_counter();"
            "_kernels.load((6,13,2));print(time.perf_counter()-t)")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    with tempfile.TemporaryDirectory() as tmp:
        env["SELPRES_CACHE_DIR"] = tmp
        out = []
        for _ in range(2):
            p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
            out.append(float(p.stdout.strip()) if p.returncode == 0 else float("nan"))
    print(f"native kernel build (6-13-2): cold {out[0]:.2f} s, cached {out[1] * 1e3:.1f} ms (load of the .so)")


def bench_exemplar_generation(quick):
    """The exemplar set (1,050,625 candidates, one batched forward-dynamics call) against a per-row
    Python loop over the same grid (math module, the closed-form 2x2 solve), extrapolated from a slice."""
    import math
    import statistics

    from omegaconf import OmegaConf

    from selpres.data import build_exemplar_set, grid_axis
    from selpres.robot import TwoLinkArm

    root = Path(__file__).resolve().parents[1] / "configs"
    rcfg, dcfg = OmegaConf.load(root / "robot/two_link.yaml"), OmegaConf.load(root / "data/paper.yaml")
    arm = TwoLinkArm.from_config(rcfg)
    times = []
    for _ in range(3 if quick else 7):
        t0 = time.perf_counter()
        ex = build_exemplar_set(arm, dcfg)
        times.append(time.perf_counter() - t0)
    batched = statistics.median(times)

    m1, m2, l1, l2, g, a = rcfg.m1, rcfg.m2, rcfg.l1, rcfg.l2, rcfg.g, dcfg.accel_limit
    axes = {k: grid_axis(dcfg[k].lo, dcfg[k].hi, dcfg[k].step).tolist() for k in ("theta", "dtheta", "tau1", "tau2")}
    states = [(q1, w1, q2, w2) for q1 in axes["theta"] for w1 in axes["dtheta"] for q2 in axes["theta"] for w2 in axes["dtheta"]]
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
            b1 = -m2 * l1 * l2 * s2 * w2 * w2 - 2 * m2 * l1 * l2 * s2 * w1 * w2 + m2 * l2 * g * math.cos(q1 + q2) + (m1 + m2) * l1 * g * math.cos(q1)
            b2 = m2 * l1 * l2 * s2 * w1 * w1 + m2 * l2 * g * math.cos(q1 + q2)
            det = h11 * h22 - h12 * h12
            a1 = (h22 * (t1 - b1) - h12 * (t2 - b2)) / det
            a2 = (h11 * (t2 - b2) - h12 * (t1 - b1)) / det
            kept += abs(a1) <= a and abs(a2) <= a
    loop = (time.perf_counter() - t0) * len(states) / limit
    print(f"\nexemplar set: {total:,} candidates -> {len(ex.X)} patterns")
    print(f"  batched torch (build_exemplar_set)  {batched * 1e3:9.1f} ms  (median of {len(times)})")
    print(f"  per-row Python loop                 {loop * 1e3:9.1f} ms  (extrapolated from {limit} of {len(states)} states)"
          f"  ratio x {loop / batched:.0f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer epochs and repeats")
    args = ap.parse_args()
    q = args.quick
    print(f"python {platform.python_version()}, torch {torch.__version__}, {os.cpu_count()} CPUs, "
          f"torch threads {torch.get_num_threads()}, load average at start {os.getloadavg()[0]:.2f}")
    print(f"replica-run = {EPOCHS} epochs x {N} patterns, 6-13-2, batch 1; times are medians; "
          f"ratio = idiomatic / this\n")
    try:
        _kernels.load(SIZES)
        native = True
    except _kernels.KernelUnavailable as exc:
        print(f"native kernel unavailable: {exc}")
        native = False

    bench_idiomatic(epochs=2 if q else 3, repeats=1 if q else 2)
    bench_engine("reference", 1, epochs=2 if q else 3, repeats=1 if q else 2)
    # the reference trains replicas one after another, so its cost per replica-run does not fall with R
    bench_engine("reference", 10, epochs=1, repeats=1, note="(R=100, 1000: the same per replica-run)")
    for R, ep in [(1, 3), (10, 3), (100, 2), (1000, 1)]:
        bench_engine("torch", R, epochs=ep if not q or R < 1000 else 1, repeats=1 if q or R >= 100 else 2)
    if native:
        for R, ep, rep in [(1, 150, 5), (10, 150, 3), (100, 150, 3), (1000, 30, 3)]:
            if q:
                ep, rep = min(ep, 30 if R < 1000 else 5), min(rep, 3 if R < 100 else 1)
            bench_engine("native", R, ep, rep, threads=1)
            if R > 1:
                bench_engine("native", R, ep, rep)
        bench_compile()
    bench_exemplar_generation(q)
    print(f"\nload average at end {os.getloadavg()[0]:.2f} (other processes on the machine slow every number)")


if __name__ == "__main__":
    main()
