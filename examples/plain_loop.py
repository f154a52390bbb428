"""Selective presentation in a plain PyTorch loop: ReLU 6-64-64-2, Adam, mini-batches of 32.

    selpres-export --out twolink                     # the paper's two-link data -> twolink.npz
    python examples/plain_loop.py --data twolink.npz

The change to a conventional loop is two lines (the sampler, and set_epoch), see README.md.
"""

import argparse

import torch
from torch.utils.data import DataLoader
from twolink import heldout_rms_nm, load, mlp

from selpres import SelectivePresentation

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--data", default="twolink.npz")
ap.add_argument("--epochs", type=int, default=30, help="epochs per stage")
a = ap.parse_args()

X, train, heldout, unscale = load(a.data)
torch.manual_seed(0)
model = mlp()
opt = torch.optim.Adam(model.parameters(), lr=1e-3)

sampler = SelectivePresentation(X, sizes=[0.05, 0.1, 0.4, 0.8, 1.0], epochs=[a.epochs] * 5, seed=0)
loader = DataLoader(train, batch_size=32, sampler=sampler)
for epoch in range(sampler.num_epochs):
    sampler.set_epoch(epoch)
    for x, y in loader:
        opt.zero_grad()
        torch.nn.functional.mse_loss(model(x), y).backward()
        opt.step()
    if epoch in sampler.schedule.stage_ends():
        rms = heldout_rms_nm(model, heldout, unscale)
        print(f"stage {sampler.stage + 1}: {sampler.training_set.numel()} patterns, ", end="")
        print(f"{sampler.presentations:,} presentations so far, held-out RMS {rms:.4f} Nm")
