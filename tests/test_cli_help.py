"""`python train.py --help`: one screen that names every config group and top-level key (and not the design
points); `name=` refused for a single run, where it would be ignored."""

from __future__ import annotations

import dataclasses

import pytest

from selpres.run.config import TrainConfig

from conftest import REPO, run_python

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def help_text() -> str:
    done = run_python("train.py", "--help")
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_help_names_every_group_and_key(help_text):
    groups = sorted(p.name for p in (REPO / "configs").iterdir() if p.is_dir() and p.name != "hydra")
    missing = [g for g in groups if f"\n  {g} " not in help_text]
    assert not missing, f"config groups not in --help: {missing}"
    keys = [f.name for f in dataclasses.fields(TrainConfig) if f.name not in groups]
    assert [k for k in keys if f"  {k}=" not in help_text and f" {k}." not in help_text] == []
    # every option of the small groups is listed (design/ and experiment/ are studies, named by their folder)
    for group in ("robot", "data", "schedule", "topology", "optim", "experiment"):
        lines = help_text.splitlines()
        i = next(i for i, ln in enumerate(lines) if ln.startswith(f"  {group} "))
        line = " ".join([lines[i], *[ln for ln in lines[i + 1 : i + 3] if ln.startswith("              ")]])
        options = sorted(p.stem for p in (REPO / "configs" / group).glob("*.yaml"))
        assert [o for o in options if o not in line] == [], group


def test_help_is_one_screen_without_design_points(help_text):
    assert len(help_text.splitlines()) <= 60
    design = sorted(p.stem for p in (REPO / "configs" / "design").glob("*.yaml"))
    assert design and not any(d in help_text for d in design)


def test_name_refused_for_a_single_run(tmp_path):
    folder = tmp_path / "run"
    done = run_python("train.py", "name=mine", f"hydra.run.dir={folder}")
    assert done.returncode == 2
    assert "name='mine'" in done.stderr and "-m" in done.stderr and "Traceback" not in done.stderr
    assert not folder.exists()


def test_export_default_names_the_task_not_exemplar_twice():
    from selpres.registry import Choice
    from selpres.run.export import compose_data_config, default_stem

    robot, data = compose_data_config([])
    assert default_stem(robot, data).as_posix() == "outputs/data/two_link_grid"
    robot, data = compose_data_config(["robot=puma560"])
    assert default_stem(robot, data).as_posix() == "outputs/data/puma560_sampled"
    urdf = Choice("urdf", {"path": "/some/where/panda.urdf"})
    assert default_stem(urdf, data).name == "panda_sampled"
