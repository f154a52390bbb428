"""The YAML/dict spec of a serial arm (``robot._target_: serial``), read with errors naming ``robot.<key>``.

The spec (see ``selpres.arms.serial``'s docstring), plain dicts and lists (``selpres.run.specs.plain`` makes them
from a config), becomes plain rows: ``parse_spec`` checks every key
and value and each link's physics with this config's key names, and returns what ``SerialArm`` is built
from, so a typo is refused before any arm exists.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from selpres.arms.kinematics import ZERO33, Link, Mat3, check_link, rpy_matrix
from selpres.errors import ConfigError

INERTIA_KEYS = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")
ZERO3 = (0.0, 0.0, 0.0)
FIELDS = ("name", "mass", "com", "inertia", "joint", "limits")


def _keys(node: Any, key: str, allowed: Sequence[str], required: Sequence[str] = ()) -> dict[str, Any]:
    if not isinstance(node, dict):
        raise ConfigError(key, node, f"a mapping with keys {list(allowed)}")
    for k in node:
        if k not in allowed:
            raise ConfigError(f"{key}.{k}", node[k], f"one of the keys {list(allowed)}")
    for k in required:
        if k not in node:
            raise ConfigError(f"{key}.{k}", None, "a value (the key is required)")
    return node


def _number(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(key, value, "a finite number")
    return float(value)


def _vector(value: Any, key: str, n: int = 3) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n:
        raise ConfigError(key, value, f"a list of {n} finite numbers")
    return tuple(_number(v, f"{key}[{i}]") for i, v in enumerate(value))


def _inertia(value: Any, key: str) -> Mat3:
    if isinstance(value, dict):
        node = _keys(value, key, INERTIA_KEYS, ("ixx", "iyy", "izz"))
        v = {k: _number(node.get(k, 0.0), f"{key}.{k}") for k in INERTIA_KEYS}
        return ((v["ixx"], v["ixy"], v["ixz"]), (v["ixy"], v["iyy"], v["iyz"]), (v["ixz"], v["iyz"], v["izz"]))
    if isinstance(value, list) and len(value) == 3:
        return tuple(_vector(row, f"{key}[{i}]") for i, row in enumerate(value))  # type: ignore[return-value]
    raise ConfigError(key, value, "{ixx, iyy, izz[, ixy, ixz, iyz]} or a 3x3 list (kg m^2, about the com)")


# the serial source's alias and import path (what a robot file's _target_ names; tests/test_plugin_contracts.py keeps
# this in step with selpres.arms.sources, which this module may not import: the sources build arms from it)
SERIAL = ("serial", "selpres.arms.sources.serial.Serial")


def parse_spec(node: Any, prefix: str, cls: type) -> Any:
    """The ``SerialArm`` (``cls``) a spec describes; ConfigError naming ``prefix.<key>``."""
    top = _keys(
        node,
        prefix,
        ("_target_", "kind", "name", "gravity", "end_point", "base", "tip", "convention", "links"),
        ("gravity", "links"),
    )
    for k in ("_target_", "kind"):  # a robot node (configs/robot/*.yaml) or an arm's description (to_config)
        if top.get(k, "serial") not in SERIAL:
            raise ConfigError(f"{prefix}.{k}", top[k], "'serial' for selpres.arms.serial.SerialArm")
    convention = top.get("convention", "urdf")
    if convention not in ("urdf", "dh"):
        raise ConfigError(f"{prefix}.convention", convention, "'urdf' (joint xyz/rpy/axis) or 'dh'")
    links = top["links"]
    if not isinstance(links, list) or not links:
        raise ConfigError(f"{prefix}.links", links, "a non-empty list of links, from the base outwards")
    kw = {k: str(top[k]) for k in ("name", "base", "tip") if k in top}
    gravity = _vector(top["gravity"], f"{prefix}.gravity")
    end = _vector(top["end_point"], f"{prefix}.end_point") if "end_point" in top else ZERO3
    joint_keys = ("name", "limits", "velocity", "effort") + (() if convention == "dh" else ("xyz", "rpy", "axis"))
    parsed = []
    for i, raw in enumerate(links):
        key = f"{prefix}.links[{i}]"
        geometry = "dh" if convention == "dh" else "joint"
        lk = _keys(
            raw,
            key,
            ("name", "joint", "dh", "mass", "com", "inertia")
            if convention == "dh"
            else ("name", "joint", "mass", "com", "inertia"),
            ("mass", "com", geometry),
        )
        joint = _keys(lk.get("joint", {}), f"{key}.joint", joint_keys, () if convention == "dh" else ("axis",))
        row = {
            "name": str(lk.get("name", f"link{i + 1}")),
            "mass": _number(lk["mass"], f"{key}.mass"),
            "com": _vector(lk["com"], f"{key}.com"),
            "inertia": _inertia(lk["inertia"], f"{key}.inertia") if "inertia" in lk else ZERO33,
            "joint": str(joint.get("name", f"joint{i + 1}")),
            "limits": _vector(joint["limits"], f"{key}.joint.limits", 2) if "limits" in joint else None,
            **{k: _number(joint[k], f"{key}.joint.{k}") for k in ("velocity", "effort") if joint.get(k) is not None},
        }
        if convention == "dh":
            dh = _keys(lk["dh"], f"{key}.dh", ("a", "alpha", "d", "offset"), ("a", "alpha", "d"))
            row.update({k: _number(v, f"{key}.dh.{k}") for k, v in dh.items()})
        else:
            row.update(
                xyz=_vector(joint.get("xyz", [0.0, 0.0, 0.0]), f"{key}.joint.xyz"),
                rotation=rpy_matrix(_vector(joint.get("rpy", [0.0, 0.0, 0.0]), f"{key}.joint.rpy")),
                axis=_vector(joint["axis"], f"{key}.joint.axis"),
            )
        # physical checks with this config's key names (the arm re-checks with its own)
        check = Link(
            **{k: row[k] for k in (*FIELDS, "velocity", "effort") if k in row},
            **({"xyz": row["xyz"], "rotation": row["rotation"], "axis": row["axis"]} if convention == "urdf" else {}),
        )
        check_link(check, key)
        parsed.append(row)
    if convention == "dh":
        return cls.from_dh(parsed, gravity, end, **kw)
    return cls([Link(**r) for r in parsed], gravity, end, **kw)
