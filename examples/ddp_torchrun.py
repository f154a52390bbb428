"""Selective presentation under DistributedDataParallel (gloo, CPU): every rank trains on its own share of the
current training set A_i; the shares' union is A_i, and the ranks agree without communicating.

    selpres-export --out twolink
    torchrun --nproc_per_node=2 examples/ddp_torchrun.py --data twolink.npz
"""

import argparse

import torch
import torch.distributed as dist
from torch.nn.parallel import DistributedDataParallel
from torch.utils.data import DataLoader
from twolink import end_process_group, heldout_rms_nm, load, mlp

from selpres import SelectivePresentation


def main(a: argparse.Namespace) -> None:
    X, train, heldout, unscale = load(a.data)
    torch.manual_seed(0)
    model = DistributedDataParallel(mlp())
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)

    # num_replicas and rank come from the process group
    sampler = SelectivePresentation(X, sizes=[0.05, 0.1, 0.4, 0.8, 1.0], epochs=[a.epochs] * 5, seed=0)
    loader = DataLoader(train, batch_size=32, sampler=sampler)  # 32 per rank
    for epoch in range(sampler.num_epochs):
        sampler.set_epoch(epoch)
        for x, y in loader:
            opt.zero_grad()
            torch.nn.functional.mse_loss(model(x), y).backward()
            opt.step()
        if epoch in sampler.schedule.stage_ends() and dist.get_rank() == 0:
            print(
                f"stage {sampler.stage + 1}: {sampler.training_set.numel()} patterns, {len(sampler)} per rank, "
                f"{sampler.presentations:,} presentations so far ({sampler.rank_presentations:,} on rank 0), "
                f"held-out RMS {heldout_rms_nm(model.module, heldout, unscale):.4f} Nm"
            )


ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--data", default="twolink.npz")
ap.add_argument("--epochs", type=int, default=30, help="epochs per stage")
a = ap.parse_args()
dist.init_process_group("gloo")
main(a)
end_process_group()  # the model went with main(): the group's threads end while Python is alive (see twolink.py)
