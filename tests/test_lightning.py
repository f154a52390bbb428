"""A real Lightning Trainer presents exactly each stage's training set: 1 device in-process, and strategy="ddp" on
2 CPU processes (tests/lightning_app.py); without the callback Lightning cuts the stages and the sampler says so."""

from __future__ import annotations

import json
import warnings

import pytest

pytest.importorskip("lightning")

import lightning_app as app  # noqa: E402

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


def test_without_the_callback_lightning_cuts_every_later_stage_and_the_sampler_warns():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model, _ = app.fit(callback=False, devices=1, max_epochs=6)
    seen = [len(r["indices"][0]) for r in model.epochs]
    assert seen[2:] == [16] * 4  # Lightning's count from A1 (15 patterns: 2 batches of 8) for ever
    cut = [w for w in caught if issubclass(w.category, SelectivePresentationWarning)]
    assert len(cut) == 1 and "SelectivePresentationCallback" in str(cut[0].message)


def test_the_callback_refuses_a_trainer_that_would_not_recount():
    with pytest.raises(ValueError, match="reload_dataloaders_every_n_epochs=2"):
        app.fit(devices=1, reload_dataloaders_every_n_epochs=2)


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
