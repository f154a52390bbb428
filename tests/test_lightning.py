"""A real Lightning Trainer presents exactly each stage's training set: 1 device in-process, and strategy="ddp" on
2 CPU processes (tests/lightning_app.py); without the callback Lightning cuts the stages and the sampler says so."""

from __future__ import annotations

import json
import warnings

import pytest

pytest.importorskip("lightning")

import lightning_app as app  # noqa: E402
from torch.utils.data import DataLoader  # noqa: E402

from selpres.presentation.sampler import SelectivePresentationWarning  # noqa: E402

from conftest import REPO, run_python  # noqa: E402


def _expected(sampler) -> list[set[int]]:
    """Each epoch's training set A_i, from the schedule's sizes and the sampler's priority order."""
    order = sampler.order.tolist()
    return [set(order[:size]) for size, e in zip(app.SIZES, app.EPOCHS) for _ in range(e)]


def test_one_device_presents_each_stage_exactly():
    model, sampler = app.fit(devices=1)  # max_epochs left at Lightning's default: the callback caps it
    want = _expected(sampler)
    assert len(model.epochs) == sampler.num_epochs == len(want) == 6  # four stages
    for rec, subset in zip(model.epochs, want):
        (seen,) = rec["indices"]
        assert len(seen) == len(subset) and set(seen) == subset, rec["epoch"]
    assert sampler.presentations == sampler.schedule.presentations == sum(s * e for s, e in zip(app.SIZES, app.EPOCHS))


@pytest.mark.parametrize("max_epochs", [None, 6])
def test_without_the_callback_lightning_stops_with_one_message(max_epochs):
    """Lightning would cut every later stage to A1's batch count (and, without max_epochs, run past the schedule
    into an IndexError): the sampler refuses Lightning's first set_epoch, naming the callback."""
    with pytest.raises(RuntimeError, match=r"needs its callback: Trainer\(callbacks=\[SelectivePresentationCallback"):
        app.fit(callback=False, devices=1, max_epochs=max_epochs)


def test_limit_train_batches_is_named_as_the_cause():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model, sampler = app.fit(devices=1, limit_train_batches=2)
    mine = [str(w.message) for w in caught if issubclass(w.category, SelectivePresentationWarning)]
    assert len(mine) == 2, mine  # once for the cut epochs, once for the last
    assert mine[0].startswith("epoch 2 presented 16 of its 31 patterns: Trainer(limit_train_batches=2)")
    assert "SelectivePresentationCallback" not in mine[0]
    assert mine[1].startswith("epoch 5, the schedule's last, presented 16 of its 90")
    assert "limit_train_batches=2" in mine[1]
    assert sampler.presentations == sum(len(r["indices"][0]) for r in model.epochs) == 15 + 15 + 16 * 4


def test_the_callback_refuses_a_trainer_that_would_not_recount():
    with pytest.raises(ValueError, match="reload_dataloaders_every_n_epochs=2"):
        app.fit(devices=1, reload_dataloaders_every_n_epochs=2)


@pytest.mark.slow
def test_ddp_mid_epoch_checkpoints_resume_exactly(tmp_path):
    """strategy="ddp" on 2 CPU processes, ModelCheckpoint(every_n_train_steps=3): a fit resumed from a checkpoint
    inside epoch 4, or at its last batch, presents per epoch, with what came before the checkpoint, the
    uninterrupted fit's indices: the ranks' union is the epoch's, none twice beyond DistributedSampler's padding."""
    full = tmp_path / "full.json"
    args = ("--devices", "2", "--every", "3", "--ckpt-dir", str(tmp_path / "ckpt"))
    done = run_python(str(REPO / "tests" / "lightning_app.py"), str(full), *args, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    full = json.loads(full.read_text())["epochs"]
    # per rank 1, 1, 2, 4, 4, 6 batches: step 9 is epoch 4's first batch, step 12 its last
    for name in ("epoch=4-step=9.ckpt", "epoch=4-step=12.ckpt"):
        out = tmp_path / "resumed.json"
        resume = ("--devices", "2", "--resume", str(tmp_path / "ckpt" / name))
        done = run_python(str(REPO / "tests" / "lightning_app.py"), str(out), *resume, cwd=tmp_path)
        assert done.returncode == 0, done.stderr[-3000:]
        got = _resumed_epochs(full, json.loads(out.read_text())["epochs"], name, app.BATCH)
        assert got == [rec["indices"] for rec in full], name
        for ranks, size in zip(got, [s for s, e in zip(app.SIZES, app.EPOCHS) for _ in range(e)]):
            union = ranks[0] + ranks[1]
            assert len(set(union)) == size and len(union) == 2 * -(-size // 2)  # none twice but the padding


@pytest.mark.slow
def test_ddp_on_two_cpu_processes_presents_each_stage_exactly(tmp_path):
    """Lightning's own DDP launcher (strategy="ddp", devices=2): every epoch the ranks' batches together are the
    stage's training set (odd sizes padded by one repeated pattern, as DistributedSampler pads), with no crash at
    a stage change."""
    out = tmp_path / "epochs.json"
    done = run_python(str(REPO / "tests" / "lightning_app.py"), str(out), "--devices", "2", cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    got = json.loads(out.read_text())
    assert got["world"] == 2
    order = got["order"]
    want = [set(order[:size]) for size, e in zip(app.SIZES, app.EPOCHS) for _ in range(e)]
    assert len(got["epochs"]) == len(want) == 6
    for rec, subset in zip(got["epochs"], want):
        a, b = rec["indices"]
        assert len(a) == len(b) == -(-len(subset) // 2)  # equal shares
        assert set(a) | set(b) == subset and len(a) + len(b) - len(set(a) | set(b)) == len(subset) % 2


def test_loader_workers_are_not_a_repeated_epoch():
    """With workers Lightning builds a second iterator each epoch after a prefetch by the first; the callback tells
    the sampler, so no warning, and every epoch still presents exactly its training set."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", SelectivePresentationWarning)
        model, sampler = app.fit(devices=1, num_workers=2)
    for rec, subset in zip(model.epochs, _expected(sampler), strict=True):
        (seen,) = rec["indices"]
        assert len(seen) == len(subset) and set(seen) == subset


def _resumed_epochs(full: list, resumed: list, ckpt_name: str, per_step: int) -> list:
    """Each epoch's indices of the interrupted run, rank by rank: the uninterrupted run's first k batches of the
    checkpoint's epoch (k from the checkpoint's step), then what the resumed fit presented (from the next epoch when
    the checkpoint was at the epoch's last batch)."""
    epoch, step = (int(part.split("=")[1]) for part in ckpt_name.removesuffix(".ckpt").split("-"))
    batches = [-(-len(rec["indices"][0]) // per_step) for rec in full]
    k = step - sum(batches[:epoch])
    assert 0 < k <= batches[epoch], ckpt_name
    if k == batches[epoch]:
        return [rec["indices"] for rec in full[: epoch + 1]] + [rec["indices"] for rec in resumed]
    head = [ranks[: k * per_step] for ranks in full[epoch]["indices"]]
    first = [h + r for h, r in zip(head, resumed[0]["indices"])]
    return [rec["indices"] for rec in full[:epoch]] + [first] + [rec["indices"] for rec in resumed[1:]]


@pytest.mark.parametrize("loader, workers", [("DataLoader", 0), ("DataLoader", 2), ("StatefulDataLoader", 2)])
def test_a_mid_epoch_checkpoint_resumes_exactly(tmp_path, loader, workers):
    """ModelCheckpoint(every_n_train_steps=4) in a full fit (epochs of 2, 2, 4, 8, 8, 12 batches); fits resumed from
    checkpoints inside epochs 3 and 5 and at the last batches of epochs 2 and 3 (where Lightning itself would cut
    the larger next stage) present, with the batches trained before, exactly the full fit's epochs, in order."""
    from lightning.pytorch.callbacks import ModelCheckpoint

    kind = (
        DataLoader
        if loader == "DataLoader"
        else pytest.importorskip("torchdata.stateful_dataloader").StatefulDataLoader
    )
    ckpt = ModelCheckpoint(dirpath=tmp_path, every_n_train_steps=4, save_top_k=-1)
    full, _ = app.fit(loader=kind, num_workers=workers, devices=1, enable_checkpointing=True, callbacks_extra=[ckpt])
    for name in ("epoch=2-step=8.ckpt", "epoch=3-step=12.ckpt", "epoch=3-step=16.ckpt", "epoch=5-step=28.ckpt"):
        with warnings.catch_warnings():
            warnings.simplefilter("error", SelectivePresentationWarning)
            model, sampler = app.fit(loader=kind, num_workers=workers, devices=1, ckpt_path=str(tmp_path / name))
        got = _resumed_epochs(full.epochs, model.epochs, name, app.BATCH)
        assert got == [rec["indices"] for rec in full.epochs], name
        assert sampler.presentations == sampler.schedule.presentations


def test_a_resumed_fit_continues_the_schedule(tmp_path):
    """Stop after 3 epochs with a checkpoint, resume in a fresh sampler: epochs 3.. present their own sets."""
    from lightning.pytorch.callbacks import ModelCheckpoint

    ckpt = ModelCheckpoint(dirpath=tmp_path, save_last=True, every_n_epochs=1)
    app.fit(devices=1, max_epochs=3, enable_checkpointing=True, callbacks_extra=[ckpt])
    model, sampler = app.fit(devices=1, ckpt_path=str(tmp_path / "last.ckpt"))
    want = _expected(sampler)[3:]
    assert len(model.epochs) == len(want) == 3
    for rec, subset in zip(model.epochs, want):
        (seen,) = rec["indices"]
        assert len(seen) == len(subset) and set(seen) == subset, rec["epoch"]
