"""Speed at scale (issue 11, item 9), every row measured side by side in one run.

    python -m selpres_bench.scale            # about a minute on an idle 2-core machine
    python -m selpres_bench.scale --quick    # fewer repeats and presentations

Rows:

* exemplar generation: 10^6 patterns of the PUMA 560 (the 6-joint arm of ``configs/robot/puma560.yaml``)
  through ``selpres.data.sampled`` (route inverse: q, q̇, q̈ drawn, τ by Newton-Euler), Sobol and uniform
  points, and the two-link arm for comparison. Target: <= 5 s.
* engine throughput: presentations per second of the training engine (``engine=fast``) for the PUMA's
  18-40-6 and the paper's 6-13-2 at R = 4, on exemplar sets of n = 10^3, 10^5 and 10^6 patterns, the same
  number of presentations each (random indices into the set, as a shuffled epoch presents them). Large
  sets leave the caches, so the ratio to n = 10^3 is the figure of merit. Target: within 25 % (issue 22,
  item 6). Sets of 10^5 and 10^6 run both as they are and staged (``selpres.native.staging``: one row of
  whole cache lines per pattern, in 2 MB pages), with bitwise the same weights (asserted). Every (n, path)
  is measured once per repeat, interleaved, and divided by that repeat's n = 10^3 time; the ratios'
  median and range are printed, in CPU time (on shared cores, time spent descheduled is not the engine's).
* padded lanes: the kernel trains replicas in groups of 4 lanes, so R = 10 and R = 12 both run 3 groups
  and should take the same time. Measured after a warm-up epoch (the padded lanes' momentum buffers reach
  their steady state), interleaved, 6-13-2 on n = 10^4: the ratio R = 10 / R = 12 is the figure of merit
  (ideal 1.0; why configs/experiment/large.yaml runs 12 replicas).

The load average before and after is printed: on a busy machine every row is slower, the ratios less so.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import torch

from selpres.run.config import CONFIG_DIR, compose_train

GENERATION_N = 1_000_000
ENGINE_SIZES = (1_000, 100_000, 1_000_000)
# (topology, presentations per replica as a multiple of the run's): the paper's 6-13-2 is ~10x cheaper a
# presentation, so it gets more of them (and the memory's share of its time is the larger)
ENGINE_TOPOLOGIES, REPLICAS = (((18, 40, 6), 1), ((6, 13, 2), 5)), 4
PADDING_TOPOLOGY, PADDING_N, PADDING_REPLICAS = (6, 13, 2), 10_000, (12, 10)  # 3 groups of 4 lanes each


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:  # pragma: no cover
        return "n/a"


def generation_rows(repeats: int) -> list[dict]:
    """Seconds to draw 10^6 patterns (median of ``repeats``), per arm and kind of points."""
    from selpres.arms.sources import make_arm
    from selpres.data import sampled as S
    from selpres.run.specs import robot_spec

    rows = []
    for robot, draw in (("puma560", "sobol"), ("puma560", "uniform"), ("two_link", "sobol")):
        arm = make_arm(robot_spec(compose_train(CONFIG_DIR, [f"robot={robot}"]).robot))
        data = {
            "route": "inverse",
            "q": None,
            "dq": [-1.0, 1.0],
            "accel_limit": 2.0,
            "tau": None,
            "wrench": None,
        }
        box = S.boxes(arm, data)
        times = []
        for r in range(repeats):
            t0 = time.perf_counter()
            drawn = S.sample(arm, box, "inverse", S.Points(draw, 3 * arm.dof, r), GENERATION_N)
            times.append(time.perf_counter() - t0)
        assert drawn.tau.shape == (GENERATION_N, arm.dof)
        rows.append({"arm": robot, "points": draw, "patterns": GENERATION_N, "seconds": statistics.median(times)})
    return rows


def engine_rows(repeats: int, presentations: int) -> list[dict]:
    """Presentations per second of engine=fast at each n and topology (same R and number of presentations),
    large sets read as they are (``staged`` False) and staged (``selpres.native.staging``), side by side.

    Each repeat measures every (n, path) once, interleaved, and divides by that repeat's n = 10^3 time:
    the ratios' median and range over the repeats are printed. Times are the calling thread's CPU seconds
    (``time.thread_time``: R = 4 is one group, trained in the calling thread, no pool; the process's time
    would also count torch's OpenMP threads spinning after a torch call), so time spent descheduled by
    other sessions on shared cores does not count; slower memory and caches do."""
    from selpres.engines.factory import EngineSpec, build_engine
    from selpres.engines.model import init_replica_params
    from selpres.native import staging

    rows = []
    for topology, per_replica in ENGINE_TOPOLOGIES:
        count = presentations * per_replica
        gen = torch.Generator().manual_seed(0)
        sets = {
            n: (
                torch.rand(n, topology[0], dtype=torch.float64, generator=gen),
                0.1 + 0.8 * torch.rand(n, topology[-1], dtype=torch.float64, generator=gen),
            )
            for n in ENGINE_SIZES
        }
        orders = {n: torch.randint(n, (REPLICAS, count), generator=gen) for n in ENGINE_SIZES}
        params = init_replica_params(topology, list(range(REPLICAS)))
        paths = [(ENGINE_SIZES[0], False)] + [(n, st) for n in ENGINE_SIZES[1:] for st in (False, True)]
        cpu: dict[tuple[int, bool], list[float]] = {k: [] for k in paths}
        wall: dict[tuple[int, bool], list[float]] = {k: [] for k in paths}
        weights: dict[tuple[int, bool], torch.Tensor] = {}
        name = None
        threshold = staging.STAGE_BYTES
        try:
            for _ in range(repeats):
                for n, staged in paths:  # interleaved: a load change hits every size and path alike
                    staging.STAGE_BYTES = threshold if staged else 1 << 62
                    engine = build_engine(EngineSpec.online("fast", topology, 0.01, 0.9), [p.clone() for p in params])
                    name = engine.name
                    X, Y = sets[n]
                    if staged and name == "native":  # the one-off copy is timed in its own row, not here
                        engine._staged = staging.stage(None, X, Y)
                    c0, w0 = time.thread_time(), time.perf_counter()
                    engine.train_epoch(X, Y, orders[n])
                    cpu[(n, staged)].append(time.thread_time() - c0)
                    wall[(n, staged)].append(time.perf_counter() - w0)
                    weights[(n, staged)] = engine.params()[0]
        finally:
            staging.STAGE_BYTES = threshold
        for n in ENGINE_SIZES[1:]:  # staging changes no number: the same weights either way
            assert torch.equal(weights[(n, False)], weights[(n, True)]), (topology, n)
        base = cpu[paths[0]]
        for key in paths:
            ratios = [c / b for c, b in zip(cpu[key], base)]
            rows.append(
                {
                    "n": key[0],
                    "staged": key[1],
                    "engine": name,
                    "topology": "-".join(map(str, topology)),
                    "replicas": REPLICAS,
                    "presentations": count * REPLICAS,
                    "presentations_per_cpu_s": count * REPLICAS / statistics.median(cpu[key]),
                    "presentations_per_wall_s": count * REPLICAS / statistics.median(wall[key]),
                    "time_ratio_to_n_1e3": statistics.median(ratios),
                    "time_ratio_min": min(ratios),
                    "time_ratio_max": max(ratios),
                }
            )
    return rows


def staging_rows(repeats: int) -> list[dict]:
    """Seconds to stage each topology's n = 10^6 set (the one-off copy per job), median of ``repeats``."""
    from selpres.native import staging

    rows = []
    for topology, _ in ENGINE_TOPOLOGIES:
        gen = torch.Generator().manual_seed(0)
        X = torch.rand(ENGINE_SIZES[-1], topology[0], dtype=torch.float64, generator=gen)
        Y = torch.rand(ENGINE_SIZES[-1], topology[-1], dtype=torch.float64, generator=gen)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            staged = staging.Staged(X, Y)
            times.append(time.perf_counter() - t0)
        rows.append(
            {
                "topology": "-".join(map(str, topology)),
                "n": ENGINE_SIZES[-1],
                "row_doubles": staged.rows.shape[1],
                "megabytes": staged.rows.numel() * 8 / 1e6,
                "seconds": statistics.median(times),
            }
        )
    return rows


def padding_rows(repeats: int, presentations: int) -> list[dict]:
    """Seconds per epoch of ``presentations`` per replica for R = 12 (no padded lane) and R = 10 (two),
    after a warm-up epoch of as many presentations, interleaved over the repeats."""
    from selpres.engines.factory import EngineSpec, build_engine
    from selpres.engines.model import init_replica_params

    gen = torch.Generator().manual_seed(0)
    X = torch.rand(PADDING_N, PADDING_TOPOLOGY[0], dtype=torch.float64, generator=gen)
    Y = 0.1 + 0.8 * torch.rand(PADDING_N, PADDING_TOPOLOGY[-1], dtype=torch.float64, generator=gen)
    engines, orders = {}, {}
    for R in PADDING_REPLICAS:
        params = init_replica_params(PADDING_TOPOLOGY, list(range(R)))
        engines[R] = build_engine(EngineSpec.online("fast", PADDING_TOPOLOGY, 0.15, 0.9), params)  # the paper's
        orders[R] = torch.randint(PADDING_N, (R, presentations), generator=gen)
        engines[R].train_epoch(X, Y, orders[R])  # warm-up: not timed
    times: dict[int, list[float]] = {R: [] for R in PADDING_REPLICAS}
    for _ in range(repeats):
        for R in PADDING_REPLICAS:  # interleaved
            t0 = time.perf_counter()
            engines[R].train_epoch(X, Y, orders[R])
            times[R].append(time.perf_counter() - t0)
    base = statistics.median(times[PADDING_REPLICAS[0]])
    return [
        {
            "replicas": R,
            "engine": engines[R].name,
            "topology": "-".join(map(str, PADDING_TOPOLOGY)),
            "presentations_per_replica": presentations,
            "seconds": statistics.median(t),
            "time_ratio_to_R_12": statistics.median(t) / base,
        }
        for R, t in times.items()
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m selpres_bench.scale",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=__doc__.split("\n\n", 2)[2],
    )
    ap.add_argument("--quick", action="store_true", help="fewer repeats and presentations")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows to this JSON file")
    ap.add_argument("--engine-only", action="store_true", help="only the engine throughput and staging rows")
    args = ap.parse_args(argv)
    repeats, presentations = (2, 100_000) if args.quick else (5, 400_000)
    print(f"load average before: {_load()}  (torch threads {torch.get_num_threads()})")
    gen = [] if args.engine_only else generation_rows(max(1, repeats - 2))
    if gen:
        print(f"\nexemplar generation, {GENERATION_N:,} patterns (route inverse; target <= 5 s):")
    for r in gen:
        print(f"  {r['arm']:9s} {r['points']:8s} {r['seconds']:6.2f} s")
    eng = engine_rows(repeats, presentations)
    for topology in dict.fromkeys(r["topology"] for r in eng):
        rows = [r for r in eng if r["topology"] == topology]
        print(
            f"\nengine throughput, topology {topology}, R = {REPLICAS}, engine {rows[0]['engine']}, "
            f"{rows[0]['presentations']:,} presentations per measurement;\n  CPU time of the calling thread, "
            f"ratio median [range] over {repeats} interleaved repeats (target: n = 1e5, 1e6 within 25 % of 1e3):"
        )
        for r in rows:
            path = "staged" if r["staged"] else ("as is" if r["n"] > ENGINE_SIZES[0] else "")
            print(
                f"  n = {r['n']:>9,} {path:7s} {r['presentations_per_cpu_s']:12,.0f} presentations/CPU s  "
                f"time x{r['time_ratio_to_n_1e3']:.2f} [{r['time_ratio_min']:.2f}-{r['time_ratio_max']:.2f}] "
                f"of n = 1e3  ({r['presentations_per_wall_s']:,.0f}/wall s)"
            )
    stg = staging_rows(max(1, repeats - 2))
    print("\nstaging a set of 10^6 patterns (once per job; selpres.native.staging):")
    for r in stg:
        print(f"  {r['topology']:8s} rows of {r['row_doubles']} doubles, {r['megabytes']:.0f} MB, {r['seconds']:.3f} s")
    pad = [] if args.engine_only else padding_rows(repeats, presentations)
    if not pad:
        print(f"\nload average after: {_load()}")
        if args.json is not None:
            args.json.write_text(json.dumps({"engine": eng, "staging": stg, "load": _load()}, indent=1))
        return 0
    print(
        f"\npadded lanes, topology {pad[0]['topology']}, engine {pad[0]['engine']}, n = {PADDING_N:,}, "
        f"{presentations:,} presentations per replica (3 groups of 4 lanes either way; ideal x1.00):"
    )
    for r in pad:
        ratio = r["time_ratio_to_R_12"]
        print(f"  R = {r['replicas']:>2}  {r['seconds']:7.3f} s  time x{ratio:.2f} of R = 12")
    print(f"\nload average after: {_load()}")
    if args.json is not None:
        rows = {"generation": gen, "engine": eng, "staging": stg, "padding": pad, "load": _load()}
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
