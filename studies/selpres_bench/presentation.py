"""selpres-bench: the per-epoch shuffles, the priority orders' cost and the stage-wise orders' cost of choosing."""

from __future__ import annotations

import functools
import json
import statistics
import tempfile
from pathlib import Path

import torch

from selpres_bench.common import EPOCHS, SIZES, N, data, median_seconds
from selpres_bench.jobs import run_job_process


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
    from selpres.presentation.orders import fixed_orders, priority_order, priority_orders
    from selpres.seeding import generator

    print("\npriority orders: the selection cost, paid once per replica and job")
    for n in (N, 100_000):
        X, _ = data(n, seed=3)
        for kind in fixed_orders():
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
    from selpres.engines.factory import EngineSpec, build_engine
    from selpres.engines.model import init_replica_params
    from selpres.presentation.orders import priority_orders
    from selpres.presentation.orders._loss import enlarge_by_loss
    from selpres.presentation.orders.reselect import reselected_orders
    from selpres.presentation.partition import strata
    from selpres.presentation.selection import errors_of, one_thread
    from selpres.seeding import generator

    print(
        "\nstage-wise orders: the cost of choosing, per enlargement (n = 1002, 50 of 952 candidates added; "
        "one torch thread, as in a job)"
    )
    X, Y = data(N, seed=3)
    for R in (1, 30, 1000):
        params = init_replica_params(SIZES, list(range(R)))
        orders = torch.stack(priority_orders(X, "stratified", [generator(s, "subset") for s in range(R)], 2))
        eng, seeds = build_engine(EngineSpec.online("fast", SIZES, 0.15, 0.9), params), list(range(R))  # as a job
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
