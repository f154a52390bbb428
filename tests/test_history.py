"""Issue 26: the history log a resume reads cannot run code, and an unreadable one never makes a crash loop.

Real planted pickle payloads (each shown to run under plain ``pickle.load``), real cut and garbled files, real
``python train.py`` re-runs of a job folder left as a killed job leaves it.
"""

from __future__ import annotations

import json
import os
import pickle

import pytest
import torch
from test_resume import newest_checkpoint

from selpres.engines.model import init_replica_params
from selpres.run.checkpoint import Checkpoints, Progress, dumps, encode, read

from conftest import cfg_of, numbers, online_engine, run_python

SIZES = (6, 3, 2)
JOB = ["schedule.epochs=[2,2,2,2,2]", "checkpoint.every=1", "data.heldout=300", "eval.heldout_curve=300"]


class Payload:
    """What an attacker plants: unpickling it makes a folder (a visible side effect of running code)."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return os.mkdir, (self.marker,)


def record(epoch: int) -> dict:
    return {"epoch": epoch, "presentations": 10 * (epoch + 1), "heldout_rms_nm": [0.5 / (epoch + 2), None]}


def engine_of(seeds=(0, 1)):
    return online_engine("torch", SIZES, init_replica_params(SIZES, list(seeds)), 0.15, 0.9, 1)


def make_legacy(folder, records, epoch: int, engine, extra: bytes = b"") -> None:
    """A folder as a selpres before issue 26 left it: history.pkl (one pickle a record) and a checkpoint of
    history_format "pickle" counting its bytes (``extra``: planted bytes inside that count)."""
    data = b"".join(pickle.dumps(r, protocol=pickle.HIGHEST_PROTOCOL) for r in records) + extra
    (folder / "history.pkl").write_bytes(data)
    state = {
        "config_hash": "h", "epoch": epoch, "presentations": 10 * epoch, "seconds": {}, "engine": engine.state_dict(),
        "diverged_at": [None, None], "history_bytes": len(data), "history_format": "pickle",
        "selection_presentations": 0, "orders": None,
    }  # fmt: skip
    (folder / "checkpoint.pt").write_bytes(dumps(state))


def test_the_payload_is_real(tmp_path):
    """The control: plain pickle.load (what selpres did) runs the planted payload."""
    marker = tmp_path / "ran"
    pickle.loads(pickle.dumps(Payload(marker)))
    assert marker.is_dir()


def test_a_payload_planted_in_an_old_history_is_never_run(tmp_path, caplog):
    marker = tmp_path / "ran"
    job = tmp_path / "job"
    job.mkdir()
    (job / "notes.txt").write_text("the user's")
    make_legacy(job, [record(-1), record(0)], 1, engine_of(), extra=pickle.dumps(Payload(marker)))
    with caplog.at_level("WARNING", logger="selpres"):
        back = Checkpoints(job, "h").resume(engine_of((5, 6)), 2)
    assert not marker.exists(), "the planted payload ran"
    assert back.epoch == 0 and back.history == []  # nothing of it resumed: a fresh start
    (line,) = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert "history.pkl its record 3 cannot be read" in line and "posix.mkdir" in line and "started afresh" in line
    names = sorted(p.name.split("-")[0] for p in job.iterdir())  # moved aside, not deleted; the user's file kept
    assert names == ["checkpoint.stale", "history.stale", "notes.txt"]
    assert back.stale_checkpoint and "checkpoint.stale-" in back.stale_checkpoint


def test_an_old_folder_resumes_its_history_read_safely_and_carries_on_in_jsonl(tmp_path):
    engine = engine_of()
    make_legacy(tmp_path, [record(-1), record(0), record(1)], 2, engine)
    ckpts = Checkpoints(tmp_path, "h")
    back = ckpts.resume(engine_of((5, 6)), 2)
    assert back.epoch == 2 and back.history == [record(-1), record(0), record(1)]
    back.history.append(record(2))
    back.epoch = 3
    ckpts.save(engine, back)  # every record goes to history.jsonl; the checkpoint says so
    assert read(tmp_path / "checkpoint.alt.pt")["history_format"] == "jsonl"
    lines = (tmp_path / "history.jsonl").read_bytes().splitlines()
    assert [json.loads(line)["epoch"] for line in lines] == [-1, 0, 1, 2]
    again = Checkpoints(tmp_path, "h")
    assert again.resume(engine, 2).history == [record(-1), record(0), record(1), record(2)]
    again.discard()
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # the old log went with the finished job


def _two_checkpoints(folder):
    """history.jsonl with 3 records; checkpoint.pt counts 2 of them (epoch 1), checkpoint.alt.pt 3 (epoch 2)."""
    engine, ckpts = engine_of(), Checkpoints(folder, "h")
    ckpts.save(engine, Progress([record(-1), record(0)], [None, None], epoch=1))
    ckpts.save(engine, Progress([record(-1), record(0), record(1)], [None, None], epoch=2))
    return engine


@pytest.mark.parametrize("extra", [5, 0])  # the third record cut mid-line, or whole lines lost
def test_a_cut_history_resumes_the_checkpoint_whose_records_are_whole(tmp_path, caplog, extra):
    engine = _two_checkpoints(tmp_path)
    path = tmp_path / "history.jsonl"
    first = len(encode([record(-1), record(0)]))
    os.truncate(path, first + extra)  # a disk that lost the file's tail
    with caplog.at_level("WARNING", logger="selpres"):
        back = Checkpoints(tmp_path, "h").resume(engine, 2)
    assert back.epoch == 1 and back.history == [record(-1), record(0)]
    (line,) = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert "cut short" in line and "resumed the checkpoint of epoch 1" in line
    assert path.stat().st_size == first  # cut back to what its checkpoint counts


@pytest.mark.parametrize(
    "damage, why",
    [
        (lambda p: os.truncate(p, 7), "cut short"),
        (lambda p: p.write_bytes(b"\x00" * 10 + p.read_bytes()[10:]), "its line 1 is not JSON"),
        (lambda p: p.write_bytes(b"[1,2]\n" * 40), "its record 1 is not a history record"),
        (lambda p: p.unlink(), "cannot be read"),
    ],
)
def test_a_history_no_checkpoint_can_use_is_one_line_and_a_fresh_start(tmp_path, caplog, damage, why):
    engine = _two_checkpoints(tmp_path)
    (tmp_path / "notes.txt").write_text("the user's")
    damage(tmp_path / "history.jsonl")
    with caplog.at_level("WARNING", logger="selpres"):
        back = Checkpoints(tmp_path, "h").resume(engine, 2)
    assert back.epoch == 0 and back.history == []
    (line,) = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert why in line and "started afresh" in line
    assert (tmp_path / "notes.txt").read_text() == "the user's"
    assert not Checkpoints.present(tmp_path) and len(list(tmp_path.glob("checkpoint.stale-*"))) == 2


# ----------------------------------------------------------------------------- a real job folder
@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    """An uninterrupted run's results."""
    out = tmp_path_factory.mktemp("straight")
    done = run_python("train.py", *JOB, f"hydra.run.dir={out}")
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads((out / "results.json").read_text())


def killed_job(folder, monkeypatch):
    """A job folder as a kill after its last checkpoint leaves it (checkpoints and history, no results)."""
    from selpres.run import job

    with monkeypatch.context() as m:
        m.setattr(Checkpoints, "discard", lambda self: None)
        job.run(cfg_of(*JOB), folder)
    for name in ("results.json", "weights.pt"):
        (folder / name).unlink()
    return read(newest_checkpoint(folder)[0])  # the newer of the two, whichever name holds it: 9 epochs done of 10


def as_legacy(folder, ck, extra: bytes = b"") -> None:
    """Rewrite a killed job's history as an older selpres wrote it (history.pkl, history_format pickle)."""
    records = [json.loads(line) for line in (folder / "history.jsonl").read_bytes()[: ck["history_bytes"]].splitlines()]
    data = b"".join(pickle.dumps(r, protocol=pickle.HIGHEST_PROTOCOL) for r in records) + extra
    (folder / "history.jsonl").unlink()
    (folder / "history.pkl").write_bytes(data)
    (folder / "checkpoint.pt").unlink()
    (folder / "checkpoint.alt.pt").write_bytes(dumps({**ck, "history_format": "pickle", "history_bytes": len(data)}))


def test_train_py_resumes_an_old_folder_bit_identical(tmp_path, monkeypatch, straight):
    job = tmp_path / "job"
    ck = killed_job(job, monkeypatch)
    as_legacy(job, ck)
    done = run_python("train.py", *JOB, f"hydra.run.dir={job}")
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"at epoch {ck['epoch']}" in done.stdout + done.stderr
    assert numbers(json.loads((job / "results.json").read_text())) == numbers(straight)
    assert not list(job.glob("history*")) and not list(job.glob("checkpoint*"))


def test_train_py_on_a_planted_or_cut_history_says_so_once_and_finishes(tmp_path, monkeypatch, straight):
    """The issue's case: a payload in a killed job's history.pkl ran on the next ``python train.py`` there, and a
    cut one made every re-run exit 1 with a traceback. Now: one line, a fresh start, the same numbers."""
    marker = tmp_path / "ran"
    for name, damage in [
        ("planted", lambda job, ck: as_legacy(job, ck, extra=pickle.dumps(Payload(marker)))),
        ("cut", lambda job, ck: os.truncate(job / "history.jsonl", 100)),
    ]:
        job = tmp_path / name
        damage(job, killed_job(job, monkeypatch))
        (job / "notes.txt").write_text("the user's")
        done = run_python("train.py", *JOB, f"hydra.run.dir={job}")
        assert done.returncode == 0, done.stderr[-2000:]
        assert not marker.exists(), "the planted payload ran"
        warned = [line for line in (done.stdout + done.stderr).splitlines() if "started afresh" in line]
        assert len(warned) == 1 and "Traceback" not in done.stderr, done.stdout + done.stderr
        assert numbers(json.loads((job / "results.json").read_text())) == numbers(straight)
        assert (job / "notes.txt").read_text() == "the user's" and len(list(job.glob("*.stale-*"))) >= 2


# ----------------------------------------------------------------------------- other read-backs (audit)
def test_a_checkpoint_of_this_hash_whose_engine_state_does_not_fit_is_set_aside(tmp_path, caplog):
    """A hand-edited checkpoint (this job's hash, another network's weights) crashed every re-run in
    load_state_dict; now one warning, the files aside, a fresh start on the engine's own initial weights."""
    Checkpoints(tmp_path, "h").save(engine_of(), Progress([record(-1), record(0)], [None, None], epoch=1))
    sizes = (6, 4, 2)
    other = online_engine("torch", sizes, init_replica_params(sizes, [0, 1]), 0.15, 0.9, 1)
    initial = [p.clone() for p in other.params()]
    with caplog.at_level("WARNING", logger="selpres"):
        back = Checkpoints(tmp_path, "h").resume(other, 2)
    assert back.epoch == 0 and back.history == []
    assert all(torch.equal(a, b) for a, b in zip(other.params(), initial))  # not half loaded
    (line,) = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert "engine state does not fit this job" in line and "started afresh" in line
    assert not Checkpoints.present(tmp_path) and len(list(tmp_path.glob("*.stale-*"))) == 2


def test_a_finished_results_json_that_lacks_its_summary_is_redone_not_a_crash(tmp_path, caplog):
    from selpres.run import job

    cfg, out = cfg_of("schedule.epochs=[1,1,1,1,1]"), tmp_path / "job"
    job.run(cfg, out)
    good = json.loads((out / "results.json").read_text())
    cut = {k: v for k, v in good.items() if k != "summary"}
    (out / "results.json").write_text(json.dumps(cut))
    with caplog.at_level("WARNING", logger="selpres"):
        job.run(cfg, out)  # was KeyError: 'summary' on every re-run
    assert "lacks what a finished job holds (KeyError: 'summary')" in caplog.text
    assert numbers(json.loads((out / "results.json").read_text())) == numbers(good)
