"""Mini-batch training of many replicas, side by side in one run: the native kernel, the torch mini-batch engine, and
what a PyTorch user would write for many models at once (``torch.func.stack_module_state`` + ``vmap``, eager and
``torch.compile``d).

For each Adam design of ``experiment=modern`` (``configs/design/modern/<arm>_adam_conventional.yaml``: its topology,
n, units, rate, batch and cosine schedule; 12 replicas), every variant trains the same 12 replicas on random data
in the design's shapes (float64, each replica its own order), and the row gives presentations per second (median
of the repeats) and the native kernel's ratio to each. The kernel runs a whole epoch per call, the others a
stretch of mini-batches (their speed per mini-batch does not depend on how many). The vmap variants are a user's
code: one ``nn.Sequential`` per replica stacked, the forward pass vmapped over replicas, the sum of the replicas'
mse backpropagated, ``torch.optim.Adam`` on the stacked weights with a cosine ``LambdaLR`` (one step count for
all replicas: no pruning here). The compiled one compiles that loss (forward and backward, AOTAutograd); the step
stays eager (a compiled step recompiles as the rate changes). Compilation is timed apart and excluded from the
rate. Every variant runs at one thread, so that they compare like with like on this shared 2-core machine (the
kernel also at torch's thread count). Target (issue 28): native >= 10x the torch engine and ahead of both vmap variants.
``python -m selpres.bench.minibatch [--quick]``.
"""

from __future__ import annotations

import argparse
import copy
import math
import statistics
import time

import torch

from selpres.run.config import CONFIG_DIR, compose_train

DESIGNS = ("two_link_adam_conventional", "puma560_adam_conventional")
R = 12


def design(name: str) -> dict:
    """The plain values the engines take, from the design's composed config."""
    c = compose_train(CONFIG_DIR, [f"+design/modern={name}", f"replicas={R}"])
    o = c.optim
    return dict(
        sizes=tuple(int(s) for s in c.topology.layers.split("-")),
        n=int(c.data.n),
        rule=o.name.value,
        hparams={k: o[k] for k in ("lr", "beta1", "beta2", "eps", "weight_decay") if o[k] is not None},
        batch=int(o.batch_size),
        activation=c.model.activation.value,
        schedule=o.lr_schedule.value,
        horizon=float(c.data.n * sum(c.schedule.epochs)),
    )


def _data(d: dict, m: int):
    g = torch.Generator().manual_seed(0)
    X = torch.rand(d["n"], d["sizes"][0], generator=g, dtype=torch.float64)
    Y = torch.rand(d["n"], d["sizes"][-1], generator=g, dtype=torch.float64)
    order = torch.stack([torch.randperm(d["n"], generator=g)[:m] for _ in range(R)])
    return X, Y, order


def _rate(fn, presentations: int, repeats: int) -> tuple[float, float]:
    """Presentations per second of ``fn``: (wall, CPU time of the calling thread), medians of ``repeats`` timed
    calls after one untimed. On a shared machine the CPU time is the steadier figure: it leaves out the time the
    thread waited for a core (at one thread, every variant runs in the calling thread)."""
    fn()
    wall, cpu = [], []
    for _ in range(repeats):
        t, c = time.perf_counter(), time.thread_time()
        fn()
        cpu.append(time.thread_time() - c)
        wall.append(time.perf_counter() - t)
    return presentations / statistics.median(wall), presentations / statistics.median(cpu)


def engine_rate(d: dict, native: bool, m: int, repeats: int, threads: int | None = None) -> float:
    from selpres.engines.minibatch import MiniBatchEngine
    from selpres.engines.model import init_replica_params
    from selpres.engines.native_minibatch import NativeMiniBatchEngine

    X, Y, order = _data(d, m)
    params = init_replica_params(d["sizes"], list(range(R)))
    args = (d["sizes"], params, d["rule"], dict(d["hparams"]), d["batch"], d["activation"], d["schedule"])
    eng = (
        NativeMiniBatchEngine(*args, d["horizon"], threads=threads) if native else MiniBatchEngine(*args, d["horizon"])
    )
    return _rate(lambda: eng.train_epoch(X, Y, order), R * m, repeats)


def vmap_rate(d: dict, compiled: bool, m: int, repeats: int) -> tuple[tuple[float, float], float]:
    """(:func:`_rate`'s pair, seconds compiling) of the stacked-models loop a PyTorch user would write."""
    from torch import nn
    from torch.func import functional_call, stack_module_state, vmap

    sizes, B = d["sizes"], d["batch"]
    act = {"relu": nn.ReLU, "tanh": nn.Tanh, "silu": nn.SiLU, "sigmoid": nn.Sigmoid}[d["activation"]]
    torch.manual_seed(0)

    def net():
        layers = []
        for k, (i, o) in enumerate(zip(sizes[:-1], sizes[1:])):
            layers += [nn.Linear(i, o)] + ([act()] if k < len(sizes) - 2 else [])
        return nn.Sequential(*layers).double()

    models = [net() for _ in range(R)]
    params, _ = stack_module_state(models)
    base = copy.deepcopy(models[0]).to("meta")

    def loss_of(params, xb, yb):
        out = vmap(lambda p, x: functional_call(base, (p,), (x,)))(params, xb)
        return (out - yb).square().mean(dim=(1, 2)).sum()

    h = d["hparams"]
    opt = torch.optim.Adam(params.values(), lr=h["lr"], betas=(h.get("beta1", 0.9), h.get("beta2", 0.999)))
    total = d["horizon"] / B  # steps in the run's budget
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: 0.5 * (1 + math.cos(math.pi * min(s / total, 1.0))))
    X, Y, order = _data(d, m)
    loss_fn = torch.compile(loss_of) if compiled else loss_of

    def stretch():
        for s in range(0, m, B):
            idx = order[:, s : s + B]
            loss = loss_fn(params, X[idx], Y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()

    t = time.perf_counter()
    stretch()  # compiles (and warms up) once
    compiling = time.perf_counter() - t
    return _rate(stretch, R * m, repeats), compiling if compiled else 0.0


def rows(quick: bool = False) -> list[str]:
    """Lines for selpres-bench: per design, presentations/s of each variant and native's ratio to it."""
    from selpres.native import KernelUnavailable

    reps, threads = (2 if quick else 3), torch.get_num_threads()
    lines = [
        f"mini-batch training, {R} replicas, the modern Adam designs: M presentations/s (median of {reps}), wall and "
        "CPU time of the calling thread; every variant at 1 thread (torch's and the kernel's), the kernel also at "
        f"{threads}; x = native at 1 thread / that, by wall (by CPU time)"
    ]
    torch.set_num_threads(1)
    try:
        for name in DESIGNS:
            d = design(name)
            m_native, m_slow = min(d["n"], 10_000 if quick else 20_000), (16 if quick else 32) * d["batch"]
            rates, note = {}, ""
            try:
                rates["native"] = engine_rate(d, True, m_native, reps, threads=1)
                if threads > 1:
                    rates[f"native, {threads} threads"] = engine_rate(d, True, m_native, reps, threads=threads)
            except KernelUnavailable as exc:
                note = f" (native kernel unavailable: {exc})"
            rates["torch engine"] = engine_rate(d, False, m_slow, reps)
            rates["vmap eager"] = vmap_rate(d, False, m_slow, reps)[0]
            try:
                rates["vmap compiled"], compiling = vmap_rate(d, True, m_slow, reps)
                note += f" (torch.compile took {compiling:.1f} s, not counted)"
            except Exception as exc:  # noqa: BLE001 - e.g. an inductor without a C++ compiler: say so, go on
                note += f" (torch.compile cannot run here: {' '.join(str(exc).split())[:160]})"
            shape = f"{'-'.join(map(str, d['sizes']))} {d['activation']}, batch {d['batch']}, lr {d['hparams']['lr']}"
            lines.append(f"  {name} ({shape}){note}:")
            base = rates.get("native")
            for label, (wall, cpu) in rates.items():
                cpu_text = f"{cpu / 1e6:8.3f}" if not label.startswith("native,") else "       -"
                ratio = ""
                if base and not label.startswith("native"):
                    ratio = f"  x{base[0] / wall:6.1f} (x{base[1] / cpu:.1f})"
                lines.append(f"    {label:<20} wall {wall / 1e6:8.3f}  cpu {cpu_text}{ratio}")
    finally:
        torch.set_num_threads(threads)
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="shorter stretches, 2 repeats")
    print("\n".join(rows(ap.parse_args(argv).quick)))


if __name__ == "__main__":
    main()
