"""``python train.py``: a real run, skipping a finished job, and one-line config errors (subprocesses)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import gated_route
import pytest

from selpres.run.checkpoint import dumps

from conftest import REPO

pytestmark = pytest.mark.slow  # subprocesses: each pays for interpreter and torch start-up

TINY = ["schedule.epochs=[1,1,1,1,1]", "data.heldout=200", "eval.heldout_curve=200", "engine=fast"]
TIMEOUT = 180


def _env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("HYDRA_FULL_ERROR", "OC_CAUSE")}
    env["PYTHONWARNINGS"] = "ignore"
    return env


def _cmd(run_dir: Path, *overrides: str) -> list[str]:
    return [sys.executable, "train.py", *overrides, f"hydra.run.dir={run_dir}"]


def _run(run_dir: Path, *overrides: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        _cmd(run_dir, *overrides), cwd=REPO, env=_env(), capture_output=True, text=True, timeout=TIMEOUT
    )


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("cli") / "run"
    proc = _run(run_dir, *TINY)
    return proc, run_dir


def test_smoke_run_writes_results_tensorboard_and_summary(smoke):
    proc, run_dir = smoke
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "Traceback" not in out
    res = json.loads((run_dir / "results.json").read_text())
    assert res["status"] == "complete"
    # 50 + 100 + 400 + 800 + 1002 patterns, one epoch each
    assert res["presentations_done"] == 2352 == res["schedule"]["presentations"]
    assert res["schedule"]["sizes"] == [50, 100, 400, 800, 1002]
    trained = [c for c in res["curves"] if c["epoch"] >= 0]  # (epoch -1, if present, scores the initial weights)
    assert [c["size"] for c in trained] == [50, 100, 400, 800, 1002]
    assert [c["presentations"] for c in trained] == [50, 150, 550, 1350, 2352]
    assert res["summary"]["heldout_rms_nm_overall"]["mean"] > 0
    assert list(run_dir.glob("events.out.tfevents.*")), "no TensorBoard event files"  # run named by the job folder
    assert (run_dir / ".hydra" / "config.yaml").exists()
    assert not list(run_dir.glob("checkpoint*.pt"))  # removed once the job finished
    # the summary table and one progress line per stage
    for text in ("schedule", "cost T/t", "2,352", "held-out RMS", "test-10 RMS", str(run_dir / "results.json")):
        assert text in proc.stdout, text
    assert sum(line.startswith("stage ") for line in proc.stdout.splitlines()) == 5


def test_same_command_again_is_skipped(smoke):
    first, run_dir = smoke
    assert first.returncode == 0
    results = run_dir / "results.json"
    before = results.read_bytes(), results.stat().st_mtime_ns, (run_dir / "weights.pt").stat().st_mtime_ns
    events = sorted(run_dir.glob("events.out.tfevents.*"))
    proc = _run(run_dir, *TINY)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "already done" in proc.stdout
    assert "held-out RMS" in proc.stdout  # still shows the table
    assert not any(line.startswith("stage ") for line in proc.stdout.splitlines())  # did not train
    assert (results.read_bytes(), results.stat().st_mtime_ns, (run_dir / "weights.pt").stat().st_mtime_ns) == before
    assert sorted(run_dir.glob("events.out.tfevents.*")) == events


def test_summary_table_for_a_budget_below_one_epoch(smoke):
    """schedule=matched with a budget < n has no full epoch, only a partial one: the summary table must
    still render it (a crash there would turn a finished job into a 'failed' results.json)."""
    from selpres.presentation.schedule import build_schedule
    from selpres.run.cli import summary_table

    _, run_dir = smoke
    res = json.loads((run_dir / "results.json").read_text())
    res["schedule"] = {"name": "matched", "order": "stratified", **build_schedule([1.0], None, 1002, 500).describe()}
    text = summary_table(res)
    assert "500 presentations" in text and "ratio 1.000" in text


# (override, what the one line must say): every refusal, selpres's or Hydra's own, is one line and exit 2
BAD = [
    ("topology.layers=6-x-2", "topology.layers='6-x-2' is not allowed"),
    ("optim.lr=-1", "optim.lr=-1 is not allowed"),
    ("optim.momentum=1.5", "optim.momentum=1.5 is not allowed"),
    ("schedule.sizes=[100,50,1002]", "schedule.sizes"),
    ("schedule.epochs=[0,1,1,1,1]", "schedule.epochs"),
    ("data.theta.step=0.3", "data.theta"),  # 0..0.5 is not a whole number of 0.3 steps
    ("optim.lr=abc", "optim.lr='abc' is not allowed"),
    # Hydra's own refusals (before any job), 6-20 lines of its own: one line naming the key and what is allowed
    ("optim.lrr=1", "optim.lrr=1 is not allowed: optim.lrr is not a key; expected one of the keys of optim: "),
    ("foo=1", "foo=1 is not allowed: foo is not a key; expected one of the keys of the top level: checkpoint, data"),
    ("topology=6-99-2", "topology=6-99-2 is not allowed: expected one of 18-40-6, 6-13-2, 6-4-2,"),
    ("replicas=four", "replicas='four' is not allowed: expected a whole number"),
    ("engine=fastest", "engine='fastest' is not allowed: expected one of reference, fast, native, torch"),
    ("seed=[1", "cannot read the override 'seed=[1'"),
    ("~topology", "topology.layers has no value"),
    ("schedule.prune_ratio=0.3", "use schedule.pruning.prune_ratio=0.3"),  # a retired spelling
]


def test_bad_inputs_fail_cleanly(tmp_path):
    """Each bad input: exit 2, one line on stderr naming the key, the value and what is allowed, no traceback, no
    job folder left behind. The subprocesses run concurrently (each is mostly interpreter start-up)."""
    procs = []
    for i, (override, says) in enumerate(BAD):
        run_dir = tmp_path / f"bad{i}" / "run"
        p = subprocess.Popen(
            _cmd(run_dir, *TINY, override),
            cwd=REPO,
            env=_env(),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        procs.append((override, says, run_dir, p))
    failures = []
    deadline = time.monotonic() + TIMEOUT
    for override, says, run_dir, p in procs:
        try:
            stdout, stderr = p.communicate(timeout=max(1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            stdout, stderr = p.communicate()
            failures.append(f"{override}: hung")
            continue
        out = stdout + stderr
        problems = []
        if p.returncode != 2:
            problems.append(f"exit code {p.returncode}, expected 2")
        if "Traceback" in out:
            problems.append("traceback printed")
        if run_dir.exists():
            problems.append(f"left {sorted(f.name for f in run_dir.iterdir())} in the run dir")
        lines = stderr.strip().splitlines()
        if len(lines) != 1 or not lines[0].startswith("error: ") or says not in lines[0]:
            problems.append(f"not one line 'error: ...{says}...' on stderr")
        if problems:
            failures.append(f"{override}: {'; '.join(problems)}\n    output: {out.strip()[-400:]!r}")
    assert not failures, "\n".join(failures)


def test_overwrite_starts_afresh_instead_of_resuming_a_stale_checkpoint(tmp_path):
    run_dir = tmp_path / "run"
    assert _run(run_dir, *TINY).returncode == 0
    (run_dir / "checkpoint.pt").write_bytes(b"left over by an older, killed run")
    proc = _run(run_dir, *TINY, "overwrite=true")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "resuming" not in proc.stdout and sum(line.startswith("stage ") for line in proc.stdout.splitlines()) == 5
    assert not list(run_dir.glob("checkpoint*.pt"))


# ------------------------------------------------------------------ a refused run deletes nothing it did not create
def _user_folder(root: Path) -> dict:
    """A folder a user already had (a file and a subfolder), as a snapshot of paths and contents."""
    (root / "sub").mkdir(parents=True)
    (root / "notes.txt").write_text("my own notes")
    (root / "sub" / "data.csv").write_text("1,2,3\n")
    return _snapshot(root)


def _snapshot(root: Path) -> dict:
    return {p.relative_to(root).as_posix(): (p.read_bytes() if p.is_file() else "dir") for p in sorted(root.rglob("*"))}


@pytest.mark.parametrize(
    "override, code",
    [
        ("optim.lr=-1", 2),  # our ConfigError, raised inside the job after Hydra made .hydra/ and train.log
        ("schedule.sizes=[50,2000]", 2),  # refused against the exemplar set (needs the data first)
        ("optim.lrr=1", 2),  # Hydra's own error, before any job starts
    ],
)
def test_a_refused_run_into_an_existing_folder_leaves_it_exactly_as_it_was(tmp_path, override, code):
    folder = tmp_path / "mine"
    before = _user_folder(folder)
    proc = _run(folder, *TINY, override)
    assert proc.returncode == code, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    assert _snapshot(folder) == before  # the user's files intact, and no .hydra/ or train.log left behind


def test_a_refused_rerun_restores_the_record_of_the_finished_run(tmp_path):
    """A folder holding a finished job: a refused run in it restores Hydra's record and the log it appended to."""
    folder = tmp_path / "done"
    assert _run(folder, *TINY).returncode == 0
    before = _snapshot(folder)
    proc = _run(folder, *TINY, "optim.momentum=1.5")
    assert proc.returncode == 2 and "optim.momentum" in proc.stderr
    assert _snapshot(folder) == before


def test_a_failing_job_in_a_multirun_keeps_the_users_sweep_folder(tmp_path):
    sweep = tmp_path / "sweep"
    before = _user_folder(sweep)
    proc = subprocess.run(
        [sys.executable, "train.py", "-m", f"hydra.sweep.dir={sweep}", *TINY, "optim.lr=-1,0.15"],
        cwd=REPO,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert proc.returncode != 0
    after = _snapshot(sweep)
    assert {k: v for k, v in after.items() if k in before} == before
    assert sum(1 for k in after if k.endswith("/results.json")) == 2  # the failed job and the good one


def test_ctrl_c_during_set_up_keeps_the_users_folder(tmp_path):
    """SIGINT while the job makes its data (tests/gated_route.py holds it there until the signal is sent; a fixed
    delay after Hydra's record cannot promise where a process is): exit 130, no traceback, the folder as it was."""
    folder = tmp_path / "mine"
    before = _user_folder(folder)
    gate = tmp_path / "gate"
    env = _env() | gated_route.env(gate)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO / "tests"), env.get("PYTHONPATH")]))
    p = subprocess.Popen(
        _cmd(folder, *TINY, gated_route.OVERRIDE),
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # a background job (`cmd &` in a script) starts with SIGINT ignored, and Python then keeps ignoring
        # it: the job must see Ctrl-C as a terminal would deliver it, whoever runs the tests
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    gated_route.signal_when(p, gated_route.reached(gate), signal.SIGINT, gate, timeout=TIMEOUT)
    stdout, stderr = p.communicate(timeout=TIMEOUT)
    assert p.returncode == 130, stdout + stderr
    assert stderr.strip().splitlines() == [
        f"stopped by SIGINT during set-up: nothing of this run was kept ({folder} as it was)"
    ]
    assert _snapshot(folder) == before


# a Ctrl-C delivered from inside numpy's first import (a meta-path finder signals the process when numpy is looked up)
NUMPY_CTRL_C = """
import os, runpy, signal, sys
class CtrlC:
    def find_spec(self, name, path=None, target=None):
        if name == "numpy":
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, CtrlC())
sys.argv = sys.argv[1:]
runpy.run_path("train.py", run_name="__main__")
"""


def test_a_ctrl_c_inside_the_first_numpy_import_stops_the_job(tmp_path):
    """torch's C start-up imports numpy and clears an error raised inside that import: a Ctrl-C landing there
    was lost (the job ran to the end, exit 0) or left numpy half-imported (exit 1). The job imports numpy itself
    first (selpres.run.main), so the Ctrl-C is one line and exit 130, wherever numpy is first imported."""
    folder = tmp_path / "run"
    p = subprocess.run(
        [sys.executable, "-c", NUMPY_CTRL_C, *_cmd(folder, *TINY)[1:]],
        cwd=REPO,
        env={k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"},
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # as a terminal delivers it (see above)
    )
    assert p.returncode == 130, p.stdout + p.stderr
    assert p.stderr.strip().splitlines()[-1].startswith("stopped by SIGINT") and "Traceback" not in p.stderr, p.stderr
    assert not (folder / "results.json").exists()


# ------------------------------------------------------------------ a stale checkpoint is set aside, said and recorded
def test_a_checkpoint_of_another_config_is_moved_aside_with_a_warning(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "checkpoint.pt").write_bytes(dumps({"config_hash": "0123456789abcdef", "epoch": 3}))
    stale_bytes = (folder / "checkpoint.pt").read_bytes()
    proc = _run(folder, *TINY)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "belongs to another config" in proc.stdout and "resuming" not in proc.stdout
    (moved,) = folder.glob("checkpoint.stale-*.pt")
    assert moved.read_bytes() == stale_bytes
    res = json.loads((folder / "results.json").read_text())
    assert res["stale_checkpoint"] == str(moved) and res["resumed_from_epoch"] is None
    assert "belongs to another config" in (folder / "train.log").read_text()


# ------------------------------------------------------------------ what ran is what is recorded
def test_a_fallback_from_the_native_engine_is_said_and_recorded(tmp_path):
    folder = tmp_path / "run"
    env = {**_env(), "SELPRES_NO_NATIVE": "1"}
    proc = subprocess.run(_cmd(folder, *TINY), cwd=REPO, env=env, capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    res = json.loads((folder / "results.json").read_text())
    assert (res["engine"], res["engine_requested"]) == ("torch", "fast")
    assert "SELPRES_NO_NATIVE" in res["engine_fallback"]
    assert res["shuffle"] == "numpy (disabled by SELPRES_NO_NATIVE)"  # the shuffles fell back too, and say so
    assert res["evaluation"] == "torch (outputs from predict)"
    log = (folder / "train.log").read_text()
    assert "shuffles run in numpy" in log
    assert sum("SELPRES_NO_NATIVE" in line for line in (proc.stdout + proc.stderr).splitlines()) >= 1
    assert "SELPRES_NO_NATIVE" in log and "stage 5/5" in log  # Python logging reaches train.log
    assert "torch (requested fast" in proc.stdout  # the summary names the engine that ran
    # asking for the native engine where it cannot run is a user error, not a silent substitute
    bad = subprocess.run(
        _cmd(tmp_path / "native", *TINY[:-1], "engine=native"),
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert bad.returncode == 2 and bad.stderr.startswith("error: engine='native'"), bad.stderr
    assert not (tmp_path / "native").exists()


def test_the_job_log_holds_what_the_console_showed(smoke):
    proc, run_dir = smoke
    log = (run_dir / "train.log").read_text()
    assert "stage 5/5" in log and "held-out RMS" in log and "results:" in log


# ------------------------------------------------------------------ a finished job is replaced only when asked
def test_a_finished_job_of_another_config_is_refused_naming_the_keys_and_kept(smoke, tmp_path):
    """Issue 39's case: ``replicas=4`` then ``replicas=2`` into one folder replaced the finished job in silence. Now
    the second command is refused before any work, in one line naming the keys that differ (old -> new) and the
    two ways on; every file of the finished job stays byte for byte. ``overwrite=true`` replaces it."""
    _, done = smoke
    folder = tmp_path / "D"
    shutil.copytree(done, folder)
    before = _snapshot(folder)
    proc = _run(folder, *TINY, "replicas=2", "schedule.epochs=[1,1,1,1,2]")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f"error: {folder} holds a finished job of another config (replicas: 1 → 2, schedule.epochs: [1, 1, 1, 1, 1] "
        "→ [1, 1, 1, 1, 2]): overwrite=true replaces it, or give this one another folder (hydra.run.dir=...)"
    ]
    assert "stage " not in proc.stdout  # no work was done
    assert _snapshot(folder) == before
    again = _run(folder, *TINY, "replicas=2", "schedule.epochs=[1,1,1,1,2]", "overwrite=true")
    assert again.returncode == 0, again.stderr
    assert json.loads((folder / "results.json").read_text())["replicas"] == 2


def test_a_sweep_names_the_finished_jobs_of_another_config_and_runs_the_rest(smoke, tmp_path):
    """A sweep re-run after a default changed: the job whose folder holds a finished job of another config is
    refused by name and left as it is; the sweep's other jobs run; the sweep exits 1."""
    _, done = smoke
    sweep = tmp_path / "sweep"
    taken = sweep / "data.heldout=200,engine=fast,eval.heldout_curve=200,schedule.epochs=[1,1,1,1,1],seed=1"
    shutil.copytree(done, taken)  # a finished job of seed 0 in the folder of seed 1
    before = _snapshot(taken)
    proc = subprocess.run(
        [sys.executable, "train.py", "-m", f"hydra.sweep.dir={sweep}", *TINY, "seed=0,1"],
        cwd=REPO, env=_env(), capture_output=True, text=True, timeout=TIMEOUT,
    )  # fmt: skip
    assert proc.returncode == 1, proc.stdout + proc.stderr
    named = [line for line in proc.stderr.splitlines() if line.startswith(f"{taken} holds a finished job")]
    assert named and "(seed: 0 → 1)" in named[0] and "overwrite=true" in named[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert _snapshot(taken) == before
    (other,) = [d for d in sweep.iterdir() if d.name.endswith("seed=0")]
    assert json.loads((other / "results.json").read_text())["status"] == "complete"


def test_hydra_full_error_prints_hydras_whole_text_then_the_line(tmp_path):
    proc = subprocess.run(
        _cmd(tmp_path / "run", "optim.lrr=1"), cwd=REPO, env={**_env(), "HYDRA_FULL_ERROR": "1"},
        capture_output=True, text=True, timeout=TIMEOUT,
    )  # fmt: skip
    assert proc.returncode == 2
    assert "Traceback" in proc.stderr and "Key 'lrr' is not in struct" in proc.stderr
    assert proc.stderr.strip().splitlines()[-1].startswith("error: optim.lrr=1 is not allowed")
