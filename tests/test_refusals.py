"""Issue 26: the last tracebacks. A damaged .npz, a memory cap (RLIMIT_AS, RLIMIT_DATA), a disk too small for
Hydra's own files: one line, exit 2, and a folder that existed before left as it was (no .hydra/, no lock, no
train.log, no results.json). Real corrupt files, real rlimits in the child process, a real tiny tmpfs (root only)."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import zipfile
import zlib

import numpy as np
import pytest

from conftest import REPO

pytestmark = pytest.mark.slow  # subprocesses
FILE = ["data=file", "data.inputs=[q1,q2,dq1,dq2,ddq1,ddq2]", "data.outputs=[tau1,tau2]"]
SMALL = ["data.heldout=300", "eval.heldout_curve=300"]


def train(folder, *args, preexec=None, **env):
    """``python train.py`` into ``folder``, as a user runs it (stderr and exit code)."""
    e = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"} | {"PYTHONPATH": str(REPO)} | env
    return subprocess.run(
        [sys.executable, "train.py", *args, f"hydra.run.dir={folder}"],
        cwd=REPO, env=e, capture_output=True, text=True, timeout=600, preexec_fn=preexec,
    )  # fmt: skip


def users_folder(path):
    path.mkdir(parents=True)
    (path / "mine.txt").write_text("the user's")
    return path


def untouched(folder) -> bool:
    return (
        sorted(p.name for p in folder.iterdir()) == ["mine.txt"] and (folder / "mine.txt").read_text() == "the user's"
    )


# ------------------------------------------------------------------------------------------ a damaged .npz
def _npz(path, compressed=False):
    rng = np.random.default_rng(0)
    cols = {k: rng.uniform(-1, 1, 300) for k in ("q1", "q2", "dq1", "dq2", "ddq1", "ddq2", "tau1", "tau2")}
    (np.savez_compressed if compressed else np.savez)(path, **cols)
    return path


def flip(path, at=2000):
    b = bytearray(path.read_bytes())
    b[at] ^= 0xFF
    path.write_bytes(bytes(b))


@pytest.mark.parametrize(
    "damage, why",
    [
        (lambda p: flip(_npz(p)), "BadZipFile: Bad CRC-32 for file 'q1.npy'"),
        (lambda p: flip(_npz(p, compressed=True), 600), "not a readable .npz"),
        (lambda p: p.write_bytes(_npz(p).read_bytes()[:3000]), "BadZipFile: File is not a zip file"),
    ],
    ids=["flipped-byte", "flipped-compressed", "cut"],
)
def test_a_damaged_npz_is_one_line_and_the_folder_is_left_as_it_was(tmp_path, damage, why):
    data = tmp_path / "bad.npz"
    damage(data)
    with pytest.raises((zipfile.BadZipFile, zlib.error)):  # the damage is real
        with np.load(data) as z:
            [z[k] for k in z.files]
    job = users_folder(tmp_path / "job")
    done = train(job, *FILE, f"data.path={data}")
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith(f"error: {data}: file: not a readable .npz") and why in line, line
    assert untouched(job)


# ------------------------------------------------------------------------------------------- a memory cap
def _cap(kind, nbytes):
    return lambda: resource.setrlimit(kind, (nbytes, nbytes))


def test_the_estimate_honours_rlimit_as_and_rlimit_data():
    """In a child with each cap: what the estimate may use is the cap less what the process maps (VmSize for
    RLIMIT_AS, VmData for RLIMIT_DATA), read here independently from /proc."""
    code = (
        "import resource, sys; from selpres.run.estimate import available_memory; "
        "kind = getattr(resource, sys.argv[1]); resource.setrlimit(kind, (int(sys.argv[2]),) * 2); "
        "room, why = available_memory(); "
        "st = {l.split(':')[0]: int(l.split()[1]) * 1024 for l in open('/proc/self/status') if l.startswith('Vm')}; "
        "print(room, st[sys.argv[3]], why)"
    )
    for kind, field in (("RLIMIT_AS", "VmSize"), ("RLIMIT_DATA", "VmData")):
        cap = 3 * 10**9
        env = {k: v for k, v in os.environ.items() if k != "SELPRES_MEMORY_LIMIT"} | {"PYTHONPATH": str(REPO)}
        done = subprocess.run([sys.executable, "-c", code, kind, str(cap), field], env=env, capture_output=True,
                              text=True, timeout=300)  # fmt: skip
        assert done.returncode == 0, done.stderr
        room, used, why = done.stdout.split(maxsplit=2)
        assert abs(int(room) - (cap - int(used))) < 50 * 2**20, (kind, room, used)  # within what one read maps
        assert why.startswith(kind), why


def test_replicas_beyond_an_address_space_cap_are_refused_from_the_estimate(tmp_path):
    """The issue's ``ulimit -v 5859375; python train.py replicas=100000``: refused up front, naming the cap."""
    job = users_folder(tmp_path / "job")
    env = {"SELPRES_MEMORY_LIMIT": ""}  # unset: the machine's own figures
    done = train(job, "replicas=100000", preexec=_cap(resource.RLIMIT_AS, 5_859_375 * 1024), **env)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("error: replicas=100000 is not allowed: expected a job that fits in memory")
    assert "RLIMIT_AS (ulimit -v) 6.0 GB less the" in line, line
    assert untouched(job)


def test_an_allocation_that_fails_in_set_up_is_the_same_refusal(tmp_path):
    """Past the estimate (here told there is plenty, SELPRES_MEMORY_LIMIT): torch's RuntimeError "can't allocate
    memory" under a real RLIMIT_AS is one line, exit 2, nothing left."""
    job = users_folder(tmp_path / "job")
    done = train(job, "replicas=20000", *SMALL, preexec=_cap(resource.RLIMIT_AS, 10**9), SELPRES_MEMORY_LIMIT="1e12")
    assert done.returncode == 2, done.stderr[-3000:]
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("error: out of memory: an allocation of") and "nothing of this run was kept" in line
    assert untouched(job)


# ------------------------------------------------------------------------------------------ a small disk
def test_a_write_of_hydras_record_that_fails_is_one_line_and_nothing_is_left(tmp_path):
    """RLIMIT_FSIZE of 4,000 bytes: the lock file and config.yaml fit, hydra.yaml (~7 KB) does not (EFBIG)."""
    job = users_folder(tmp_path / "job")

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead of a signal
        resource.setrlimit(resource.RLIMIT_FSIZE, (4000, 4000))

    done = train(job, preexec=limit)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"error: cannot write Hydra's record {job}/.hydra/hydra.yaml (File too large): nothing was kept"
    ]
    assert untouched(job)


@pytest.fixture
def tiny_disk(tmp_path):
    """A 64 KB tmpfs (mounting needs root: skipped otherwise)."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)], capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here (not root)")
    yield mnt
    subprocess.run(["umount", str(mnt)], check=True)


@pytest.mark.parametrize("free_kb", [16, 0])
def test_a_disk_too_small_for_hydras_files_is_one_line_and_nothing_is_left(tiny_disk, free_kb):
    job = users_folder(tiny_disk / "job")
    filler = tiny_disk / "filler"
    with open(filler, "wb") as f:  # fill the disk to leave free_kb
        try:
            while os.statvfs(tiny_disk).f_bavail * os.statvfs(tiny_disk).f_frsize > free_kb * 1024:
                f.write(b"\0" * 4096)
                f.flush()
        except OSError:
            pass
    done = train(job)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith(f"error: {job} has") or line.startswith(f"error: cannot write into {job}"), line
    assert "nothing was written" in line and "Traceback" not in done.stderr
    assert untouched(job)  # no .hydra/, no .selpres.lock (not even empty), no train.log
