"""The sampler's overhead in a DataLoader loop: SelectivePresentation against torch's RandomSampler, side by side.

    python -m selpres_bench.sampler [--quick] [--n 100000] [--batch 256]

Both samplers present all n patterns every epoch (a one-stage schedule, so the work is the same); an epoch is
``set_epoch`` plus a full pass of ``DataLoader(dataset, batch_size, sampler=...)`` with the batches touched, timed
in turn (the two samplers alternate within every repeat) and reported as medians and their ratio. Two datasets:
``TensorDataset`` (the DataLoader fetches pattern by pattern and collates: what most loops do) and a dataset
indexed by a whole batch at once (``__getitems__``: the leanest loop, where a sampler's cost shows most); and the
samplers alone (set_epoch and their n indices, no DataLoader), which is what the two differ in.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch
from torch.utils.data import DataLoader, RandomSampler, TensorDataset

from selpres.presentation.sampler import SelectivePresentation, shuffle_implementation

BUDGET = 1.05  # the bound: at most RandomSampler + 5 % per epoch


class BatchIndexed(torch.utils.data.Dataset):
    """X, Y fetched a batch at a time (the DataLoader calls ``__getitems__`` with the batch's indices)."""

    def __init__(self, X: torch.Tensor, Y: torch.Tensor):
        self.X, self.Y = X, Y

    def __len__(self) -> int:
        return self.X.shape[0]

    def __getitem__(self, i):
        return self.X[i], self.Y[i]

    def __getitems__(self, indices: list[int]):
        idx = torch.tensor(indices)
        return self.X[idx], self.Y[idx]


def _epoch(loader: DataLoader | None, sampler, epoch: int) -> int:
    if hasattr(sampler, "set_epoch"):
        sampler.set_epoch(epoch)
    if loader is None:  # the sampler alone: its indices, no DataLoader
        return sum(1 for _ in sampler)
    seen = 0
    for x, _ in loader:
        seen += x.shape[0]
    return seen


def bench_sampler(quick: bool = False, n: int = 100_000, batch: int = 256) -> bool:
    """Print one row per dataset kind; True when SelectivePresentation stays within ``BUDGET`` of RandomSampler."""
    g = torch.Generator().manual_seed(0)
    X, Y = torch.rand(n, 6, generator=g), torch.rand(n, 2, generator=g)
    repeats = 5 if quick else 15
    print(
        f"\nsampler in a DataLoader loop: n = {n:,}, batch {batch}, one epoch = set_epoch + a full pass "
        f"(medians of {repeats}, alternating, either first in turn; shuffles: {shuffle_implementation()})"
    )
    within = True
    for label, ds, collate in (
        ("TensorDataset", TensorDataset(X, Y), None),
        ("batch-indexed", BatchIndexed(X, Y), lambda b: b),
        ("sampler alone", TensorDataset(X, Y), None),
    ):
        samplers = {
            "RandomSampler": RandomSampler(ds, generator=torch.Generator().manual_seed(1)),
            "SelectivePresentation": SelectivePresentation(n=n, order="random", sizes=[1.0], epochs=[10_000], seed=1),
        }
        loaders = {
            k: None if label == "sampler alone" else DataLoader(ds, batch_size=batch, sampler=s, collate_fn=collate)
            for k, s in samplers.items()
        }
        times = {k: [] for k in samplers}
        for k in samplers:  # warm-up, and the check that both present n per epoch
            assert _epoch(loaders[k], samplers[k], 0) == n
        for r in range(repeats):
            for k in list(samplers)[:: 1 if r % 2 == 0 else -1]:  # each sampler first in every other repeat
                t = time.perf_counter()
                _epoch(loaders[k], samplers[k], r + 1)
                times[k].append(time.perf_counter() - t)
        med = {k: statistics.median(v) for k, v in times.items()}
        ratio = med["SelectivePresentation"] / med["RandomSampler"]
        best = min(times["SelectivePresentation"]) / min(times["RandomSampler"])  # the least disturbed epochs
        within &= ratio <= BUDGET or label == "sampler alone"  # the bound is on the loop
        print(
            f"sampler     {label:14s} ms/epoch: RandomSampler {med['RandomSampler'] * 1e3:8.2f}  "
            f"SelectivePresentation {med['SelectivePresentation'] * 1e3:8.2f}   x{ratio:.3f} "
            f"({'within' if ratio <= BUDGET else 'over'} the +{(BUDGET - 1) * 100:.0f} % budget; fastest epochs "
            f"x{best:.3f})",
            flush=True,
        )
    return within


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m selpres_bench.sampler", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--batch", type=int, default=256)
    a = ap.parse_args(argv)
    return 0 if bench_sampler(a.quick, a.n, a.batch) else 1


if __name__ == "__main__":
    raise SystemExit(main())
