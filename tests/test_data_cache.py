"""The on-disk task cache (selpres.data.cache): a hit is the task a build makes, bit for bit; anything the task
depends on changes the key; a bad entry, an unwritable folder or a file-based task never break a job."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest
import torch

import selpres.data.cache as C
import selpres.data.task as T
from selpres.run.specs import task_specs

from conftest import REPO, cfg_of, compose, numbers


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("SELPRES_DATA_CACHE", str(folder))
    T._task.cache_clear()  # the in-process cache would answer before the disk's
    yield folder
    T._task.cache_clear()


def _load(*overrides):
    T._task.cache_clear()
    cfg = compose(*overrides)
    return T.load_task(*task_specs(cfg))


def _same(a, b):
    pairs = [
        (a.exemplar.X, b.exemplar.X),
        (a.exemplar.Y, b.exemplar.Y),
        (a.tests.test10.X, b.tests.test10.X),
        (a.tests.test10.Y, b.tests.test10.Y),
        (a.tests.test10_from_exemplar, b.tests.test10_from_exemplar),
        (a.tests.heldout.X, b.tests.heldout.X),
        (a.tests.heldout.Y, b.tests.heldout.Y),
        (a.scaler.x_min, b.scaler.x_min),
        (a.scaler.y_max, b.scaler.y_max),
    ]
    assert all(x.dtype == y.dtype and torch.equal(x, y) for x, y in pairs)
    assert (a.scaler.lo, a.scaler.hi, a.input_names, a.output_names) == (
        b.scaler.lo,
        b.scaler.hi,
        b.input_names,
        b.output_names,
    )
    assert a.exemplar.n_candidates == b.exemplar.n_candidates and a.arm == b.arm
    strip = lambda info: {k: v for k, v in info.items() if k != "cache"}  # noqa: E731
    assert json.loads(json.dumps(strip(a.info))) == json.loads(json.dumps(strip(b.info)))


@pytest.mark.parametrize(
    "overrides",
    [
        ("data.heldout=500",),
        ("robot=planar3", "data=sampled", "data.n=300", "data.heldout=100", "topology.layers=9-5-3"),
    ],
)
def test_a_hit_is_the_task_a_build_makes(cache, monkeypatch, overrides):
    stored = _load(*overrides)
    assert stored.info["cache"].startswith("stored") and len(list(cache.glob("*.task.pt"))) == 1
    hit = _load(*overrides)
    assert hit.info["cache"].startswith("hit")
    monkeypatch.setenv("SELPRES_DATA_CACHE", "off")
    built = _load(*overrides)
    assert built.info["cache"].startswith("off")
    _same(hit, built)
    _same(stored, built)
    if stored.commanded is not None:
        assert all(torch.equal(x, y) for x, y in zip(hit.commanded, built.commanded))


def test_a_job_on_a_hit_has_the_numbers_of_a_job_that_built_its_data(cache, tmp_path, monkeypatch):
    from selpres.run.train import train

    args = ("schedule.epochs=[1,1,1,1,2]", "replicas=2")
    first = train(cfg_of(*args), tmp_path / "a")
    T._task.cache_clear()
    second = train(cfg_of(*args), tmp_path / "b")
    assert first["data"]["cache"].startswith("stored") and second["data"]["cache"].startswith("hit")
    monkeypatch.setenv("SELPRES_DATA_CACHE", "off")
    T._task.cache_clear()
    third = train(cfg_of(*args))
    assert numbers(first) == numbers(second) == numbers(third)


def test_what_the_task_depends_on_is_in_the_key(cache, monkeypatch):
    _load("data.heldout=300")
    assert _load("data.heldout=301").info["cache"].startswith("stored")  # another config
    assert _load("data.heldout=300", "robot.l1=0.45").info["cache"].startswith("stored")  # another arm
    monkeypatch.setattr(C, "code_digest", lambda: "edited source")  # what an edit to selpres/arms or data does
    assert _load("data.heldout=300").info["cache"].startswith("stored")
    assert len(list(cache.glob("*.task.pt"))) == 4


@pytest.mark.slow
def test_an_edit_to_the_code_that_builds_tasks_changes_the_digest_and_no_other_does(tmp_path):
    """On a copy of the package: a comment added to an arm's module or a data module changes the digest; one
    added to the training loop does not (its edits cannot change the data)."""
    shutil.copytree(REPO / "selpres", tmp_path / "selpres", ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    code = """
import sys; sys.path.insert(0, sys.argv[1])
from pathlib import Path
import selpres.data.cache as C
assert C.__file__.startswith(sys.argv[1]), C.__file__
def edit(rel):
    p = Path(sys.argv[1]) / "selpres" / rel
    p.write_text(p.read_text() + "\\n# an edit\\n")
    C.code_digest.cache_clear()
    return C.code_digest()
d0 = C.code_digest()
d1 = edit("run/train.py")
d2 = edit("arms/two_link.py")
d3 = edit("data/paper.py")
print(d0 == d1, d1 != d2, d2 != d3)
"""
    done = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["True", "True", "True"]


def test_a_cut_entry_is_built_again_and_replaced(cache, caplog):
    _load("data.heldout=300")
    (entry,) = cache.glob("*.task.pt")
    entry.write_bytes(entry.read_bytes()[:1000])
    again = _load("data.heldout=300")
    assert again.info["cache"].startswith("stored")
    assert "cannot be read" in caplog.text and str(entry) in caplog.text
    assert _load("data.heldout=300").info["cache"].startswith("hit")


def test_an_unwritable_cache_folder_does_not_stop_the_job(tmp_path, monkeypatch, caplog):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("SELPRES_DATA_CACHE", str(blocker / "cache"))
    task = _load("data.heldout=300")
    assert task.info["cache"].startswith(f"not written: {blocker / 'cache'}")
    assert "the job goes on without the cache" in caplog.text and blocker.read_text() == "not a folder"
    T._task.cache_clear()


def test_off_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("SELPRES_DATA_CACHE", "off")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert _load("data.heldout=300").info["cache"].startswith("off") and not list(tmp_path.iterdir())
    T._task.cache_clear()


def test_the_default_folder_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("SELPRES_DATA_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert C.cache_dir() == tmp_path / "selpres" / "tasks"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert C.cache_dir() == C.Path.home() / ".cache" / "selpres" / "tasks"


def test_files_named_from_home_are_read_again_when_edited(cache, tmp_path, monkeypatch):
    """``~/s.csv`` and ``~/arm.urdf`` (the readers expand ``~``): never stored, and an edit is seen, by the task
    and by the job's identity (selpres.run.results.job_hash)."""
    from test_datafile import INPUTS, OUTPUTS, file_cfg, sarcos_like, write_csv

    from selpres.arms.sources import make_arm
    from selpres.arms.urdf import to_urdf
    from selpres.run.results import job_hash
    from selpres.run.specs import robot_spec

    monkeypatch.setenv("HOME", str(tmp_path))
    cfg = file_cfg("'~/s.csv'")
    sums, hashes = [], []
    for seed in (0, 1):
        write_csv(tmp_path / "s.csv", sarcos_like(200, seed), INPUTS + OUTPUTS)
        T._task.cache_clear()
        task = T.load_task(*task_specs(cfg))
        sums.append(float(task.exemplar.X.sum()))
        hashes.append(job_hash(cfg))
        assert task.info["cache"].startswith("not stored")
    assert sums[0] != sums[1] and hashes[0] != hashes[1]
    urdf = compose("robot=urdf", "robot.path='~/arm.urdf'", "topology.layers=9-5-3", "data.n=200", "data.heldout=50")
    means = []
    for mass in (0.42, 0.84):
        arm = robot_spec(compose("robot=planar3", "topology.layers=9-5-3", f"robot.links.0.mass={mass}").robot)
        to_urdf(make_arm(arm), tmp_path / "arm.urdf")
        T._task.cache_clear()
        task = T.load_task(*task_specs(urdf))
        means.append(float(task.exemplar.Y.abs().mean()))
        assert task.info["cache"].startswith("not stored")
    assert means[0] != means[1] and not cache.exists()


def test_a_cache_that_cannot_record_a_hit_still_serves_it(cache, monkeypatch):
    """A read-only or shared cache: os.utime fails; the hit is served, the job goes on."""
    _load("data.heldout=300")

    def refuse(*a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(C.os, "utime", refuse)
    assert _load("data.heldout=300").info["cache"].startswith("hit")


def test_a_stored_task_holds_its_own_tensors_not_their_bases(cache):
    """torch.save writes a view's whole storage: the held-out set is a view of its draws."""
    task = _load("data.heldout=2000")
    (entry,) = cache.glob("*.task.pt")
    tensors = sum(v.numel() * v.element_size() for v in C._tensors(C._pack(task, {})))
    assert entry.stat().st_size < tensors + 64_000


def test_a_task_read_from_a_file_is_not_stored(cache, tmp_path):
    from test_datafile import INPUTS, OUTPUTS, file_cfg, sarcos_like, write_csv

    cfg = file_cfg(write_csv(tmp_path / "s.csv", sarcos_like(200), INPUTS + OUTPUTS))
    T._task.cache_clear()
    task = T.load_task(*task_specs(cfg))
    assert task.info["cache"].startswith("not stored") and not cache.exists()


def test_only_the_least_recently_used_entries_beyond_keep_are_removed(cache, monkeypatch):
    monkeypatch.setattr(C, "KEEP", 2)
    cache.mkdir()
    (cache / "notes.txt").write_text("mine")
    (cache / "my.task.pt").write_text("mine too: not named like an entry")
    old_temp, new_temp = cache / ".0123.task.pt.x1.tmp", cache / ".4567.task.pt.x2.tmp"
    old_temp.write_text("a killed write")
    new_temp.write_text("a write under way")
    os.utime(old_temp, (1, 1))
    for h in (300, 301, 302):
        _load(f"data.heldout={h}")
        for i, p in enumerate(sorted(cache.glob("*.task.pt"), key=lambda p: p.stat().st_mtime)):
            os.utime(p, (1000 + i, 1000 + i))  # mtimes in the order written, whatever the clock's resolution
    assert len(list(cache.glob("[0-9a-f]*.task.pt"))) == 2 and (cache / "notes.txt").read_text() == "mine"
    assert (cache / "my.task.pt").exists() and new_temp.exists() and not old_temp.exists()
    assert _load("data.heldout=300").info["cache"].startswith("stored")  # the oldest was the one removed


@pytest.mark.slow
def test_two_processes_building_one_task_at_once_both_get_it(cache):
    code = (
        "import json, os; from selpres.run.config import compose_train; import selpres.data.task as T; "
        "from selpres.run.specs import task_specs; "
        "c = compose_train(os.path.abspath('configs'), ['data.heldout=2000']); "
        "t = T.load_task(*task_specs(c)); "
        "print(json.dumps([t.info['cache'].split()[0], float(t.tests.heldout.X.sum())]))"
    )
    env = {**os.environ, "SELPRES_DATA_CACHE": str(cache)}
    procs = [subprocess.Popen([sys.executable, "-c", code], cwd=REPO, env=env, stdout=subprocess.PIPE, text=True)]
    procs.append(subprocess.Popen([sys.executable, "-c", code], cwd=REPO, env=env, stdout=subprocess.PIPE, text=True))
    outs = [json.loads(p.communicate(timeout=300)[0].strip().splitlines()[-1]) for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert outs[0][1] == outs[1][1] and {o[0] for o in outs} <= {"stored", "hit"}
    assert len(list(cache.glob("*.task.pt"))) == 1 and not list(cache.glob(".*.tmp"))


def test_a_copied_entry_of_other_configs_is_a_miss_said_once_and_the_numbers_are_right(cache, tmp_path, caplog):
    """Issue 26's case: an entry of data.test_seed=1 copied under the default config's name (a user syncing cache
    folders, or two keys colliding) was a hit with test_seed=1's numbers. Now: one warning, a build, and the
    numbers of a run that never saw the cache."""
    from selpres.run.train import train

    args = ("schedule.epochs=[1,1,1,1,2]", "replicas=2")
    T._task.cache_clear()
    first = train(cfg_of(*args), tmp_path / "a")  # the default config's entry
    (ours,) = cache.glob("*.task.pt")
    T._task.cache_clear()
    other = train(cfg_of(*args, "data.test_seed=1"), tmp_path / "b")
    (theirs,) = set(cache.glob("*.task.pt")) - {ours}
    shutil.copyfile(theirs, ours)
    T._task.cache_clear()
    with caplog.at_level("WARNING", logger="selpres"):
        copied = train(cfg_of(*args), tmp_path / "c")
    warned = [r.getMessage() for r in caplog.records if "data cache" in r.getMessage()]
    assert warned == [f"data cache: {ours} is not this job's entry (it holds the task of data.test_seed=1 (this job: "
                      "0)); building the task again"]  # fmt: skip
    assert copied["data"]["cache"].startswith("stored") and copied["data"]["hash"] == first["data"]["hash"]
    assert other["data"]["hash"] != first["data"]["hash"]  # the copy really was another task
    assert numbers(copied) == numbers(first) and numbers(copied) != numbers(other)
    T._task.cache_clear()
    assert train(cfg_of(*args), tmp_path / "d")["data"]["cache"].startswith("hit")  # replaced by the right one


def test_an_entry_built_by_other_code_is_a_miss(cache, monkeypatch, caplog):
    """The key holds the source digest; the entry holds it too, so a collision or a copy across versions is caught
    even where the names agree."""
    _load("data.heldout=300")
    (entry,) = cache.glob("*.task.pt")
    monkeypatch.setattr(C, "code_digest", lambda: "edited source")
    shutil.copyfile(entry, cache / (C.key(*_jsons("data.heldout=300")) + ".task.pt"))  # where this "code" looks
    assert _load("data.heldout=300").info["cache"].startswith("stored")
    assert "built by other source or library versions" in caplog.text


def _jsons(*overrides):
    """The (robot, data) texts a built-in arm's task is keyed by, as selpres.data.task.load_task writes them."""
    robot, data = task_specs(compose(*overrides))
    return (
        json.dumps({"_target_": robot.target, **robot.params}, sort_keys=True),
        json.dumps(data.as_dict(), sort_keys=True),
    )
