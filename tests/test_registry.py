"""The registry lists a kind's built-ins without importing them and resolves import paths, refusing the rest."""

from __future__ import annotations

import sys

import pytest

from selpres.errors import ConfigError
from selpres.registry import Registry, locate


def test_built_ins_are_the_package_modules_and_none_is_imported(tmp_path, monkeypatch):
    pkg = tmp_path / "kinds"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "alpha.py").write_text("ENTRY = 'a'\nimport sys\nsys.modules[__name__].IMPORTED = True\n")
    (pkg / "beta.py").write_text("ENTRY = 'b'\n")
    (pkg / "_helper.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    reg = Registry("kind.name", "kinds", "ENTRY")
    assert reg.names == ("alpha", "beta")
    assert "kinds.alpha" not in sys.modules
    assert reg.get("beta") == "b"
    assert reg.check("alpha") == "alpha"
    with pytest.raises(ConfigError, match=r"kind.name='gamma' is not allowed: expected one of alpha, beta"):
        reg.check("gamma")
    with pytest.raises(ConfigError, match="kind.name"):
        reg.get("_helper")


def test_import_paths_resolve_or_say_why_not():
    assert locate("k", "collections.OrderedDict").__name__ == "OrderedDict"
    with pytest.raises(ConfigError, match=r"an importable module \(no_such_mod"):
        locate("k", "no_such_mod.Thing")
    with pytest.raises(ConfigError, match="it has no 'Nope'"):
        locate("k", "collections.Nope")


def test_build_makes_the_class_from_the_node_and_names_a_bad_key():
    from dataclasses import dataclass

    from selpres.registry import construct

    @dataclass
    class Arm:
        mass: float
        length: float = 1.0

    assert construct(Arm, {"mass": 2.0}, "robot") == Arm(2.0, 1.0)
    with pytest.raises(
        ConfigError, match=r"robot.lenght=3 is not allowed: expected one of the keys \['mass', 'length'\]"
    ):
        construct(Arm, {"mass": 2.0, "lenght": 3}, "robot")
    with pytest.raises(ConfigError, match=r"robot.mass=None is not allowed: expected a value \(.*Arm requires it\)"):
        construct(Arm, {"length": 2.0}, "robot")
    reg = Registry("node._target_", "selpres.arms", "ENTRY")
    assert reg.build("collections.OrderedDict", {"a": 1}) == {"a": 1}  # **kwargs: the class checks its own keys
