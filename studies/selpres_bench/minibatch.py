"""Mini-batch training of many replicas, side by side in one run: the native kernel, the torch mini-batch engine, and
what a PyTorch user would write for many models at once (``torch.func.stack_module_state`` + ``vmap``, eager and
``torch.compile``d), the variants in turn round after round.

For each Adam design of ``experiment=modern`` (``configs/design/modern/<arm>_adam_conventional.yaml``: its topology,
n, units, rate, batch and cosine schedule; 12 replicas), every variant trains the same 12 replicas on random data
in the design's shapes (float64, each replica its own order). The row gives presentations per second (median of
the rounds) and the native kernel's ratio to each (median of the rounds' ratios). The kernel runs a whole epoch
per call, the others a stretch of mini-batches (their speed per mini-batch does not depend on how many). The vmap
variants are a user's code: one ``nn.Sequential`` per replica stacked, the forward pass vmapped over replicas, the
sum of the replicas' mse backpropagated, ``torch.optim.Adam`` on the stacked weights with a cosine ``LambdaLR``
(one step count for all replicas: no pruning here). The compiled one compiles that loss (forward and backward,
AOTAutograd); the step stays eager (a compiled step recompiles as the rate changes). Its first call, which
compiles, is timed apart and not counted. Every variant runs at one thread, so that they compare like with like
on this shared 2-core machine (the kernel also at torch's thread count). Target (issue 28): native >= 10x the
torch engine and ahead of both vmap variants. ``python -m selpres_bench.minibatch [--quick]``.
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
        rule=o._target_,
        hparams={k: o[k] for k in ("lr", "beta1", "beta2", "eps", "weight_decay") if o.get(k) is not None},
        batch=int(o.batch_size),
        activation=c.model.activation,
        schedule=o.lr_schedule,
        horizon=float(c.data.n * sum(c.schedule.epochs)),
    )


def _data(d: dict, m: int):
    g = torch.Generator().manual_seed(0)
    X = torch.rand(d["n"], d["sizes"][0], generator=g, dtype=torch.float64)
    Y = torch.rand(d["n"], d["sizes"][-1], generator=g, dtype=torch.float64)
    order = torch.stack([torch.randperm(d["n"], generator=g)[:m] for _ in range(R)])
    return X, Y, order


def engine_stretch(d: dict, native: bool, m: int, threads: int | None = None):
    """An epoch of ``m`` patterns per replica on the native kernel or the torch mini-batch engine (a callable)."""
    from selpres.engines.minibatch import MiniBatchEngine
    from selpres.engines.model import init_replica_params
    from selpres.engines.native_minibatch import NativeMiniBatchEngine

    X, Y, order = _data(d, m)
    params = init_replica_params(d["sizes"], list(range(R)))
    args = (d["sizes"], params, d["rule"], dict(d["hparams"]), d["batch"], d["activation"], d["schedule"])
    eng = (
        NativeMiniBatchEngine(*args, d["horizon"], threads=threads) if native else MiniBatchEngine(*args, d["horizon"])
    )
    return lambda: eng.train_epoch(X, Y, order)


def vmap_stretch(d: dict, compiled: bool, m: int):
    """(a callable training ``m`` patterns per replica, seconds its first call took): the stacked-models loop a
    PyTorch user would write; the first call compiles (and warms up)."""
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
    stretch()
    return stretch, time.perf_counter() - t


def measure(variants: dict, rounds: int) -> dict[str, list[tuple[float, float]]]:
    """Per variant ``(callable, presentations)``, per round (the variants in turn, so that a busy machine slows all
    alike) its presentations per second: (wall, CPU time of the calling thread). On a shared machine CPU time is
    the steadier figure: it leaves out the time the thread waited for a core (at one thread every variant runs in
    the calling thread)."""
    out = {k: [] for k in variants}
    for fn, _ in variants.values():
        fn()  # warm: the first epoch of an engine, the caches
    for _ in range(rounds):
        for name, (fn, presentations) in variants.items():
            t, c = time.perf_counter(), time.thread_time()
            fn()
            cpu, wall = time.thread_time() - c, time.perf_counter() - t
            out[name].append((presentations / wall, presentations / max(cpu, 1e-9)))
    return out


def rows(quick: bool = False) -> list[str]:
    """Lines for selpres-bench: per design, presentations/s of each variant and native's ratio to it."""
    from selpres.native import KernelUnavailable

    rounds, threads = (3 if quick else 5), torch.get_num_threads()
    lines = [
        f"mini-batch training, {R} replicas, the modern Adam designs: M presentations/s, median of {rounds} rounds "
        "(each round every variant in turn), by wall and by CPU time of the calling thread; every variant at 1 thread "
        f"(torch's and the kernel's), the kernel also at {threads} (wall only); x = native / that, the median of the "
        "rounds' ratios, by wall (by CPU time)"
    ]
    torch.set_num_threads(1)
    try:
        for name in DESIGNS:
            d = design(name)
            m_native, m_slow = min(d["n"], 10_000 if quick else 20_000), (16 if quick else 32) * d["batch"]
            variants, note = {}, ""
            try:
                variants["native"] = (engine_stretch(d, True, m_native, threads=1), R * m_native)
                if threads > 1:
                    variants[f"native, {threads} threads"] = (engine_stretch(d, True, m_native, threads), R * m_native)
            except KernelUnavailable as exc:
                note = f" (native kernel unavailable: {exc})"
            variants["torch engine"] = (engine_stretch(d, False, m_slow), R * m_slow)
            variants["vmap eager"] = (vmap_stretch(d, False, m_slow)[0], R * m_slow)
            try:
                fn, compiling = vmap_stretch(d, True, m_slow)
                variants["vmap compiled"] = (fn, R * m_slow)
                note += f" (torch.compile's first call took {compiling:.1f} s, not counted)"
            except Exception as exc:  # noqa: BLE001 - e.g. an inductor without a C++ compiler: say so, go on
                note += f" (torch.compile cannot run here: {' '.join(str(exc).split())[:160]})"
            rates = measure(variants, rounds)
            shape = f"{'-'.join(map(str, d['sizes']))} {d['activation']}, batch {d['batch']}, lr {d['hparams']['lr']}"
            lines.append(f"  {name} ({shape}){note}:")
            for label, per_round in rates.items():
                wall, cpu = (statistics.median(r[k] for r in per_round) for k in (0, 1))
                cpu_text = f"{cpu / 1e6:8.3f}" if not label.startswith("native,") else "       -"
                ratio = ""
                if "native" in rates and not label.startswith("native"):
                    by = [statistics.median(n[k] / r[k] for n, r in zip(rates["native"], per_round)) for k in (0, 1)]
                    ratio = f"  x{by[0]:6.1f} (x{by[1]:.1f})"
                lines.append(f"    {label:<20} wall {wall / 1e6:8.3f}  cpu {cpu_text}{ratio}")
    finally:
        torch.set_num_threads(threads)
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="shorter stretches, 3 rounds")
    print("\n".join(rows(ap.parse_args(argv).quick)))


if __name__ == "__main__":
    main()
