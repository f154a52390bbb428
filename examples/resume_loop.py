"""Selective presentation in a plain loop that survives being killed mid-epoch, and resumes exactly.

    selpres-export --out twolink
    python examples/resume_loop.py --data twolink.npz --kill-in 5   # checkpoints, then SIGKILLs itself in epoch 5
    python examples/resume_loop.py --data twolink.npz               # the same command resumes where it died

The checkpoint holds the sampler's state (the epoch, the position in it, the count) beside the model's and the
optimiser's; the resumed run presents exactly the batches the uninterrupted one would have, so it ends on the same
weights (the last line is the same with or without the kill). With DataLoader workers, use torchdata's
StatefulDataLoader and save loader.state_dict() instead (it holds the sampler's, at the batch last yielded).
"""

import argparse
import hashlib
import os
import signal

import torch
from torch.utils.data import DataLoader
from twolink import heldout_rms_nm, load, mlp

from selpres import SelectivePresentation

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--data", default="twolink.npz")
ap.add_argument("--epochs", type=int, default=30, help="epochs per stage")
ap.add_argument("--ckpt", default="resume_loop.pt", help="the checkpoint (resumed from when it exists)")
ap.add_argument("--every", type=int, default=5, help="checkpoint every N batches")
ap.add_argument("--kill-in", type=int, default=-1, help="SIGKILL itself at the first checkpoint of this epoch")
a = ap.parse_args()

X, train, heldout, unscale = load(a.data)
torch.manual_seed(0)
model = mlp()
opt = torch.optim.Adam(model.parameters(), lr=1e-3)
sampler = SelectivePresentation(X, sizes=[0.05, 0.1, 0.4, 0.8, 1.0], epochs=[a.epochs] * 5, seed=0)
loader = DataLoader(train, batch_size=32, sampler=sampler)

start = 0
if os.path.exists(a.ckpt):
    ckpt = torch.load(a.ckpt)
    model.load_state_dict(ckpt["model"])
    opt.load_state_dict(ckpt["opt"])
    sampler.load_state_dict(ckpt["sampler"])
    start = ckpt["epoch"]
    print(f"resumed in epoch {start} at pattern {ckpt['sampler']['position']} of {len(sampler)}")

for epoch in range(start, sampler.num_epochs):
    sampler.set_epoch(epoch)  # the saved epoch keeps the saved position
    for k, (x, y) in enumerate(loader):
        opt.zero_grad()
        torch.nn.functional.mse_loss(model(x), y).backward()
        opt.step()
        if (k + 1) % a.every == 0:
            state = {
                "epoch": epoch,
                "sampler": sampler.state_dict(),
                "model": model.state_dict(),
                "opt": opt.state_dict(),
            }
            torch.save(state, a.ckpt + ".tmp")
            os.replace(a.ckpt + ".tmp", a.ckpt)  # a kill never leaves half a checkpoint
            if epoch == a.kill_in:
                print(f"killed in epoch {epoch} after pattern {sampler.state_dict()['position']}", flush=True)
                os.kill(os.getpid(), signal.SIGKILL)

weights = hashlib.sha256(b"".join(p.detach().numpy().tobytes() for p in model.parameters())).hexdigest()[:16]
rms = heldout_rms_nm(model, heldout, unscale)
print(f"{sampler.presentations:,} presentations, held-out RMS {rms:.6f} Nm, weights {weights}")
