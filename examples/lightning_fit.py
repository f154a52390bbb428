"""Selective presentation in a Lightning Trainer (1 device, or --devices 2 --strategy ddp on CPU processes):
one callback makes Lightning recount every epoch, so each stage presents exactly its training set.

    selpres-export --out twolink
    python examples/lightning_fit.py --data twolink.npz [--devices 2 --strategy ddp]
"""

import argparse

import lightning.pytorch as pl
import torch
from torch.utils.data import DataLoader
from twolink import end_process_group, heldout_rms_nm, load, mlp

from selpres import SelectivePresentation, SelectivePresentationCallback


class Net(pl.LightningModule):
    def __init__(self):
        super().__init__()
        self.net = mlp()

    def training_step(self, batch, _):
        x, y = batch
        return torch.nn.functional.mse_loss(self.net(x), y)

    def configure_optimizers(self):
        return torch.optim.Adam(self.parameters(), lr=1e-3)


def main(a: argparse.Namespace) -> None:
    X, train, heldout, unscale = load(a.data)
    torch.manual_seed(0)
    sampler = SelectivePresentation(X, sizes=[0.05, 0.1, 0.4, 0.8, 1.0], epochs=[a.epochs] * 5, seed=0)
    loader = DataLoader(train, batch_size=32, sampler=sampler)
    trainer = pl.Trainer(
        accelerator="cpu",
        devices=a.devices,
        strategy=a.strategy,
        callbacks=[SelectivePresentationCallback(sampler)],
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
    )
    model = Net()
    trainer.fit(model, loader)
    if trainer.global_rank == 0:
        print(
            f"{sampler.num_epochs} epochs, {sampler.presentations:,} presentations "
            f"(the schedule's {sampler.schedule.presentations:,}), held-out RMS "
            f"{heldout_rms_nm(model.net, heldout, unscale):.4f} Nm"
        )


if __name__ == "__main__":  # Lightning's DDP launcher runs this file again in each process
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="twolink.npz")
    ap.add_argument("--epochs", type=int, default=30, help="epochs per stage")
    ap.add_argument("--devices", type=int, default=1)
    ap.add_argument("--strategy", default="auto")
    main(ap.parse_args())
    end_process_group()  # under DDP (Lightning leaves a gloo group to the interpreter's exit): see twolink.py
