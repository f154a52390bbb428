"""selpres-bench: the training engines alone (the idiomatic loop, reference, torch, native) and the batch optimizers."""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import torch

from selpres.run.config import compose_train
from selpres_bench.common import LR, MOM, SIZES, EngineTable, N, data


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
    from selpres.engines.factory import EngineSpec, build_engine

    make = lambda p: build_engine(EngineSpec.online(name, SIZES, LR, MOM, 1, threads), p)
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
    from selpres.engines.factory import build_engine
    from selpres.run.resolve import resolve

    default_threads = torch.get_num_threads()
    for name in BATCH_OPTIMIZERS:
        spec = resolve(compose_train(configs, [f"optim={name}"])).engine.replace(sizes=SIZES)
        make = lambda p, spec=spec: build_engine(spec, p)  # the engine a job of optim=<name> builds
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
