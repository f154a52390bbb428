"""URDF out: ``to_urdf`` writes a ``SerialArm`` that ``load_urdf``, Pinocchio or MuJoCo read back as the same dynamics.

URDF stores no gravity; tools assume it along −z of the root link. ``to_urdf`` therefore writes a root link
``world`` turned so that the arm's gravity points along its −z whenever it does not already (the paper's arm
has gravity along −y), and its magnitude in a comment.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

from selpres.arms.kinematics import IDENTITY, ZERO3, Mat3, Vec3, _mat_mul, matrix_rpy
from selpres.arms.serial import SerialArm
from selpres.storage import atomic_write


# ------------------------------------------------------------------------------------------------- writing
def _fmt(values) -> str:
    return " ".join(repr(float(v) + 0.0) for v in values)


def _gravity_turn(gravity: Vec3) -> Mat3:
    """A rotation taking the direction of ``gravity`` onto −z (identity for zero gravity)."""
    norm = math.sqrt(sum(x * x for x in gravity))
    if norm == 0.0:
        return IDENTITY
    u = tuple(x / norm for x in gravity)
    down = (0.0, 0.0, -1.0)
    axis = (u[1] * down[2] - u[2] * down[1], u[2] * down[0] - u[0] * down[2], u[0] * down[1] - u[1] * down[0])
    s, c = math.sqrt(sum(x * x for x in axis)), -u[2]
    if s < 1e-15:
        return IDENTITY if c > 0 else ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))  # π about x
    k = tuple(x / s for x in axis)
    skew = ((0.0, -k[2], k[1]), (k[2], 0.0, -k[0]), (-k[1], k[0], 0.0))
    sq = _mat_mul(skew, skew)
    return tuple(tuple(IDENTITY[r][j] + s * skew[r][j] + (1 - c) * sq[r][j] for j in range(3)) for r in range(3))


def to_urdf(arm: SerialArm, path: str | Path) -> Path:
    """Write ``arm`` as a URDF that ``load_urdf`` (with g = |gravity|), Pinocchio or MuJoCo read back as the
    same dynamics. Returns the path."""
    path = Path(path)
    names = {lk.name for lk in arm.links} | {arm.base}
    write_tip = arm.tip != arm.links[-1].name
    if write_tip and arm.tip in names:
        raise ValueError(f"tip name {arm.tip!r} is already a link or the base of {arm.name!r}: rename the tip")
    if not write_tip and any(x != 0.0 for x in arm.end_point):
        raise ValueError(f"tip {arm.tip!r} is the last link but the end point {arm.end_point} is not its origin")
    g = math.sqrt(sum(x * x for x in arm.gravity_vector))
    turn = _gravity_turn(arm.gravity_vector)
    robot = ET.Element("robot", name=arm.name)
    robot.append(
        ET.Comment(
            f" written by selpres.arms.urdf.to_urdf: {arm.dof} revolute joints. Gravity {g!r} m/s^2 along -z of the "
            f"root link (selpres: load_urdf(path, gravity=[0, 0, -g])). The wrench of eq. (4) is expressed in link "
            f"{arm.base!r} and acts at the origin of link {arm.tip!r}. Effort and velocity limits: 0 = not given. "
        )
    )

    def joint(name: str, kind: str, parent: str, child: str, xyz, rpy) -> ET.Element:
        el = ET.SubElement(robot, "joint", name=name, type=kind)
        ET.SubElement(el, "parent", link=parent)
        ET.SubElement(el, "child", link=child)
        ET.SubElement(el, "origin", xyz=_fmt(xyz), rpy=_fmt(rpy))
        return el

    if turn != IDENTITY:  # a root whose -z is the arm's gravity
        world = next(n for n in ("world", "world_", "world__") if n not in names | {arm.tip})
        ET.SubElement(robot, "link", name=world)
        joint(f"{world}_to_{arm.base}", "fixed", world, arm.base, ZERO3, matrix_rpy(turn))
    ET.SubElement(robot, "link", name=arm.base)
    parent = arm.base
    for lk in arm.links:
        kind = "continuous" if lk.limits is None else "revolute"
        el = joint(lk.joint, kind, parent, lk.name, lk.xyz, lk.rpy)
        ET.SubElement(el, "axis", xyz=_fmt(lk.axis))
        if lk.limits is not None:
            rates = {k: repr(getattr(lk, k) or 0.0) for k in ("effort", "velocity")}  # 0: not given
            ET.SubElement(el, "limit", lower=repr(lk.limits[0]), upper=repr(lk.limits[1]), **rates)
        inertial = ET.SubElement(ET.SubElement(robot, "link", name=lk.name), "inertial")
        ET.SubElement(inertial, "origin", xyz=_fmt(lk.com), rpy="0 0 0")
        ET.SubElement(inertial, "mass", value=repr(lk.mass))
        i = lk.inertia
        ET.SubElement(
            inertial,
            "inertia",
            ixx=repr(i[0][0]),
            ixy=repr(i[0][1]),
            ixz=repr(i[0][2]),
            iyy=repr(i[1][1]),
            iyz=repr(i[1][2]),
            izz=repr(i[2][2]),
        )
        parent = lk.name
    if write_tip:
        joint(f"{parent}_to_{arm.tip}", "fixed", parent, arm.tip, arm.end_point, ZERO3)
        ET.SubElement(robot, "link", name=arm.tip)
    ET.indent(robot)
    atomic_write(path, lambda f: ET.ElementTree(robot).write(f, encoding="utf-8", xml_declaration=True))
    return path
