"""Issue 18: one writer per job folder, sweep workers that stop with their sweep, and the last bad inputs.

Real second processes (a second ``python train.py``, a SIGKILLed sweep, a process holding the lock), real
data files at the edges of float64, real disk faults (RLIMIT_FSIZE: the kernel refuses the write).
"""

from __future__ import annotations

import json
import os
import re
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from test_outcomes import says

from selpres.run import outcomes
from selpres.run.checkpoint import Checkpoints

from conftest import REPO, cfg_of, compose, numbers

TINY = ["data.heldout=300", "eval.heldout_curve=300", "logging.progress=false"]


def _env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("HYDRA_FULL_ERROR",)}
    env["PYTHONPATH"] = str(REPO)
    env.update(extra)
    return env


def _train(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "train.py", *args],
        cwd=REPO,
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


def _wait_for(cond, timeout: float = 240, what: str = "") -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.1)


def _epochs_once_each(res: dict) -> None:
    """The curves hold the untrained network (-1) and every epoch of the schedule, once each, in order."""
    total = sum(res["schedule"]["epochs"]) + sum(1 for e in res["schedule"]["extra_presentations"] if e)
    assert [c["epoch"] for c in res["curves"]] == list(range(-1, total))


# ------------------------------------------------------------------------------------------- the lock
def test_lock_is_held_by_the_os_named_by_pid_and_freed_by_a_kill(tmp_path):
    from selpres.run.lock import LOCK, FolderBusy, FolderLock

    folder = tmp_path / "job"
    holder = subprocess.Popen(
        [sys.executable, "-c", f"from selpres.run.lock import FolderLock; FolderLock.take({str(folder)!r}); "
         "print('held', flush=True); import time; time.sleep(600)"],
        cwd=REPO, env=_env(), stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(FolderBusy, match=f"in use by process {holder.pid}"):
            FolderLock.take(folder)
        holder.send_signal(signal.SIGKILL)
        holder.wait(30)
        lock = FolderLock.take(folder)  # at once: the kernel dropped the dead holder's lock
        assert (folder / LOCK).read_text().strip() == str(os.getpid())
        lock.release()
        assert not (folder / LOCK).exists()
    finally:
        holder.kill()


@pytest.mark.slow
@pytest.mark.parametrize("kill", [False, True], ids=["no-kill", "sigkill"])
def test_two_processes_on_one_folder_history_once_each(tmp_path, kill):
    """The issue's race: the same command twice 0.3 s apart. Whichever takes the folder first runs, the other exits
    2 naming it (nothing touched; on a loaded machine the second may win); with both SIGKILLed mid-training, the
    command once more completes with every epoch once."""
    out = tmp_path / "D"
    args = [*TINY, "replicas=20", "engine=native", "checkpoint.every=1", "schedule.epochs=[30,30,30,30,400]",
            f"hydra.run.dir={out}"]  # fmt: skip
    first = _train(*args)
    time.sleep(0.3)
    second = _train(*args)
    _wait_for(lambda: Checkpoints.present(out) or first.poll() is not None, what="a checkpoint")
    if kill:
        first.send_signal(signal.SIGKILL)
        second.send_signal(signal.SIGKILL)
        first.wait(60), second.wait(60)
        again = _train(*args)
        again.wait(600)
        assert again.returncode == 0, again.stderr
    else:
        errs = {p.pid: p.communicate(timeout=600)[1] for p in (first, second)}
        ends = sorted(((p.returncode, p.pid) for p in (first, second)), key=lambda e: e[0] != 0)
        (won, winner), (lost, loser) = ends
        assert (won, lost) == (0, 2), (ends, errs)
        assert errs[loser].strip().splitlines() == [f"error: {out} is in use by process {winner} "
                                                    "(one writer per job folder); nothing was touched"]  # fmt: skip
    res = json.loads((out / "results.json").read_text())
    assert res["status"] == "complete"
    _epochs_once_each(res)
    assert not list(out.glob("checkpoint*")) and not (out / "history.jsonl").exists()


@pytest.mark.slow
def test_a_busy_job_in_a_sweep_is_skipped_and_the_others_run(tmp_path):
    from selpres.run.lock import FolderLock

    sweep = tmp_path / "sweep"
    busy = sweep / "data.heldout=300,eval.heldout_curve=300,schedule.epochs=[1,1,1,1,1],seed=1"
    lock = FolderLock.take(busy)  # this test process holds the folder of job seed=1
    record = {name: f"the holder's {name}\n".encode() for name in ("config.yaml", "hydra.yaml", "overrides.yaml")}
    (busy / ".hydra").mkdir()
    for name, data in record.items():
        (busy / ".hydra" / name).write_bytes(data)
    (busy / "train.log").write_text("the holder's log\n")
    try:
        p = _train("-m", f"hydra.sweep.dir={sweep}", *TINY, "schedule.epochs=[1,1,1,1,1]", "seed=0,1")
        _, err = p.communicate(timeout=600)
    finally:
        lock.release()
    assert p.returncode == 1 and "Traceback" not in err, err
    line = f"{busy} is in use by process {os.getpid()} (one writer per job folder); nothing was touched"
    assert line in err.splitlines(), err
    assert not (busy / "results.json").exists()
    assert {p.name: p.read_bytes() for p in (busy / ".hydra").iterdir()} == record  # the record is written once held
    assert sorted(p.name for p in busy.iterdir()) == [".hydra", "train.log"]  # (the lock file went with the lock)
    assert (busy / "train.log").read_text() == "the holder's log\n"  # the skipped job wrote nothing into it
    (done,) = [d for d in sweep.iterdir() if d.name.endswith("seed=0")]
    assert json.loads((done / "results.json").read_text())["status"] == "complete"


# --------------------------------------------------------------------------- a sweep whose parent dies
def _children(pid: int) -> set[int]:
    kids = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        kids |= {int(k) for k in (task / "children").read_text().split()}
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc")
def test_sweep_workers_stop_when_the_sweep_is_killed_and_the_rerun_matches(tmp_path):
    sweep = tmp_path / "sweep"
    job = [
        *TINY,
        "replicas=4",
        "engine=native",
        "threads=1",
        "checkpoint.every=1",
        "schedule.epochs=[30,30,30,30,3000]",
    ]
    cmd = ["-m", "hydra/launcher=local2", f"hydra.sweep.dir={sweep}", *job, "seed=0,1"]
    parent = _train(*cmd)
    _wait_for(lambda: sum(map(Checkpoints.present, sweep.glob("*/"))) == 2, what="both jobs' checkpoints")
    workers = _children(parent.pid)
    assert len(workers) >= 2  # two loky workers (and resource trackers)
    parent.send_signal(signal.SIGKILL)
    parent.wait(30)
    _wait_for(lambda: not any(_alive(w) for w in workers), timeout=60, what="the workers to stop")
    kept = sorted(sweep.glob("*/checkpoint*.pt"))
    assert len(kept) >= 2 and not list(sweep.glob("*/results.json"))
    logs = " ".join(p.read_text() for p in sweep.glob("*/train.log"))
    assert logs.count("the sweep that launched this job is gone") == 2
    said = re.findall(r"\] (the sweep that launched this job is gone .*)", logs)
    assert len(said) == 2 and all(says(outcomes.ORPHANED, line) for line in said), said  # the table's row
    again = _train(*cmd)
    _, err = again.communicate(timeout=900)
    assert again.returncode == 0, err
    from selpres.run.train import train

    for folder in sorted(d for d in sweep.iterdir() if d.is_dir()):
        res = json.loads((folder / "results.json").read_text())
        assert res["resumed_from_epoch"] is not None
        _epochs_once_each(res)
        if folder.name.endswith("seed=0"):  # one job against an uninterrupted run of it, in this process
            ref = train(compose(*job, "seed=0"), tmp_path / "ref")
            assert numbers(res) == json.loads(json.dumps(numbers(ref)))


# ----------------------------------------------------------------------------- edge data and configs
def _csv(path: Path, X: np.ndarray, Y: np.ndarray) -> Path:
    with open(path, "w") as f:
        f.write("a,b,y\n")
        for x, y in zip(X, Y):
            f.write(f"{float(x[0])!r},{float(x[1])!r},{float(y)!r}\n")
    return path


def _file_cfg(path: Path):
    return cfg_of(
        "data=file", f"data.path={path}", "data.inputs=[a,b]", "data.outputs=[y]", "topology.layers=2-5-1",
        "schedule=conventional", "schedule.sizes=[1.0]", "schedule.epochs=[1]", "data.heldout=0.2",
    )  # fmt: skip


@pytest.fixture
def table():
    rng = np.random.default_rng(0)
    X = rng.uniform(-1, 1, (400, 2))
    return X, np.sin(X).sum(1)


def test_a_range_float64_cannot_scale_is_refused_naming_file_column_and_line(tmp_path, table):
    from selpres.data.file import DataFileError
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    X, Y = table
    X1 = X.copy()
    X1[5, 0], X1[7, 0] = 1e308, -1e308  # rows 5 and 7: lines 7 and 9 (line 1 is the header)
    with pytest.raises(DataFileError, match=r"inputs\.csv: column 'a', line (7|9): .*cannot be scaled in float64"):
        prepare(resolve(_file_cfg(_csv(tmp_path / "inputs.csv", X1, Y))))
    Y2 = Y.copy()
    Y2[9] = 1e308  # a target: its squared errors in its own unit would overflow
    with pytest.raises(DataFileError, match=r"target\.csv: column 'y', line 11: 1e\+308: .*target column"):
        prepare(resolve(_file_cfg(_csv(tmp_path / "target.csv", X, Y2))))


def test_a_column_collapsed_by_an_outlier_is_named_and_recorded(tmp_path, table, caplog):
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    X, Y = table
    X3 = X.copy()
    X3[11, 1] = 1e6
    with caplog.at_level("WARNING", logger="selpres"):
        prob = prepare(resolve(_file_cfg(_csv(tmp_path / "outlier.csv", X3, Y))))
    (warning,) = prob.task.info["warnings"]
    assert "column 'b'" in warning and "line 13" in warning and "1000000.0" in warning
    assert warning in caplog.text
    assert prepare(resolve(_file_cfg(_csv(tmp_path / "ok.csv", X, Y)))).task.info["warnings"] == []


@pytest.mark.parametrize(
    "content, where",
    [(b"a,b\xff,y\n1,2,3\n", "line 1: byte 0xff"), (b"a,b,y\n1,2,3\n4,\xfe5,6\n", "line 3: byte 0xfe"),
     (bytes(range(256)) * 40, "line 1"), (b"a,b,y\n1,2\x00,3\n", "line 2: holds a NUL byte")],
    ids=["header", "body", "garbage", "nul"],
)  # fmt: skip
def test_a_file_that_is_not_utf8_text_is_one_short_line(tmp_path, content, where):
    from selpres.data.file import DataFileError, columns, load_columns

    path = tmp_path / "bad.csv"
    path.write_bytes(content)
    with pytest.raises(DataFileError) as e:
        columns(path)
        load_columns(path, ["a", "b", "y"])
    msg = str(e.value)
    assert where in msg and "\n" not in msg and len(msg) < 300  # the file's bytes are not in it


@pytest.mark.parametrize(
    "overrides, key",
    [
        (["replicas=1000000000"], "replicas"),
        (["schedule.epochs=[1000000000,30,30,30,30]"], "schedule.epochs"),
        (["schedule=matched", "schedule.budget=1000000000000000"], "schedule.budget"),
        (["replicas=100000"], "replicas"),  # on a machine with 4 GB available (SELPRES_MEMORY_LIMIT)
    ],
)
def test_work_that_cannot_fit_is_refused_from_the_estimate(overrides, key, monkeypatch):
    from selpres.errors import ConfigError
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    monkeypatch.setenv("SELPRES_MEMORY_LIMIT", "4e9")
    with pytest.raises(ConfigError) as e:
        prepare(resolve(compose(*overrides)))
    assert e.value.key == key
    assert "needs an estimated" in str(e.value) and "4.0 GB available (SELPRES_MEMORY_LIMIT)" in str(e.value)


def test_the_estimate_allows_the_paper_and_matches_a_measured_peak():
    """The default job fits; R = 100,000 of 5 epochs measured 8.58 GB peak RSS here (module docstring):
    the estimate is within 25 % of that."""
    from selpres.run.estimate import estimate

    est = estimate(100_000, (6, 13, 2), 1002, 5, 2352, 10_000)
    assert 0.75 * 8.58e9 < est.total < 1.25 * 8.58e9
    assert estimate(1, (6, 13, 2), 1002, 150, 70_560, 10_000).total < 1e8


def test_a_huge_plan_is_never_materialised():
    from selpres.presentation.schedule import EpochPlan, Plan, build_schedule

    s = build_schedule([1002], None, 1002, 10**15)
    plan = s.plan()
    assert len(plan) == 10**15 // 1002 + 1
    assert plan[-1] == EpochPlan(len(plan) - 1, 0, 1002, 10**15 % 1002)
    assert plan[len(plan) - 5 :][0].index == len(plan) - 5 and len(plan[len(plan) - 5 :]) == 5
    small = build_schedule([50, 100], [2, 3], 100)
    assert small.plan() == tuple(Plan(small.stages))  # a short plan is the tuple it always was
    assert list(Plan(small.stages)[3:]) == [EpochPlan(3, 1, 100, 100), EpochPlan(4, 1, 100, 100)]
    assert list(small.plan()) == [EpochPlan(0, 0, 50, 50), EpochPlan(1, 0, 50, 50)] + [
        EpochPlan(i, 1, 100, 100) for i in (2, 3, 4)
    ]
    assert list(small.plan()[3:]) == [EpochPlan(3, 1, 100, 100), EpochPlan(4, 1, 100, 100)]


def test_a_seed_beyond_64_bits_is_a_config_error(tmp_path):
    from selpres.errors import ConfigError
    from selpres.run.train import train

    with pytest.raises(ConfigError, match=r"seed=18446744073709551616 is not allowed: expected a whole number in"):
        train(compose("seed=18446744073709551616"), tmp_path / "job")  # before seed_everything
    assert not (tmp_path / "job" / "results.json").exists()


def test_final_scores_that_are_not_finite_make_the_replica_diverged():
    import torch

    from selpres.run.checkpoint import Progress
    from selpres.run.results import unscored

    progress = Progress.fresh(3)
    progress.epoch, progress.presentations = 7, 700
    v = torch.tensor([0.1, float("inf"), 0.2])
    final = {"heldout": {"nm": {"overall": v}, "scaled": {"overall": torch.tensor([0.1, 0.2, 0.3])}}}
    unscored(final, progress)
    assert progress.diverged_at[0] is None and progress.diverged_at[2] is None
    assert progress.diverged_at[1]["epoch"] == 7 and "not finite" in progress.diverged_at[1]["reason"]


# ----------------------------------------------------------------------------- the report goes on
@pytest.mark.parametrize(
    "content, why",
    [(os.urandom(3000), "unreadable"), (b'{"a": "\xff"}', "not UTF-8"), (b"[]", "a JSON list"),
     (b'{"status": "complete"}', "schedule is missing")],
    ids=["random", "non-utf8", "list", "bare-status"],
)  # fmt: skip
def test_a_bad_results_json_is_listed_unreadable(tmp_path, content, why):
    from selpres.report.jobs import load_jobs

    for name in ("schedule=selective", "schedule=conventional"):
        (tmp_path / name).mkdir()
    (tmp_path / "schedule=selective" / "results.json").write_bytes(content)
    (tmp_path / "schedule=conventional" / "results.json").write_text('{"status": "failed", "error": "x"}')
    jobs = {j.path.name: j for j in load_jobs(tmp_path)}
    bad = jobs["schedule=selective"]
    assert bad.status == "unreadable" and why in bad.error and bad.schedule == "selective"
    assert jobs["schedule=conventional"].status == "failed"


# ------------------------------------------------------------------------------- the very end
def test_a_kill_during_the_final_writes_is_cleaned_up_by_the_rerun(tmp_path, monkeypatch):
    """results.json is written before the checkpoint is removed: a kill between them leaves the checkpoint
    of a finished job, and a kill inside an atomic write leaves its temp file; the re-run removes both."""
    from selpres.run import job
    from selpres.run.checkpoint import Checkpoints

    out = tmp_path / "job"
    cfg = cfg_of("schedule.epochs=[2,2,2,2,2]", "checkpoint.every=1")
    monkeypatch.setattr(Checkpoints, "discard", lambda self: None)  # killed before the checkpoint went
    job.run(cfg, out)
    monkeypatch.undo()
    (out / ".results.json.x1y2.tmp").write_bytes(b"half")
    (out / "notes.txt").write_text("the user's")
    assert Checkpoints.present(out) and (out / "history.jsonl").exists()  # either name of the pair holds one
    before = (out / "results.json").read_bytes()
    job.run(cfg, out)  # found done: skipped
    names = sorted(p.name for p in out.iterdir())
    assert [n for n in names if not n.startswith("events.out.tfevents.")] == ["notes.txt", "results.json", "weights.pt"]
    assert len(names) == 4  # and the job's one TensorBoard event file
    assert (out / "results.json").read_bytes() == before  # found done, not redone


# ------------------------------------------------------------------------------ disk faults, Ctrl-C
@pytest.mark.slow
def test_a_write_the_kernel_refuses_is_one_line_and_the_rerun_resumes(tmp_path):
    """RLIMIT_FSIZE (what a full disk does to a write, without root): the checkpoint that would exceed it
    fails with EFBIG; one line names the file, the last checkpoint stays, the re-run completes."""
    out = tmp_path / "D"
    args = [*TINY, "replicas=200", "checkpoint.every=1", "schedule.epochs=[10,10,10,10,10]",
            "logging.tensorboard=false", f"hydra.run.dir={out}"]  # fmt: skip

    def limit():  # a checkpoint (~0.4 MB at R = 200) fits, results.json (~1.5 MB: 51 curve records) does not
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write then fails with EFBIG instead of a signal
        resource.setrlimit(resource.RLIMIT_FSIZE, (600_000, 600_000))

    p = _train(*args, preexec_fn=limit)
    _, err = p.communicate(timeout=600)
    assert p.returncode == 2, err
    (line,) = err.strip().splitlines()
    assert says(outcomes.WRITE_FAILED, line)  # the table's row
    assert line.startswith(f"error: cannot write {out}/results.json: File too large (errno 27)")
    assert "the last checkpoint is kept" in line and "Traceback" not in err
    assert Checkpoints.present(out) and not list(out.glob(".*.tmp"))  # either name of the pair: the re-run resumes
    again = _train(*args)
    _, err = again.communicate(timeout=600)
    assert again.returncode == 0, err
    res = json.loads((out / "results.json").read_text())
    assert res["resumed_from_epoch"] is not None
    _epochs_once_each(res)


def resumable(folder: Path, line: str, *overrides: str) -> bool:
    """What the command named in ``line`` resumes from: the newest checkpoint in ``folder`` reads, is this
    config's, is of the epoch the line names (when it names one), and its history holds the records it counts."""
    from selpres.run.checkpoint import read
    from selpres.run.results import job_hash

    ckpts = [read(p) for p in folder.glob("checkpoint*.pt") if ".stale-" not in p.name]
    if not ckpts:
        return False
    newest = max(ckpts, key=lambda c: c["epoch"])
    named = re.search(r"after epoch (\d+)", line)
    return (
        newest["config_hash"] == job_hash(compose(*overrides))
        and (named is None or newest["epoch"] == int(named.group(1)))
        and (folder / "history.jsonl").stat().st_size >= newest["history_bytes"]
    )


@pytest.mark.slow
@pytest.mark.parametrize("delay", [0.5, 3.0])
def test_ctrl_c_during_set_up_leaves_a_folder_that_existed_as_it_was(tmp_path, delay):
    """The job is long (9000 epochs a stage: a minute or more) so it is still running when the Ctrl-C comes. The
    property, whatever the moment: exit 130 and one line; the user's file as it was; and either nothing of this run
    is left, or the folder resumes (a checkpoint of this config, under whichever of its two names a checkpoint
    being rewritten has at that moment: selpres.run.checkpoint's pair)."""
    out = tmp_path / "D"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    args = [*TINY, "replicas=20", "schedule.epochs=[9000,9000,9000,9000,9000]"]
    p = _train(*args, f"hydra.run.dir={out}", preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(delay)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130 and "Traceback" not in err, err
    (line,) = err.strip().splitlines()
    assert line.startswith("stopped by SIGINT "), line
    assert (out / "mine.txt").read_text() == "keep"
    left = sorted(q.name for q in out.iterdir())
    assert left == ["mine.txt"] or ("resume: " in line and resumable(out, line, *args)), (left, line)
