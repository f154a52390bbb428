"""Checkpoints: the history log a checkpoint names is exactly what a resume gets back."""

from __future__ import annotations

import torch

from selpres.engines.model import init_replica_params
from selpres.run.checkpoint import Checkpoints, Progress, encode

from conftest import online_engine

SIZES = (6, 3, 2)


def record(epoch: int) -> dict:
    return {"epoch": epoch, "presentations": 10 * (epoch + 1), "heldout_rms_nm": [0.5 / (epoch + 2), None]}


def test_records_appended_after_the_last_checkpoint_are_dropped_on_resume(tmp_path):
    """A kill between a save's history append and its checkpoint rename leaves extra records in history.jsonl;
    the resume must return the history of the checkpoint it read: nothing lost, nothing twice."""
    engine = online_engine("torch", SIZES, init_replica_params(SIZES, [0, 1]), 0.15, 0.9, 1)
    progress = Progress([record(-1), record(0), record(1)], [None, None], epoch=2, presentations=20)
    Checkpoints(tmp_path, "h").save(engine, progress)
    with open(tmp_path / "history.jsonl", "ab") as f:  # the next save's append, its checkpoint never renamed
        f.write(encode(record(e) for e in (2, 3)))

    resumed = Checkpoints(tmp_path, "h")
    back = resumed.resume(online_engine("torch", SIZES, init_replica_params(SIZES, [5, 6]), 0.15, 0.9, 1), 2)
    assert back.history == progress.history and (back.epoch, back.presentations) == (2, 20)

    back.history += [record(2), record(3), record(4)]  # training goes on from there: saved once each
    back.epoch = 5
    resumed.save(engine, back)
    again = Checkpoints(tmp_path, "h").resume(engine, 2)
    assert [r["epoch"] for r in again.history] == [-1, 0, 1, 2, 3, 4]


def test_the_engine_state_comes_back_exactly(tmp_path):
    engine = online_engine("torch", SIZES, init_replica_params(SIZES, [0, 1]), 0.15, 0.9, 1)
    Checkpoints(tmp_path, "h").save(engine, Progress([record(-1)], [None, None], epoch=1))
    other = online_engine("torch", SIZES, init_replica_params(SIZES, [7, 8]), 0.15, 0.9, 1)
    Checkpoints(tmp_path, "h").resume(other, 2)
    assert all(torch.equal(a, b) for a, b in zip(engine.params(), other.params()))


def test_saves_alternate_and_never_rename_over_a_file(tmp_path, monkeypatch):
    """Each save renames onto a name that is free at that moment (a rename over a file was slow on ext4),
    and the two names take turns, so the other always holds the newest checkpoint."""
    import os

    from selpres import storage

    real = os.replace
    targets = []

    def replace(src, dst):
        assert not os.path.exists(dst), f"renamed over {dst}"
        targets.append(os.path.basename(dst))
        real(src, dst)

    monkeypatch.setattr(storage.os, "replace", replace)
    engine = online_engine("torch", SIZES, init_replica_params(SIZES, [0, 1]), 0.15, 0.9, 1)
    ckpts, progress = Checkpoints(tmp_path, "h"), Progress([record(-1)], [None, None])
    for epoch in range(1, 5):
        progress.history.append(record(epoch - 1))
        progress.epoch = epoch
        ckpts.save(engine, progress)
    assert targets == ["checkpoint.pt", "checkpoint.alt.pt"] * 2
    assert Checkpoints(tmp_path, "h").resume(engine, 2).epoch == 4  # the newer of the two (alt)


def test_a_kill_while_the_older_checkpoint_is_replaced_resumes_from_the_newer(tmp_path):
    """Between freeing the older name and the rename onto it only the newer checkpoint exists: a resume
    takes it, and the history log is cut back to it. The next save goes to the free name, not over the
    checkpoint resumed from."""
    engine = online_engine("torch", SIZES, init_replica_params(SIZES, [0, 1]), 0.15, 0.9, 1)
    ckpts = Checkpoints(tmp_path, "h")
    ckpts.save(engine, Progress([record(-1), record(0)], [None, None], epoch=1))  # -> checkpoint.pt
    ckpts.save(engine, Progress([record(-1), record(0), record(1)], [None, None], epoch=2))  # -> .alt.pt
    (tmp_path / "checkpoint.pt").unlink()  # the third save freed the older name, then the job was killed
    with open(tmp_path / "history.jsonl", "ab") as f:  # after appending its records
        f.write(encode([record(2)]))
    resumed = Checkpoints(tmp_path, "h")
    back = resumed.resume(engine, 2)
    assert back.epoch == 2 and [r["epoch"] for r in back.history] == [-1, 0, 1]
    back.history.append(record(2))
    back.epoch = 3
    resumed.save(engine, back)
    assert (tmp_path / "checkpoint.pt").exists() and (tmp_path / "checkpoint.alt.pt").exists()
    assert Checkpoints(tmp_path, "h").resume(engine, 2).epoch == 3


def test_an_unreadable_partner_is_set_aside_and_ours_resumed(tmp_path):
    """A crash can leave the newer file empty (saves do not fsync): it is moved aside, named in the record,
    and the other checkpoint of this job resumed."""
    engine = online_engine("torch", SIZES, init_replica_params(SIZES, [0, 1]), 0.15, 0.9, 1)
    Checkpoints(tmp_path, "h").save(engine, Progress([record(-1), record(0)], [None, None], epoch=1))
    (tmp_path / "checkpoint.alt.pt").write_bytes(b"")
    back = Checkpoints(tmp_path, "h").resume(engine, 2)
    assert back.epoch == 1 and [r["epoch"] for r in back.history] == [-1, 0]
    (moved,) = tmp_path.glob("checkpoint.stale-*.alt.pt")
    assert back.stale_checkpoint == str(moved) and moved.read_bytes() == b""
    assert (tmp_path / "checkpoint.pt").exists() and (tmp_path / "history.jsonl").exists()


def test_a_checkpoint_of_another_config_beside_ours_sets_everything_aside(tmp_path):
    """The history log may then be the other job's: neither checkpoint is resumed and nothing is deleted."""
    from selpres.run.checkpoint import dumps

    engine = online_engine("torch", SIZES, init_replica_params(SIZES, [0, 1]), 0.15, 0.9, 1)
    Checkpoints(tmp_path, "h").save(engine, Progress([record(-1)], [None, None], epoch=1))
    (tmp_path / "checkpoint.alt.pt").write_bytes(dumps({"config_hash": "other", "epoch": 9}))
    back = Checkpoints(tmp_path, "h").resume(engine, 2)
    assert back.epoch == 0 and back.history == []
    (foreign,) = tmp_path.glob("checkpoint.stale-*.alt.pt")
    assert back.stale_checkpoint == str(foreign)
    names = sorted(p.name.split("-")[0] + "|" + p.suffix for p in tmp_path.iterdir())
    assert names == ["checkpoint.stale|.pt", "checkpoint.stale|.pt", "history.stale|.jsonl"]
    assert not Checkpoints.present(tmp_path)
