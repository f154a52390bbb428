"""The public API: every name in ``selpres.__all__`` is the object its owning module defines, and ``import
selpres`` imports none of them (nor torch) until one is used."""

from __future__ import annotations

import importlib
import subprocess
import sys

import selpres


def test_every_public_name_resolves_to_its_owner():
    for name in selpres.__all__:
        owner = importlib.import_module(selpres._EXPORTS[name])
        assert getattr(selpres, name) is getattr(owner, name), name
    assert "train" in dir(selpres) and "SerialArm" in selpres.__all__


def test_unknown_names_are_attribute_errors():
    try:
        selpres.no_such_thing  # noqa: B018
    except AttributeError as e:
        assert "no_such_thing" in str(e)
    else:
        raise AssertionError("selpres.no_such_thing did not raise")


def test_import_is_lazy():
    code = "import sys, selpres; print('torch' in sys.modules, 'selpres.run.train' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]
