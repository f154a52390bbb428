"""Mid-epoch resume through torchdata's ``StatefulDataLoader`` in a real process group: run under
``torchrun --nproc_per_node=2 tests/resume_app.py DIR MODE`` (gloo, CPU), MODE one of

* ``stop``: every rank presents the whole schedule uninterrupted (``full``), then, with a fresh sampler and loader,
  stops in epoch STOP_EPOCH after STOP_BATCHES batches and saves its own loader state (``state-<rank>.pt``);
* ``resume``: every rank loads its own state into a fresh sampler and loader and continues with the natural loop.

for ``num_workers`` 0 and 2. Each rank writes what it presented, per epoch, to ``<mode>-<rank>.json``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import torch
import torch.distributed as dist
from torch.utils.data import TensorDataset
from torchdata.stateful_dataloader import StatefulDataLoader

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from selpres.presentation.sampler import SelectivePresentation  # noqa: E402

N, SIZES, EPOCHS, BATCH = 101, [0.1, 0.25, 0.5, 1.0], [2, 1, 2, 1], 4
STOP_EPOCH, STOP_BATCHES = 3, 5  # in A3 (51 patterns, 26 per rank): 20 of a rank's 26 handed out
WORKERS = (0, 2)


def make(workers: int):
    X = torch.rand(N, 4, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    sampler = SelectivePresentation(X, sizes=SIZES, epochs=EPOCHS, seed=5)
    loader = StatefulDataLoader(TensorDataset(torch.arange(N)), batch_size=BATCH, sampler=sampler, num_workers=workers)
    return sampler, loader


def main() -> None:
    out, mode = Path(sys.argv[1]), sys.argv[2]
    dist.init_process_group("gloo")
    rank = dist.get_rank()
    record = {}
    for workers in WORKERS:
        sampler, loader = make(workers)
        if mode == "stop":
            full = []
            for epoch in range(sampler.num_epochs):
                sampler.set_epoch(epoch)
                full.append([i for (b,) in loader for i in b.tolist()])
            sampler, loader = make(workers)  # the run that is interrupted
            seen = [[] for _ in full]
            for epoch in range(STOP_EPOCH + 1):
                sampler.set_epoch(epoch)
                for k, (b,) in enumerate(loader):
                    seen[epoch] += b.tolist()
                    if epoch == STOP_EPOCH and k + 1 == STOP_BATCHES:
                        break
            state = {"epoch": STOP_EPOCH, "loader": loader.state_dict()}
            torch.save(state, out / f"state-{workers}-{rank}.pt")
            record[workers] = {"full": full, "seen": seen, "counter": sampler.presentations}
        else:
            saved = torch.load(out / f"state-{workers}-{rank}.pt", weights_only=False)
            loader.load_state_dict(saved["loader"])
            seen = [[] for _ in range(sampler.num_epochs)]
            for epoch in range(saved["epoch"], sampler.num_epochs):
                sampler.set_epoch(epoch)
                for (b,) in loader:
                    seen[epoch] += b.tolist()
            record[workers] = {"seen": seen, "counter": sampler.presentations, "state": saved["loader"] is not None}
    (out / f"{mode}-{rank}.json").write_text(json.dumps(record))
    dist.destroy_process_group()


if __name__ == "__main__":
    main()
