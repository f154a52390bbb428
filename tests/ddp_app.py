"""Run under ``torchrun --nproc_per_node=2 tests/ddp_app.py OUT.json [--drop-last]`` (gloo, CPU): every rank builds
its sampler without num_replicas/rank (read from the process group), presents every epoch through a DataLoader,
and the ranks' shares, full epoch orders and counters are gathered; rank 0 writes them."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch
import torch.distributed as dist
from torch.utils.data import DataLoader, TensorDataset

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from selpres.presentation.sampler import SelectivePresentation  # noqa: E402

N, SIZES, EPOCHS = 101, [0.1, 0.25, 0.5, 1.0], [2, 1, 2, 1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--drop-last", action="store_true")
    a = ap.parse_args()
    X = torch.rand(N, 4, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    sampler = SelectivePresentation(X, sizes=SIZES, epochs=EPOCHS, seed=5, drop_last=a.drop_last)  # before the group
    dist.init_process_group("gloo")
    loader = DataLoader(TensorDataset(torch.arange(N)), batch_size=4, sampler=sampler)
    epochs = []
    for epoch in range(sampler.num_epochs):
        sampler.set_epoch(epoch)
        mine = torch.cat([b[0] for b in loader]).tolist()
        record = {
            "share": mine,
            "epoch_order": sampler.epoch_indices().tolist(),
            "training_set": sampler.training_set.tolist(),
            "rank_presentations": sampler.rank_presentations,
            "presentations": sampler.presentations,
            "len": len(sampler),
        }
        ranks = [None] * dist.get_world_size()
        dist.all_gather_object(ranks, record)
        epochs.append(ranks)
    if dist.get_rank() == 0:
        Path(a.out).write_text(json.dumps({"world": sampler.num_replicas, "epochs": epochs}))
    dist.destroy_process_group()


if __name__ == "__main__":
    main()
