"""Issue 39.5: results.json records what ran (selpres's version, its commit and uncommitted changes only from its
own checkout, Python, torch, numpy, the platform, the CPUs, the native kernels' build), and the report's runs
section says when a sweep's jobs ran on different versions.

The commit is checked against checkouts made here with git: selpres's own (a commit of its own, then an edit, then
an unknown file), and the package installed inside another project's repository (its site-packages in that
project's virtual environment, and a copy vendored at the other repository's top), whose commit must never be
taken for selpres's; for real, by importing the copied package in a process of its own."""

from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from test_faults import train

from selpres.run import provenance as P

from conftest import REPO, requires_native

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="no git here to make checkouts with")


def git(where: Path, *args: str) -> str:
    done = subprocess.run(
        ["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=where, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def _package_copy(dest: Path) -> Path:
    """The selpres package (its Python files and what it reads) copied to ``dest/selpres``."""
    shutil.copytree(REPO / "selpres", dest / "selpres", ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    return dest / "selpres"


def _repo(folder: Path, pyproject: str) -> Path:
    folder.mkdir(parents=True)
    (folder / "pyproject.toml").write_text(pyproject)
    git(folder, "init", "-q")
    git(folder, "add", "-A")
    git(folder, "commit", "-q", "-m", "first")
    return folder


def test_selpres_own_checkout_gives_its_commit_and_says_when_it_has_changes(tmp_path):
    root = tmp_path / "selpres-checkout"
    root.mkdir()
    package = _package_copy(root)
    (root / "pyproject.toml").write_text('[project]\nname = "selpres"\nversion = "9.8.7"\n')
    (root / "notes.txt").write_text("the user's")
    git(root, "init", "-q")
    git(root, "add", "-A")
    git(root, "commit", "-q", "-m", "first")
    head = git(root, "rev-parse", "HEAD")
    src = P.selpres_source(package)
    assert src == {"version": "9.8.7", "location": str(package), "checkout": True, "commit": head, "dirty": False}
    (root / "scratch.txt").write_text("not known to git, outside the package: no change to selpres")
    assert P.selpres_source(package)["dirty"] is False
    (package / "mine.py").write_text("x = 1\n")  # a file git does not know, inside the package: it can change runs
    assert P.selpres_source(package)["dirty"] is True
    (package / "mine.py").unlink()
    (root / "notes.txt").write_text("edited")  # a tracked file changed
    assert P.selpres_source(package) == {**src, "dirty": True}


@pytest.mark.parametrize("where", ["site-packages", "vendored", "no repository"])
def test_a_package_inside_another_repository_has_no_commit_of_its_own(tmp_path, where):
    """The package in another project's repository: in its virtual environment's site-packages, or copied to the top
    of it (whose pyproject.toml names that project); or in a folder no repository holds (an installed wheel)."""
    if where == "no repository":
        package = _package_copy(tmp_path / "lib")
    else:
        other = _repo(tmp_path / "project", '[project]\nname = "project"\nversion = "1.0"\n')
        base = other / ".venv/lib/python3.11/site-packages" if where == "site-packages" else other
        package = _package_copy(base)
        if where == "vendored":
            git(other, "add", "-A")
            git(other, "commit", "-q", "-m", "vendor selpres")
    src = P.selpres_source(package)
    assert (src["checkout"], src["commit"], src["dirty"], src["location"]) == (False, None, None, str(package))


@pytest.mark.slow
def test_imported_from_inside_another_repository_a_process_records_no_commit(tmp_path):
    """For real: a process that imports the copy in the other project's site-packages (the way a virtual
    environment there runs selpres) records that copy, and no commit; the other repository's HEAD appears nowhere."""
    other = _repo(tmp_path / "project", '[project]\nname = "project"\nversion = "1.0"\n')
    site = other / ".venv/lib/python3.11/site-packages"
    package = _package_copy(site)
    code = "import json, selpres.run.provenance as P; print(json.dumps({**P.record(), 'file': P.__file__}))"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("GIT_", "PYTHON"))}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=other, env={**env, "PYTHONPATH": str(site)},
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    rec = json.loads(done.stdout.strip().splitlines()[-1])
    assert rec["file"].startswith(str(package))
    assert rec["selpres"]["location"] == str(package) and rec["selpres"]["commit"] is None
    assert git(other, "rev-parse", "HEAD") not in done.stdout


def test_a_jobs_results_record_the_versions_and_machine_it_ran_on(tmp_path):
    assert train(tmp_path / "job", "replicas=1").code == 0
    rec = json.loads((tmp_path / "job" / "results.json").read_text())["provenance"]
    assert (rec["python"], rec["torch"], rec["numpy"]) == (platform.python_version(), torch.__version__, np.__version__)
    assert (
        rec["platform"] == platform.platform() and rec["cpus"] >= 1 and rec["selpres"]["location"].endswith("selpres")
    )
    checkout = P.checkout_of(Path(rec["selpres"]["location"]))
    if checkout is not None:  # this suite runs from selpres's own checkout: its HEAD
        assert rec["selpres"]["commit"] == git(checkout, "rev-parse", "HEAD")
        assert isinstance(rec["selpres"]["dirty"], bool)


@requires_native
def test_a_native_job_records_how_its_kernel_was_built(tmp_path):
    assert train(tmp_path / "job", "replicas=1", "engine=native").code == 0
    native = json.loads((tmp_path / "job" / "results.json").read_text())["provenance"]["native"]
    from selpres.native.build import CFLAGS, _compiler, _compiler_version

    assert any(f.startswith(" ".join(CFLAGS)) for f in native["flags"]) and "-march=native" in native["flags"][0]
    assert not any("-DSIZES" in f for f in native["flags"])  # the topology is the config's, not the build's
    assert any(lib.startswith("selpres_6-13-2_") for lib in native["libraries"])
    assert _compiler_version(tuple(_compiler())).splitlines()[0] in native["compiler"]
    assert "AVX2" in native["instruction_set"] and "FMA" in native["instruction_set"]


# ---------------------------------------------------------------------------------------------- the report
def test_the_runs_section_says_what_ran_and_which_jobs_ran_on_other_versions(tmp_path):
    from selpres.report.build import Report

    sweep = tmp_path / "sweep"
    for seed in range(3):
        assert train(sweep / f"seed{seed}", f"seed={seed}", "replicas=1").code == 0
    runs = Report.build(sweep).sections[-1].markdown()
    line = next(ln for ln in runs.splitlines() if ln.startswith("**What ran.**"))
    assert "3 jobs: selpres " in line and f"torch {torch.__version__}" in line and "warning" not in runs
    path = sweep / "seed2" / "results.json"
    res = json.loads(path.read_text())
    res["provenance"]["torch"] = "2.99.0"
    res["provenance"]["cpus"] = 512
    path.write_text(json.dumps(res))
    res = json.loads((sweep / "seed1" / "results.json").read_text())
    del res["provenance"]
    (sweep / "seed1" / "results.json").write_text(json.dumps(res))
    runs = Report.build(sweep).sections[-1].markdown()
    assert (
        f"- warning: the jobs ran on different versions: torch: {torch.__version__} (1 job); 2.99.0 (1 job: `seed2`)"
        in runs
    )
    assert "- note: the jobs ran on different machines: CPUs:" in runs and "512 (1 job: `seed2`)" in runs
    assert "- 1 finished job records no provenance" in runs
    assert "2 jobs: selpres" in runs and "numpy " in runs  # what they share, once
    said = {r["job"]: r["provenance"] for r in Report.build(sweep).rows("runs.csv")}
    assert said["seed1"] == "not recorded" and "torch 2.99.0" in said["seed2"]
    assert f"torch {torch.__version__}" in said["seed0"] and "CPUs 512" in said["seed2"]

    # native kernels: a sweep worker's record lists every library its process loaded, so two jobs may list different
    # kernels built the same way (no warning); one kernel under two build hashes is a difference
    def kernels(job, libraries):
        path = sweep / job / "results.json"
        res = json.loads(path.read_text())
        res["provenance"]["torch"], res["provenance"]["cpus"] = torch.__version__, 2
        flags = ["-O3 -march=native", "-O3 -march=native -ffp-contract=off"][: len(libraries)]
        res["provenance"]["native"] = {"libraries": libraries, "compiler": "cc (12)", "flags": flags,
                                       "instruction_set": "AVX2 FMA", "cpu": "x"}  # fmt: skip
        path.write_text(json.dumps(res))

    kernels("seed0", ["selpres_6-13-2_aaaa.so", "selpres_6-13-2_dddd.so", "selpres_mb_6-13-2_relu_bbbb.so"])
    kernels("seed2", ["selpres_6-13-2_aaaa.so"])  # a variant beside the usual build in seed0's process: no conflict
    runs = Report.build(sweep).sections[-1].markdown()
    assert "warning" not in runs and "native kernels cc (12) (AVX2 FMA)" in runs, runs
    kernels("seed2", ["selpres_6-13-2_cccc.so"])
    runs = Report.build(sweep).sections[-1].markdown()
    assert "- warning: the jobs ran on different versions: native kernel selpres_6-13-2: build " in runs
    assert "build aaaa, dddd (1 job" in runs and "build cccc (1 job" in runs and "`seed" in runs
