"""The public API: ``selpres.__all__`` is what a library user needs (the Sampler and its Lightning callback, the
schedule, arms and task builders, the trained network, the report, the errors), every name is the object its owning
module defines, the command line's internals are not among them, and ``import selpres`` imports none of them (nor
torch) until one is used."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import selpres

# what a library user reaches for, by the README's sections (your own loop, Lightning, your own robot, a trained
# network, the report); written out here so that a name dropped from __all__ or an internal added to it fails
FRONT_DOOR = {
    "SelectivePresentation",
    "SelectivePresentationWarning",
    "SelectivePresentationCallback",
    "Schedule",
    "build_schedule",
    "priority_order",
    "TwoLinkArm",
    "SerialArm",
    "make_arm",
    "load_urdf",
    "to_urdf",
    "load_task",
    "load_exported",
    "load_csv",
    "Scaler",
    "BPN",
    "load_into",
    "Selector",
    "Presentation",
    "Ledger",
    "write_report",
    "ConfigError",
    "FileError",
}


def test_all_is_the_front_door():
    assert set(selpres.__all__) == FRONT_DOOR
    assert selpres.__all__ == sorted(selpres.__all__)


def test_every_public_name_resolves_to_its_owner():
    for name in selpres.__all__:
        owner = importlib.import_module(selpres._EXPORTS[name])
        assert getattr(selpres, name) is getattr(owner, name), name
    assert "SerialArm" in dir(selpres)


@pytest.mark.parametrize(
    "name, module",
    [
        ("train", "selpres.run.train"),
        ("compose_train", "selpres.run.config"),
        ("SelectivePresentationSampler", "selpres.presentation.sampler"),
    ],
)
def test_the_command_lines_internals_stay_in_their_modules(name, module):
    assert name not in selpres.__all__ and name not in dir(selpres)
    assert callable(getattr(importlib.import_module(module), name))  # still importable where they live


def test_a_former_public_name_says_where_it_lives():
    with pytest.raises(AttributeError, match=r"from selpres\.run\.train import train"):
        selpres.train  # noqa: B018
    with pytest.raises(AttributeError, match=r"from selpres\.run\.config import compose_train"):
        selpres.compose_train  # noqa: B018


def test_unknown_names_are_attribute_errors():
    with pytest.raises(AttributeError, match="no_such_thing"):
        selpres.no_such_thing  # noqa: B018


def test_import_is_lazy():
    code = "import sys, selpres; print('torch' in sys.modules, 'selpres.run.train' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]


def test_load_task_takes_a_jobs_recorded_robot_and_data_nodes():
    """A study (or any user) rebuilds the task a job trained on from its results.json config: the plain robot and
    data nodes give the task their specs give."""
    import json

    import torch

    from selpres.run.specs import recorded, task_specs

    from conftest import compose

    cfg = compose("data.heldout=300")
    config = json.loads(json.dumps(recorded(cfg)))  # as results.json holds it
    ours, theirs = selpres.load_task(config["robot"], config["data"]), selpres.load_task(*task_specs(cfg))
    assert torch.equal(ours.exemplar.X, theirs.exemplar.X) and torch.equal(ours.tests.heldout.Y, theirs.tests.heldout.Y)
    for field in ("x_min", "x_max", "y_min", "y_max"):
        assert torch.equal(getattr(ours.scaler, field), getattr(theirs.scaler, field)), field


def test_the_reports_blocks_are_its_api_and_load_on_first_use():
    """``selpres.report.__all__``: what a study of one's own composes; each name resolves, and importing the
    package loads none of the blocks' modules (the command line starts without them)."""
    import selpres.report as R

    for name in R.__all__:
        assert getattr(R, name) is not None, name
    code = "import sys, selpres.report; print(sorted(m for m in sys.modules if m.startswith('selpres.report.')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["[]"]
