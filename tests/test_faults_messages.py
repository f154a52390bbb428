"""Issue 39.4: what selpres reads back or is given, when it cannot be used, is said in one line naming the file (or
key), what is wrong and what is allowed: a checkpoint or cache entry that torch's weights-only load refuses (torch's
own text is six lines of advice with terminal escape codes), an empty checkpoint, random bytes given as a ``.npz``
(numpy's advice to allow pickles is wrong here), a directory given as ``data.path`` or ``robot.path``."""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from test_faults import train


class Planted:
    """A class a weights-only load must refuse: loading it with pickle's full powers would run ``__setstate__``."""

    def __setstate__(self, state):
        Path(state["marker"]).write_text("ran")


def _planted(path: Path, marker: Path, **extra) -> None:
    p = Planted()
    p.__dict__["marker"] = str(marker)
    torch.save({**extra, "payload": p}, path)


ESC = re.compile(r"\x1b")


def one_line(text: str) -> str:
    """``text``, which must be a single line free of terminal escape codes."""
    assert "\n" not in text.strip() and not ESC.search(text), repr(text)
    return text.strip()


# ------------------------------------------------------------------------------------- checkpoints
@pytest.mark.parametrize("kind", ["planted", "empty", "cut"])
def test_a_checkpoint_torch_refuses_is_set_aside_in_one_line_and_the_job_runs(kind, tmp_path):
    """Through the job, as a user meets it: the warning names the file and what is wrong with it in one line, the
    file is moved aside (never loaded, nothing in it run), results.json names where it went, the job completes."""
    folder = tmp_path / "job"
    folder.mkdir()
    marker = tmp_path / "ran"
    bad = folder / "checkpoint.pt"
    if kind == "planted":
        _planted(bad, marker, config_hash="0123456789abcdef", epoch=3)
    elif kind == "empty":
        bad.write_bytes(b"")
    else:
        torch.save({"epoch": 3, "w": torch.zeros(1000)}, bad)
        bad.write_bytes(bad.read_bytes()[:2000])
    ran = train(folder)
    assert ran.code == 0, ran.err
    said = [ln for ln in (folder / "train.log").read_text().splitlines() if str(bad) in ln]
    (line,) = said
    line = one_line(line)
    expected = {
        "planted": f"cannot be read: it names {Planted.__module__}.Planted, which a weights-only load refuses",
        "empty": "cannot be read: it is empty (0 bytes)",
        "cut": "cannot be read: it is cut short or not a torch file (2,000 bytes)",
    }[kind]
    assert expected in line and "moved it to checkpoint.stale-" in line, line
    assert "weights_only" not in line and "Re-running" not in line  # none of torch's advice
    res = json.loads((folder / "results.json").read_text())
    assert res["status"] == "complete" and Path(res["stale_checkpoint"]).name.startswith("checkpoint.stale-")
    assert not marker.exists()


# -------------------------------------------------------------------------------------- the data cache
def test_a_cache_entry_torch_refuses_is_rebuilt_with_one_line(tmp_path, monkeypatch, caplog):
    from selpres.data import cache as C
    from selpres.data import task as T
    from selpres.run.specs import task_specs

    from conftest import cfg_of

    monkeypatch.setenv("SELPRES_DATA_CACHE", str(tmp_path / "cache"))
    T._task.cache_clear()
    specs = task_specs(cfg_of())
    assert T.load_task(*specs).info["cache"].startswith("stored")
    (entry,) = (tmp_path / "cache").glob("*.task.pt")
    marker = tmp_path / "ran"
    _planted(entry, marker)
    T._task.cache_clear()
    with caplog.at_level(logging.WARNING, logger="selpres"):
        task = T.load_task(*specs)
    T._task.cache_clear()
    assert task.info["cache"].startswith("stored") and not marker.exists()
    (line,) = [one_line(r.getMessage()) for r in caplog.records if str(entry) in r.getMessage()]
    assert f"cannot be read: it names {Planted.__module__}.Planted, which a weights-only load refuses" in line
    assert line.endswith("building the task again") and C.torch.load(entry, weights_only=True)["made_of"]


# ------------------------------------------------------------------------------------ data and robot files
def _npz_cases(tmp_path: Path) -> dict[str, tuple[Path, str, str]]:
    """name -> (file, where, what the line says)."""
    rng = np.random.default_rng(0)
    cases = {}
    (p := tmp_path / "random.npz").write_bytes(rng.bytes(3000))
    cases["random bytes"] = (p, "file", "is not a .npz: its first bytes are not a zip archive's")
    np.save(tmp_path / "array.npy", np.zeros(3))
    (p := tmp_path / "array.npz").write_bytes((tmp_path / "array.npy").read_bytes())
    cases["a .npy"] = (p, "file", "is a .npy array (np.save), not a .npz")
    (p := tmp_path / "empty.npz").write_bytes(b"")
    cases["empty"] = (p, "file", "is empty (0 bytes)")
    np.savez(p := tmp_path / "objects.npz", a=np.array([{"x": 1}], dtype=object), b=np.zeros(1))
    cases["objects"] = (p, "array 'a'", "holds Python objects (dtype object): a column holds numbers")
    (p := tmp_path / "cut.npz").write_bytes(b"PK\x03\x04" + rng.bytes(200))
    cases["cut zip"] = (p, "file", "not a readable .npz (BadZipFile")
    return cases


@pytest.mark.parametrize("case", ["random bytes", "a .npy", "empty", "objects", "cut zip"])
def test_a_npz_that_is_not_one_is_one_line_without_numpys_pickle_advice(case, tmp_path):
    from selpres.data.file import DataFileError, columns

    path, where, said = _npz_cases(tmp_path)[case]
    with pytest.raises(DataFileError) as e:
        columns(path)
    assert one_line(str(e.value)).startswith(f"{path}: {where}: {said}"), str(e.value)
    assert "allow_pickle" not in str(e.value) and "trust" not in str(e.value)


@pytest.mark.parametrize("key", ["data.path", "robot.path"])
def test_a_directory_given_as_a_file_is_named_a_directory_in_one_line(key, tmp_path):
    """Through ``python train.py`` (in this process): exit 2, one line, and nothing written."""
    given = tmp_path / "a-folder"
    given.mkdir()
    extra = (
        ["data=file", f"data.path={given}", "data.inputs=[a]", "data.outputs=[b]"]
        if key == "data.path"
        else ["robot=urdf", f"robot.path={given}"]
    )
    ran = train(tmp_path / "job", *extra)
    assert ran.code == 2 and len(ran.err) == 1, ran.err
    assert one_line(ran.err[0]) == f"error: {given}: file: is a directory, not a file ({key} must name a " + (
        "CSV or .npz file)" if key == "data.path" else "URDF file)"
    )
    assert not (tmp_path / "job").exists()


def test_a_data_file_that_cannot_be_read_is_a_data_file_error_not_a_failed_write(tmp_path, monkeypatch):
    """A file that vanishes (or turns unreadable) after its check: a read failure naming it, not the job's "cannot
    write" line."""
    from selpres.data import file as F

    path = tmp_path / "t.csv"
    path.write_text("a,b\n1,2\n")
    real = Path.read_bytes

    def vanish(self):
        if self == path:
            path.unlink()
        return real(self)

    monkeypatch.setattr(Path, "read_bytes", vanish)
    with pytest.raises(F.DataFileError, match=r"t.csv: file: cannot be read \(No such file or directory\)"):
        F.load_columns(path, ["a"])


def test_a_checkpoint_that_vanishes_between_the_check_and_the_read_is_absent(tmp_path, monkeypatch):
    """The newer of the pair removed after ``exists()`` said it was there: the other one is resumed, nothing is
    said to be moved aside."""
    from test_history import engine_of, record

    from selpres.run import checkpoint as K

    ckpts = K.Checkpoints(tmp_path, "h")
    for epoch in (1, 2):
        ckpts.save(engine_of(), K.Progress([record(e) for e in range(-1, epoch)], [None, None], epoch=epoch))
    newer = max(ckpts.paths, key=lambda p: K.read(p)["epoch"])
    real = K.read

    def vanishing(path):
        if path == newer and newer.exists():
            newer.unlink()
        return real(path)

    monkeypatch.setattr(K, "read", vanishing)
    progress = K.Checkpoints(tmp_path, "h").resume(engine_of(), 2)
    assert progress.epoch == 1 and progress.stale_checkpoint is None
    assert not list(tmp_path.glob("*stale*"))
