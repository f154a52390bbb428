"""selpres-bench: SeTa's selection, its exact 1-D k-means in C against the numpy programme, side by side.

    python -m selpres_bench.pruning            # k-means calls, then the two-link and PUMA SeTa jobs (~2 minutes)
    python -m selpres_bench.pruning --quick    # k-means calls and the two-link job only

Rows: one k-means call (``selpres.presentation.kmeans.kmeans_edges``, 5 groups) on SeTa-like scores (squared
exponential losses, a tenth never presented at 3.0) at the draw sizes of the two study arms, 9,000 and 90,000, C and
numpy called in turn after checking that they give the same groups; then whole SeTa jobs (``train()``, 12 replicas,
one thread), each run twice in this process, k-means in C and in numpy, with the same numbers required of both. Jobs
report the "select" and "train" phases in CPU seconds of the job's thread (so other processes on a shared machine
do not inflate them) beside wall seconds.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import statistics
import time

import numpy as np

from selpres_bench.common import median_seconds

JOBS = {  # name: the overrides of ``python train.py``
    "two-link n=1e4": [
        "+design/modern=two_link_paper_conventional",
        "schedule=seta",
        "data=sampled",
        "data.n=10000",
    ],
    "PUMA n=1e5": [
        "+design/modern=puma560_paper_conventional",
        "schedule=seta",
        "data.n=100000",
        "schedule.epochs=[10]",
    ],
}
COMMON = ["replicas=12", "threads=1", "logging.tensorboard=false", "checkpoint.enabled=false"]


def seta_scores(n: int, seed: int) -> np.ndarray:
    """Scores as SeTa's k-means meets them: losses (squared exponential), a tenth never presented (3.0)."""
    rng = np.random.default_rng(seed)
    x = 0.01 * rng.exponential(size=n) ** 2
    x[rng.random(n) < 0.1] = 3.0
    return x


@contextlib.contextmanager
def numpy_kmeans():
    """The numpy programme even where the C kernel loads (what a machine without a compiler runs)."""
    from selpres.presentation import kmeans as K

    real, quiet = K.native_kmeans, logging.getLogger("selpres.presentation.pruning.seta")
    K.native_kmeans, level = (lambda: (None, "bench row")), quiet.level
    quiet.setLevel(logging.ERROR)  # not SeTa's warning that its k-means runs in numpy: this row asks for it
    try:
        yield
    finally:
        K.native_kmeans = real
        quiet.setLevel(level)


def cpu_ms(fn, repeats: int) -> float:
    """Median CPU milliseconds of this thread per call."""
    return median_seconds(fn, repeats, time.thread_time) * 1e3


def kmeans_rows(quick: bool):
    """One k-means call at the two arms' draw sizes, C and numpy in turn: lines, as measured."""
    from selpres.presentation.kmeans import kmeans_edges, kmeans_implementation

    yield f"SeTa's k-means, one call, 5 groups (CPU ms of one thread; kernel: {kmeans_implementation()})"
    for n in (9_000, 90_000):
        inputs = [seta_scores(n, s) for s in range(3)]
        for x in inputs:
            with numpy_kmeans():
                want = kmeans_edges(x, 5)
            if not np.array_equal(kmeans_edges(x, 5), want):
                raise AssertionError("the C k-means gives other groups than numpy's programme")
        reps = (2 if quick else 4) * (10 if n < 50_000 else 1)
        c, py = [], []
        for _ in range(3):  # in turn, so a busy spell slows both
            c.append(cpu_ms(lambda: [kmeans_edges(x, 5) for x in inputs], reps) / len(inputs))
            with numpy_kmeans():
                py.append(cpu_ms(lambda: [kmeans_edges(x, 5) for x in inputs], max(1, reps // 4)) / len(inputs))
        c_ms, py_ms = statistics.median(c), statistics.median(py)
        yield f"kmeans      n={n:<7} numpy {py_ms:9.2f} ms   C {c_ms:7.3f} ms   x{py_ms / c_ms:6.1f}"


class _CpuClock:
    """``selpres.run.train.Clock`` that also keeps each phase's CPU seconds of the calling thread."""

    def __init__(self, base):
        self._base = base()
        self.cpu: dict[str, float] = {}

    @contextlib.contextmanager
    def __call__(self, phase: str):
        t = time.thread_time()
        with self._base(phase):
            try:
                yield
            finally:
                self.cpu[phase] = self.cpu.get(phase, 0.0) + time.thread_time() - t

    def __getattr__(self, name):
        return getattr(self._base, name)


def run_seta(overrides: list[str], configs=None) -> tuple[dict, dict]:
    """One job in this process: (results, CPU seconds per phase)."""
    import selpres.run.train as T
    from selpres.run.config import CONFIG_DIR, compose_train

    clocks = []
    real = T.Clock
    T.Clock = lambda: clocks.append(_CpuClock(real)) or clocks[-1]
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            res = T.train(compose_train(configs or CONFIG_DIR, [*overrides, *COMMON]))
    finally:
        T.Clock = real
    return res, clocks[-1].cpu


def _untimed(curves: list[dict]) -> list[dict]:
    """The curves without their clock readings (``work_seconds``), which differ from run to run."""
    return [{k: v for k, v in rec.items() if not k.endswith("_seconds")} for rec in curves]


def job_rows(quick: bool, configs=None):
    """Whole SeTa jobs, k-means in C and in numpy: lines, as measured."""
    yield (
        "SeTa jobs, 12 replicas, one thread: select and train phases, CPU s of the job's thread (wall s), "
        "k-means in C and in numpy"
    )
    for name, overrides in list(JOBS.items())[:1] if quick else JOBS.items():
        runs = {}
        for way in ("C", "numpy"):
            with numpy_kmeans() if way == "numpy" else contextlib.nullcontext():
                res, cpu = run_seta(overrides, configs)
            if way == "C" and res["selector"]["kmeans"] != "native":
                yield f"{name}: the C k-means is unavailable here ({res['selector']['kmeans']})"
                break
            runs[way] = (res, cpu)
            wall = res["wall_seconds"]
            yield (
                f"seta job    {name:<15} k-means {way:<5} select {cpu['select']:7.3f} s ({wall['select']:7.3f})  "
                f"train {cpu['train']:7.3f} s ({wall['train']:7.3f})  select/train {cpu['select'] / cpu['train']:7.1%}"
                f" ({wall['select'] / wall['train']:7.1%})"
            )
        if len(runs) == 2:
            (c, c_cpu), (py, py_cpu) = runs["C"], runs["numpy"]
            if c["replica_results"] != py["replica_results"] or _untimed(c["curves"]) != _untimed(py["curves"]):
                raise AssertionError(f"{name}: the C k-means changed the job's numbers")
            yield (
                f"seta job    {name:<15} select numpy / C x{py_cpu['select'] / c_cpu['select']:.1f} "
                "(CPU); the same numbers (replica_results, curves but their clock)"
            )


def rows(quick: bool, configs=None):
    """Every line of this section, as measured (``selpres-bench`` prints them among its own)."""
    yield ""
    yield from kmeans_rows(quick)
    yield ""
    yield from job_rows(quick, configs)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="k-means calls and the two-link job only")
    args = ap.parse_args(argv)
    import os

    print(f"load average at start {os.getloadavg()[0]:.2f}")
    for line in rows(args.quick):
        print(line, flush=True)
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
