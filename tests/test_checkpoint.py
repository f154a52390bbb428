"""Checkpoints: the history log a checkpoint names is exactly what a resume gets back."""

from __future__ import annotations

import pickle

import torch

from selpres.checkpoint import Checkpoints, Progress
from selpres.engine import make_engine
from selpres.model import init_replica_params

SIZES = (6, 3, 2)


def record(epoch: int) -> dict:
    return {"epoch": epoch, "presentations": 10 * (epoch + 1), "heldout_rms_nm": [0.5 / (epoch + 2), None]}


def test_records_appended_after_the_last_checkpoint_are_dropped_on_resume(tmp_path):
    """A kill between a save's history append and its checkpoint rename leaves extra records in history.pkl;
    the resume must return the history of the checkpoint it read: nothing lost, nothing twice."""
    engine = make_engine("torch", SIZES, init_replica_params(SIZES, [0, 1]), 0.15, 0.9, 1)
    progress = Progress([record(-1), record(0), record(1)], [None, None], epoch=2, presentations=20)
    Checkpoints(tmp_path, "h").save(engine, progress)
    with open(tmp_path / "history.pkl", "ab") as f:  # the next save's append, its checkpoint never renamed
        f.write(b"".join(pickle.dumps(record(e)) for e in (2, 3)))

    resumed = Checkpoints(tmp_path, "h")
    back = resumed.resume(make_engine("torch", SIZES, init_replica_params(SIZES, [5, 6]), 0.15, 0.9, 1), 2)
    assert back.history == progress.history and (back.epoch, back.presentations) == (2, 20)

    back.history += [record(2), record(3), record(4)]  # training goes on from there: saved once each
    back.epoch = 5
    resumed.save(engine, back)
    again = Checkpoints(tmp_path, "h").resume(engine, 2)
    assert [r["epoch"] for r in again.history] == [-1, 0, 1, 2, 3, 4]


def test_the_engine_state_comes_back_exactly(tmp_path):
    engine = make_engine("torch", SIZES, init_replica_params(SIZES, [0, 1]), 0.15, 0.9, 1)
    Checkpoints(tmp_path, "h").save(engine, Progress([record(-1)], [None, None], epoch=1))
    other = make_engine("torch", SIZES, init_replica_params(SIZES, [7, 8]), 0.15, 0.9, 1)
    Checkpoints(tmp_path, "h").resume(other, 2)
    assert all(torch.equal(a, b) for a, b in zip(engine.params(), other.params()))
