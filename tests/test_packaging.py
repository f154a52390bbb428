"""selpres installs as a package, and its front page stays short and whole.

The slow tests: a wheel built from this checkout, installed (not editable) into a fresh virtualenv, runs a training
job (``selpres-train``) and an export (``selpres-export``) from a folder outside the checkout, on the configs and
kernel sources the wheel ships. The fast ones: README.md is at most 300 lines, keeps the one Table 1 block the
report rewrites, links one page per study under docs/studies/, and every relative link in it and in docs/ resolves.

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

OWN = ("selpres", "selpres_search", "__editable__")  # the development install's entries (and the plugin's)
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
    """The checkout's files a build reads (no .git, outputs, tests or build leftovers, which could leak into it)."""
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
    subprocess.run(
        [*pip, "wheel", "--no-deps", "--no-build-isolation", "-q", str(src), "-w", str(tmp / "dist")], **quiet
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
    return venv / "bin", work, env, purelib


def _run(installed, *cmd: str) -> subprocess.CompletedProcess:
    bin_, work, env, _ = installed
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
    work, purelib = installed[1], installed[3]
    out = _run(installed, "selpres-export").stdout
    stem = work / "outputs" / "data" / "two_link_grid"
    for path in (stem.with_suffix(".npz"), *(Path(f"{stem}_{s}.csv") for s in ("exemplar", "test10", "heldout"))):
        assert path.is_file() and str(path.relative_to(work)) in out, path
    bench = _run(installed, "selpres-bench", "--help").stdout
    assert str(purelib / "selpres" / "configs") in bench.replace("\n", "").replace(" ", "")
    assert "--readme" in _run(installed, "selpres-report", "--help").stdout
    assert "Config groups" in _run(installed, "selpres-train", "--help").stdout


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
