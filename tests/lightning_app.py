"""A real Lightning fit that records which patterns every epoch presented (imported by tests/test_lightning.py,
and run as ``python tests/lightning_app.py OUT.json --devices 2`` for ``strategy="ddp"`` on 2 CPU processes).

The dataset yields each pattern's index beside its input, so the module sees exactly what was presented; under
DDP the ranks' records are gathered at each epoch's end and rank 0 writes them."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import lightning.pytorch as pl
import torch
from torch.utils.data import DataLoader, TensorDataset

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))  # twolink, as the examples have it

from twolink import end_process_group  # noqa: E402

from selpres.presentation.lightning import SelectivePresentationCallback  # noqa: E402
from selpres.presentation.sampler import SelectivePresentation  # noqa: E402

N, SIZES, EPOCHS, BATCH = 90, [15, 31, 60, 90], [2, 1, 2, 1], 8  # odd sizes: DDP pads them to a multiple of 2


class Recorder(pl.LightningModule):
    """A linear model trained on (X -> sum X); training_step records the indices of every batch."""

    def __init__(self):
        super().__init__()
        self.net = torch.nn.Linear(3, 1)
        self.seen: list[int] = []
        self.epochs: list[dict] = []  # per epoch: {"epoch", "stage", "indices" of every rank}

    def training_step(self, batch, _):
        idx, x = batch
        self.seen += idx.tolist()
        return (self.net(x).squeeze(1) - x.sum(1)).square().mean()

    def on_train_epoch_end(self):
        mine = self.seen
        self.seen = []
        if torch.distributed.is_available() and torch.distributed.is_initialized():
            ranks = [None] * torch.distributed.get_world_size()
            torch.distributed.all_gather_object(ranks, mine)
        else:
            ranks = [mine]
        self.epochs.append({"epoch": self.current_epoch, "indices": ranks})

    def configure_optimizers(self):
        return torch.optim.SGD(self.parameters(), lr=0.01)


def data():
    X = torch.rand(N, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    return X, TensorDataset(torch.arange(N), X.float())


def fit(
    callback: bool = True,
    batch_size: int = BATCH,
    num_workers: int = 0,
    ckpt_path=None,
    callbacks_extra=(),
    loader=DataLoader,
    **trainer_kw,
) -> tuple[Recorder, SelectivePresentation]:
    X, ds = data()
    sampler = SelectivePresentation(X, sizes=SIZES, epochs=EPOCHS, seed=3)
    model = Recorder()
    trainer = pl.Trainer(
        accelerator="cpu",
        logger=False,
        enable_checkpointing=trainer_kw.pop("enable_checkpointing", False),
        enable_progress_bar=False,
        enable_model_summary=False,
        callbacks=([SelectivePresentationCallback(sampler)] if callback else []) + list(callbacks_extra),
        **trainer_kw,
    )
    loader = loader(ds, batch_size=batch_size, sampler=sampler, num_workers=num_workers)  # or torchdata's
    trainer.fit(model, loader, ckpt_path=ckpt_path)
    return model, sampler


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--devices", type=int, default=2)
    ap.add_argument("--every", type=int, default=0, help="ModelCheckpoint(every_n_train_steps) into --ckpt-dir")
    ap.add_argument("--ckpt-dir")
    ap.add_argument("--resume", help="a checkpoint to resume from")
    a = ap.parse_args()
    kw = {}
    if a.every:
        from lightning.pytorch.callbacks import ModelCheckpoint

        ckpt = ModelCheckpoint(dirpath=a.ckpt_dir, every_n_train_steps=a.every, save_top_k=-1)
        kw = {"enable_checkpointing": True, "callbacks_extra": [ckpt]}
    model, sampler = fit(devices=a.devices, strategy="ddp", ckpt_path=a.resume, **kw)
    if model.global_rank == 0:
        Path(a.out).write_text(
            json.dumps({"epochs": model.epochs, "order": sampler.order.tolist(), "world": sampler.num_replicas})
        )


if __name__ == "__main__":
    main()  # the fit's Trainer and model go with main's frame
    end_process_group()
