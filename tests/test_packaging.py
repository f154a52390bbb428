"""selpres installs as a package, apart from its studies, and its front page stays short and whole.

The slow tests: a wheel built from this checkout holds the library, its configs (the checkout's top-level configs/,
mapped in) and the kernels' C sources, and no study or benchmark code (those are the second distribution,
studies/); installed (not editable) into a fresh virtualenv, it runs a training job (``selpres-train``) and an
export (``selpres-export``) from a folder outside the checkout; a study's sweep runs there too and its report says
in one line that the studies are not installed, until the studies' own wheel is. The fast ones: README.md is at
most 300 lines, keeps the one Table 1 block the report rewrites, links one page per study under docs/studies/, and
every relative link in it and in docs/ resolves.

Isolation, and why this way. The new venv must see the wheel's selpres and nothing of the development install, but
re-installing torch, Hydra and the rest from the package index would take minutes. So the venv is made without
``--system-site-packages`` (the base interpreter may hold anything) and the wheel is installed with ``--no-deps``;
the dependencies come from the running interpreter's site-packages folders through a folder of symbolic links to
each of their entries *except* selpres's own (``selpres/``, ``selpres-*.dist-info``, the editable install's
``__editable__*`` finder and ``.pth`` files, ``hydra_plugins/selpres_search``) and except every ``.pth`` file (a path
line in the venv's ``.pth`` adds that folder to ``sys.path`` without running the ``.pth`` files inside it, and the
editable install is exactly such a file). That folder comes after the venv's own site-packages on ``sys.path``.
The processes run with ``PYTHONPATH`` removed and their working directory outside the checkout, so the only
selpres they can import is the installed one; the test asserts it (``selpres.__file__``, the configs the job's
Hydra read) rather than assuming it, and compares the job's numbers with the same job run from the checkout.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from conftest import REPO, run_python

# the development install's entries (and the plugin's, the studies' and the benchmarks')
OWN = ("selpres", "selpres_search", "selpres_studies", "selpres_bench", "__editable__")
JOB = ["replicas=2", "data.heldout=300", "eval.heldout_curve=300", "logging.progress=false"]


def _own(name: str) -> bool:
    """An entry of site-packages that belongs to the development install of selpres, or a .pth file."""
    return name.endswith(".pth") or name.split("-")[0].split(".")[0] in OWN or name.startswith("__editable__")


def dependencies_without_selpres(sites: list[Path], dest: Path) -> Path:
    """``dest``: symbolic links to every entry of the ``sites`` (the first of a name wins, as on ``sys.path``) but
    selpres's own and the .pth files; namespace folders that selpres shares with others (``hydra_plugins``) are
    linked entry by entry."""
    dest.mkdir()
    for site in sites:
        for entry in site.iterdir():
            if _own(entry.name):
                continue
            if entry.name == "hydra_plugins" and entry.is_dir():
                (dest / entry.name).mkdir(exist_ok=True)
                for sub in entry.iterdir():
                    if not _own(sub.name) and not (dest / entry.name / sub.name).exists():
                        (dest / entry.name / sub.name).symlink_to(sub)
            elif not (dest / entry.name).exists():
                (dest / entry.name).symlink_to(entry)
    return dest


def site_packages() -> list[Path]:
    """The running interpreter's site-packages folders in ``sys.path`` order (a venv's, then with
    ``--system-site-packages`` the base interpreter's)."""
    found = [Path(p) for p in sys.path if Path(p).name in ("site-packages", "dist-packages") and Path(p).is_dir()]
    return list(dict.fromkeys(found)) or [Path(sysconfig.get_paths()["purelib"])]


def _copy_source(dest: Path) -> Path:
    """The checkout's files a build reads (no .git, outputs, tests or build leftovers, which could leak into it): the
    library's project at ``dest``, the studies' at ``dest/studies``."""
    skip = shutil.ignore_patterns(
        ".git", ".venv", "outputs", "build", "dist", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis", "tests"
    )
    return Path(shutil.copytree(REPO, dest, ignore=skip))


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(venv's bin folder, a working folder outside the checkout, the environment the commands run in)."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = _copy_source(tmp / "src")
    pip = [sys.executable, "-m", "pip"]
    quiet = {"capture_output": True, "text": True, "check": True}
    for project in (src, src / "studies"):
        subprocess.run(
            [*pip, "wheel", "--no-deps", "--no-build-isolation", "-q", str(project), "-w", str(tmp / "dist")], **quiet
        )
    (wheel,) = (tmp / "dist").glob("selpres-*.whl")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], **quiet)
    py = venv / "bin" / "python"
    subprocess.run([*pip, "--python", str(py), "install", "--no-deps", "-q", str(wheel)], **quiet)
    purelib = Path(
        subprocess.run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], **quiet).stdout.strip()
    )
    deps = dependencies_without_selpres(site_packages(), tmp / "deps")
    (purelib / "zz_selpres_test_deps.pth").write_text(f"{deps}\n")
    work = tmp / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "HYDRA_FULL_ERROR")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env.pop("VIRTUAL_ENV", None)
    return venv / "bin", work, env, purelib, tmp / "dist"


def _run(installed, *cmd: str) -> subprocess.CompletedProcess:
    bin_, work, env = installed[:3]
    done = subprocess.run(
        [str(bin_ / cmd[0]), *cmd[1:]], cwd=work, env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, f"{' '.join(cmd)} exited {done.returncode}:\n{done.stderr[-3000:]}"
    return done


@pytest.mark.slow
def test_the_installed_selpres_is_the_wheels(installed):
    purelib = installed[3]
    code = "import sys, selpres, selpres.run.config as c; print(selpres.__file__); print(c.CONFIG_DIR); print(sys.path)"
    lines = _run(installed, "python", "-c", code).stdout.splitlines()
    assert Path(lines[0]).resolve() == (purelib / "selpres" / "__init__.py").resolve()
    assert (Path(lines[1]) / "train.yaml").is_file() and Path(lines[1]).is_relative_to(purelib)
    assert str(REPO) not in lines[2], "the checkout is on the installed interpreter's path"
    kernels = {p.name for p in (purelib / "selpres" / "native" / "kernels").iterdir()}
    assert {p.name for p in (REPO / "selpres" / "native" / "kernels").glob("*.[ch]")} <= kernels


@pytest.mark.slow
def test_selpres_train_runs_a_job_from_any_folder(installed, tmp_path):
    work, purelib = installed[1], installed[3]
    _run(installed, "selpres-train", *JOB)
    (results,) = (work / "outputs" / "runs").glob("*/results.json")  # the folder's default: outputs/ of the CWD
    hydra = (results.parent / ".hydra" / "hydra.yaml").read_text()
    assert f"path: {purelib / 'selpres' / 'configs'}" in hydra, "the job did not compose the installed configs"
    wheel = json.loads(results.read_text())
    assert wheel["status"] == "complete" and wheel["replicas"] == 2
    # the same job from the checkout (python train.py) gives the same numbers
    done = run_python("train.py", *JOB, f"hydra.run.dir={tmp_path / 'checkout'}")
    assert done.returncode == 0, done.stderr[-3000:]
    checkout = json.loads((tmp_path / "checkout" / "results.json").read_text())
    for key in ("summary", "replica_results", "schedule", "config_hash", "engine"):
        assert wheel[key] == checkout[key], key
    assert (wheel["provenance"]["selpres"]["commit"], wheel["provenance"]["selpres"]["version"]) == (
        None,
        checkout["provenance"]["selpres"]["version"],
    )  # an installed wheel has no commit of its own (issue 39)


@pytest.mark.slow
def test_selpres_export_and_the_other_commands_find_their_configs(installed):
    work = installed[1]
    out = _run(installed, "selpres-export").stdout
    stem = work / "outputs" / "data" / "two_link_grid"
    for path in (stem.with_suffix(".npz"), *(Path(f"{stem}_{s}.csv") for s in ("exemplar", "test10", "heldout"))):
        assert path.is_file() and str(path.relative_to(work)) in out, path
    assert not (installed[0] / "selpres-bench").exists()  # the benchmarks' command is the studies' distribution's
    assert "--readme" in _run(installed, "selpres-report", "--help").stdout
    assert "Config groups" in _run(installed, "selpres-train", "--help").stdout


def wheel_files(wheel: Path) -> list[str]:
    import zipfile

    with zipfile.ZipFile(wheel) as z:
        return z.namelist()


@pytest.mark.slow
def test_the_wheel_holds_the_library_its_configs_and_kernels_and_no_study(installed):
    (wheel,) = installed[4].glob("selpres-0*.whl")
    files = wheel_files(wheel)
    assert {f.split("/")[0] for f in files if ".dist-info/" not in f} == {"selpres", "hydra_plugins"}
    code = [f for f in files if f.endswith(".py")]
    assert not [f for f in code if "bench" in f or "studies" in f], "study or benchmark code in the library's wheel"
    assert sorted(f[len("selpres/configs/") :] for f in files if f.startswith("selpres/configs/")) == sorted(
        str(p.relative_to(REPO / "configs")) for p in (REPO / "configs").rglob("*.yaml")
    ), "the wheel's configs are not the checkout's configs/"
    assert {f"selpres/native/kernels/{p.name}" for p in (REPO / "selpres/native/kernels").glob("*.[ch]")} <= set(files)
    # and the studies' wheel holds them, with their designs, the benchmarks' command and the report's plug-in
    (studies,) = installed[4].glob("selpres_studies-*.whl")
    theirs = wheel_files(studies)
    assert {"selpres_studies/table1.py", "selpres_studies/table1.yaml", "selpres_bench/main.py"} <= set(theirs)
    assert not [f for f in theirs if f.startswith(("selpres/", "hydra_plugins/"))]
    meta = next(f for f in theirs if f.endswith("entry_points.txt"))
    import zipfile

    with zipfile.ZipFile(studies) as z:
        entry = z.read(meta).decode()
    assert "[selpres.report]" in entry and "selpres_studies" in entry and "selpres-bench" in entry


@pytest.mark.slow
def test_a_studys_sweep_runs_without_the_studies_and_its_report_says_so_in_one_line(installed):
    """Installed without the studies, ``experiment=compare`` (its report's plug-in: the studies) still trains, saying
    at its start in one line that the plug-in is not installed; its report is written with the runs and one line
    naming the plug-in; once the studies' wheel is installed, the same report has the study's sections."""
    work = installed[1]
    small = ["replicas=1", "data.heldout=300", "eval.heldout_curve=300", "logging.progress=false"]
    done = _run(installed, "selpres-train", "experiment=compare", "name=compare_wheel", *small)
    warned = [line for line in done.stderr.splitlines() if "selpres_studies" in line]
    assert len(warned) == 1 and "not installed" in warned[0], done.stderr[-2000:]
    sweep = work / "outputs" / "sweeps" / "compare_wheel"
    assert len(list(sweep.glob("*/results.json"))) == 2
    report = _run(installed, "selpres-report", str(sweep), "--out", str(work / "r1"))
    assert "## selpres_studies (not built)" in report.stdout and "## Runs" in report.stdout, report.stdout[:2000]
    assert "Table 1" not in report.stdout
    assert len([line for line in report.stderr.splitlines() if line.startswith("warning:")]) == 1
    # the studies installed: the same sweep's report has the sections its record names
    (studies,) = installed[4].glob("selpres_studies-*.whl")
    pip = [sys.executable, "-m", "pip", "--python", str(installed[0] / "python"), "install", "--no-deps", "-q"]
    subprocess.run([*pip, str(studies)], env=installed[2], capture_output=True, text=True, check=True)
    report = _run(installed, "selpres-report", str(sweep), "--out", str(work / "r2"))
    assert "not built" not in report.stdout and "# Table 1 reproduction" in report.stdout, report.stdout[:2000]
    assert "Benchmark selpres" in _run(installed, "selpres-bench", "--help").stdout


# ------------------------------------------------------------------------------------------------ the front page
STUDIES = ("sensitivity", "selection", "modern", "large")  # issue 25: one page each, one paragraph in the README
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def broken_links(text: str, base: Path) -> list[str]:
    """The relative Markdown links in ``text`` whose file (``#fragment`` dropped) does not exist under ``base``."""
    targets = [t.split("#")[0] for t in LINK.findall(text) if not re.match(r"[a-z]+:|#", t)]
    return [t for t in targets if not (base / t).exists()]


def pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def test_relative_links_in_the_readme_and_docs_resolve():
    assert broken_links("[a](docs/nowhere.md) [b](README.md#x) [c](https://x.org/y.md)", REPO) == ["docs/nowhere.md"]
    found = {str(p.relative_to(REPO)): broken for p in pages() if (broken := broken_links(p.read_text(), p.parent))}
    assert found == {}


def test_the_readme_is_short_keeps_its_table1_block_and_links_every_study():
    from selpres.report.readme import read_readme

    text = read_readme(REPO / "README.md")  # exactly one table1:begin/end pair, as `selpres-report --readme` needs
    assert len(text.splitlines()) <= 300
    for study in STUDIES:
        assert (REPO / "docs" / "studies" / f"{study}.md").is_file(), study
        assert f"](docs/studies/{study}.md)" in text, study
    assert "selpres-train" in text and ".whl" in text
