"""Issue 39: real disk faults on whole ``python train.py`` processes, no layer in between (tests/test_faults.py holds
the layer that reaches every write site in-process).

* A real full disk: the job folder on a small tmpfs that fills while ``weights.pt`` is written, the data cache on a
  tmpfs too small for its entry (the issue's two reproductions), then remounted read-only; mounted in a mount
  namespace of the test's own (``unshare -m``: nothing outside the test sees them, and they go when it ends).
  Skipped, with the reason, where this machine allows no such mount (no ``unshare``, no CAP_SYS_ADMIN).
* A real file-size limit (RLIMIT_FSIZE, which needs no privilege) that only the data cache's entry exceeds.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from test_faults import JOB, newest_epoch, train, whole

from conftest import REPO, numbers

pytestmark = pytest.mark.slow


def _env(**extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
    env["PYTHONPATH"] = str(REPO)
    env.update(extra)
    return env


def _mount_refused(where: Path) -> str | None:
    """Why this process cannot mount a tmpfs in a mount namespace of its own (None: it can)."""
    if shutil.which("unshare") is None:
        return "no unshare(1) here"
    probe = where / "probe"
    probe.mkdir()
    done = subprocess.run(
        ["unshare", "-m", "--propagation", "private", "sh", "-c", f"mount -t tmpfs -o size=64k tmpfs {probe}"],
        capture_output=True,
        text=True,
    )
    return None if done.returncode == 0 else f"cannot mount a tmpfs here: {done.stderr.strip() or done.returncode}"


_SCRIPT = r"""
set -u
M=$1; JOB_KB=$2; shift 2
mkdir -p "$M/disk" "$M/cache"
mount -t tmpfs -o size=${JOB_KB}k tmpfs "$M/disk" || exit 90
mount -t tmpfs -o size=64k tmpfs "$M/cache" || exit 90
export SELPRES_DATA_CACHE="$M/cache"
run() {  # the same command each time
    "$PY" train.py "$@" hydra.run.dir="$M/disk/job" >"$M/$RUN.out" 2>"$M/$RUN.err"; echo $? >"$M/$RUN.rc"
}
RUN=first run "$@"
cp -a "$M/disk/job" "$M/after"            # the folder as the full disk left it
ls -A "$M/cache" >"$M/cache.ls"
mount -o remount,size=65536k "$M/disk"    # room again
mount -o remount,ro "$M/cache"             # and the cache's disk now read-only
RUN=second run "$@"
cp -a "$M/disk/job" "$M/final"
"""


def test_a_real_full_disk_while_weights_are_written_and_a_cache_too_small_for_its_entry(tmp_path, monkeypatch):
    """The issue's reproductions, on real tmpfs mounts: the job folder's disk fills while ``weights.pt`` is written
    (torch's writer meets ENOSPC), the data cache's cannot hold its entry. The job ends in one line naming
    ``weights.pt`` and the cause, exit 2, its last checkpoint intact and no temp file; the cache's failure is one
    warning and the job runs on without it. With room again (and the cache's disk remounted read-only: EROFS), the
    same command resumes the last checkpoint and ends with the numbers of a job that met no fault; results.json says
    the cache entry was not written, and why."""
    why = _mount_refused(tmp_path)
    if why is not None:
        pytest.skip(why)
    args = [a for a in JOB if not a.startswith("replicas=")] + ["replicas=300"]
    # the job once on this disk, its checkpoints kept: its numbers, and what its folder holds before weights.pt
    from selpres.run.checkpoint import Checkpoints

    ref_folder = tmp_path / "ref"
    monkeypatch.setattr(Checkpoints, "discard", lambda self: None)
    assert train(ref_folder, "replicas=300").code == 0
    monkeypatch.undo()
    clean = numbers(json.loads((ref_folder / "results.json").read_text()))
    pages = {p.name: -(-p.stat().st_size // 4096) * 4096 for p in ref_folder.rglob("*") if p.is_file()}
    before = sum(v for k, v in pages.items() if k not in ("weights.pt", "results.json"))
    job_kb = (before + pages["weights.pt"] // 2) // 1024  # full halfway through weights.pt
    done = subprocess.run(
        ["unshare", "-m", "--propagation", "private", "bash", "-c", _SCRIPT, "script", str(tmp_path), str(job_kb),
         *args],
        cwd=REPO, env=_env(PY=sys.executable), capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    read = lambda name: (tmp_path / name).read_text()  # noqa: E731
    assert read("first.rc").strip() == "2", read("first.err")
    (line,) = read("first.err").strip().splitlines()
    assert f"{tmp_path}/disk/job/weights.pt" in line and "No space left on device" in line, line
    cache_said = [ln for ln in read("first.out").splitlines() if "data cache" in ln]
    assert len(cache_said) == 1 and "goes on without the cache" in cache_said[0] and "No space left" in cache_said[0]
    assert read("cache.ls").strip() == ""  # no entry, no temp file
    after = tmp_path / "after"
    whole(after)
    assert not (after / "weights.pt").exists()
    kept = newest_epoch(after)
    assert kept == 4, sorted(p.name for p in after.iterdir())  # the checkpoint after the 4th of 5 epochs
    assert read("second.rc").strip() == "0", read("second.err")
    res = json.loads((tmp_path / "final" / "results.json").read_text())
    assert res["resumed_from_epoch"] == kept and numbers(res) == clean
    cache = res["data"]["cache"]
    assert cache.startswith(f"not written: {tmp_path}/cache/") and "Read-only file system (errno 30)" in cache, cache
    assert torch.load(tmp_path / "final" / "weights.pt", weights_only=True)["config_hash"] == res["config_hash"]


def test_a_real_file_size_limit_only_the_cache_entry_passes_leaves_the_job_running_without_it(tmp_path):
    """RLIMIT_FSIZE at 48 KB on the whole process: the job's files fit, the cache entry (~90 KB) does not; the
    kernel refuses its write (EFBIG, inside torch's writer), the job runs to its end, results.json and one warning
    say the entry was not written, and the numbers are a job's whose cache worked."""
    cache, out = tmp_path / "cache", tmp_path / "job"

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # as Python sets it: the write fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (48 * 1024, resource.RLIM_INFINITY))

    args = [a for a in JOB if not a.startswith("replicas=")] + ["replicas=1", f"hydra.run.dir={out}"]
    done = subprocess.run(
        [sys.executable, "train.py", *args], cwd=REPO, env=_env(SELPRES_DATA_CACHE=str(cache)), preexec_fn=limit,
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0 and done.stderr.strip() == "", done.stderr
    res = json.loads((out / "results.json").read_text())
    assert (
        res["data"]["cache"].startswith(f"not written: {cache}/")
        and "File too large (errno 27)" in res["data"]["cache"]
    )
    said = [ln for ln in (out / "train.log").read_text().splitlines() if "data cache" in ln]
    assert len(said) == 1 and "goes on without the cache" in said[0]
    assert not list(cache.iterdir())  # neither the entry nor its temp file
    ref = tmp_path / "ref"
    assert train(ref, "replicas=1").code == 0
    assert numbers(res) == numbers(json.loads((ref / "results.json").read_text()))
