"""URDF in and out for ``selpres.arms.serial.SerialArm``: any serial chain of revolute joints, 1:1.

``load_urdf`` reads a chain of ``revolute``/``continuous`` joints; ``fixed`` joints are merged into the
body they hang from (masses, centres of mass and inertias combined by the parallel-axis rule, as Pinocchio
and MuJoCo do), so sensor or flange frames cost nothing. Anything else is refused with an error naming the
file and the element: prismatic/floating/planar or mimic joints, branches that lead to two moving joints,
closed loops, joints naming missing links, moving bodies without an <inertial>, bad numbers.

Frames: the wrench k of eq. (4) is expressed in the frame of the link the first moving joint hangs from
(the arm's ``base``); its end point is the origin of the ``tip`` link (default: follow the fixed joints
after the last moving joint while there is exactly one). URDF stores no gravity; tools assume g along −z of
the root link, and so does ``load_urdf`` (magnitude ``g``). ``to_urdf`` therefore writes a root link
``world`` turned so that the arm's gravity points along its −z whenever it does not already (the paper's
arm has gravity along −y), and the magnitude in a comment: Pinocchio, MuJoCo or ``load_urdf`` then load
exactly the dynamics selpres simulates.
"""

from __future__ import annotations

import logging
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from selpres.arms.kinematics import (
    IDENTITY,
    ZERO3,
    Link,
    Mat3,
    Vec3,
    _mat_mul,
    _mat_vec,
    _transpose,
    check_link,
    matrix_rpy,
    rpy_matrix,
)
from selpres.arms.serial import SerialArm
from selpres.errors import ConfigError, FileError
from selpres.storage import atomic_write

log = logging.getLogger(__name__)
MOVING = ("revolute", "continuous")
REFUSED = {"prismatic": "a sliding joint", "floating": "a free-floating base", "planar": "a planar joint"}


class UrdfError(FileError):
    """A URDF that selpres cannot simulate: one line naming the file, the element and the problem."""


@dataclass(frozen=True)
class _Pose:
    """A rigid transform: rotation ``rot`` then translation ``xyz`` (x' = rot x + xyz)."""

    rot: Mat3 = IDENTITY
    xyz: Vec3 = ZERO3

    def then(self, inner: _Pose) -> _Pose:
        """self ∘ inner: ``inner`` expressed in self's parent frame."""
        return _Pose(_mat_mul(self.rot, inner.rot), _add(_mat_vec(self.rot, inner.xyz), self.xyz))


def _add(a, b) -> Vec3:
    return tuple(x + y for x, y in zip(a, b))


# ------------------------------------------------------------------------------------------------- reading
class _Reader:
    """One URDF file's links and joints, with errors that name the file and the element."""

    def __init__(self, path: Path):
        self.path = path
        if not path.is_file():
            raise UrdfError(path, "file", "not found (robot.path must name a URDF file)")
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError as e:
            raise UrdfError(path, "XML", f"not well-formed ({e})") from None
        if root.tag != "robot":
            raise UrdfError(path, f"<{root.tag}>", "the root element must be <robot>")
        self.name = root.get("name", path.stem)
        self.links: dict[str, ET.Element] = {}
        for el in root.findall("link"):
            name = self.attr(el, "name", "<link>")
            if name in self.links:
                raise UrdfError(path, f'<link name="{name}">', "defined twice")
            self.links[name] = el
        self.joints: dict[str, ET.Element] = {}
        self.parent_of: dict[str, str] = {}  # child link -> joint
        self.children: dict[str, list[str]] = {n: [] for n in self.links}  # link -> joints, document order
        for el in root.findall("joint"):
            name = self.attr(el, "name", "<joint>")
            where = f'<joint name="{name}">'
            if name in self.joints:
                raise UrdfError(path, where, "defined twice")
            kind = self.attr(el, "type", where)
            if kind in REFUSED:
                raise UrdfError(
                    path,
                    where,
                    f"type {kind!r} ({REFUSED[kind]}) is not supported: selpres "
                    "simulates chains of revolute joints (revolute, continuous; fixed joints are "
                    "merged)",
                )
            if kind not in (*MOVING, "fixed"):
                raise UrdfError(path, where, f"unknown type {kind!r}: expected revolute, continuous or fixed")
            if el.find("mimic") is not None:
                raise UrdfError(path, where, "<mimic> couples joints; selpres needs independent joints")
            parent, child = (
                self.attr(self.one(el, tag, where), "link", f"{where} <{tag}>") for tag in ("parent", "child")
            )
            for tag, link in (("parent", parent), ("child", child)):
                if link not in self.links:
                    raise UrdfError(path, where, f"<{tag} link={link!r}> names a link that no <link> defines")
            if child in self.parent_of:
                raise UrdfError(
                    path,
                    f'<link name="{child}">',
                    f"is the child of joints "
                    f"{self.parent_of[child]!r} and {name!r}: a closed loop (selpres takes "
                    "serial chains)",
                )
            self.joints[name] = el
            self.parent_of[child] = name
            self.children[parent].append(name)

    # -- small parsers ---------------------------------------------------------------------------------------
    def attr(self, el: ET.Element, key: str, where: str) -> str:
        value = el.get(key)
        if value is None:
            raise UrdfError(self.path, where, f"missing attribute {key!r}")
        return value

    def one(self, el: ET.Element, tag: str, where: str) -> ET.Element:
        found = el.find(tag)
        if found is None:
            raise UrdfError(self.path, where, f"missing <{tag}>")
        return found

    def numbers(self, text: str | None, n: int, where: str, default: tuple[float, ...]) -> tuple[float, ...]:
        if text is None:
            return default
        try:
            values = tuple(float(x) for x in text.split())
        except ValueError:
            values = ()
        if len(values) != n or not all(math.isfinite(v) for v in values):
            raise UrdfError(
                self.path, where, f"{text!r} is not " + ("a finite number" if n == 1 else f"{n} finite numbers")
            )
        return values

    def origin(self, el: ET.Element, where: str) -> _Pose:
        """An element's <origin xyz rpy> (identity when absent, as the URDF spec says)."""
        o = el.find("origin")
        if o is None:
            return _Pose()
        xyz = self.numbers(o.get("xyz"), 3, f"{where} <origin xyz>", ZERO3)
        rpy = self.numbers(o.get("rpy"), 3, f"{where} <origin rpy>", ZERO3)
        return _Pose(rpy_matrix(rpy), xyz)

    def inertial(self, link: str) -> tuple[float, Vec3, Mat3] | None:
        """(mass, com, inertia about the com) of a link in its own frame; None without <inertial>."""
        el = self.links[link].find("inertial")
        if el is None:
            return None
        where = f'<link name="{link}"> <inertial>'
        pose = self.origin(el, where)
        mass_el = self.one(el, "mass", where)
        (mass,) = self.numbers(self.attr(mass_el, "value", f"{where} <mass>"), 1, f"{where} <mass value>", ())
        inertia_el = self.one(el, "inertia", where)
        v = {
            k: self.numbers(self.attr(inertia_el, k, f"{where} <inertia>"), 1, f"{where} <inertia {k}>", ())[0]
            for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
        }
        tensor = ((v["ixx"], v["ixy"], v["ixz"]), (v["ixy"], v["iyy"], v["iyz"]), (v["ixz"], v["iyz"], v["izz"]))
        try:
            check_link(Link(link, mass, pose.xyz, tensor), "inertial")
        except ConfigError as e:
            raise UrdfError(self.path, f'<link name="{link}">', str(e)) from None
        return mass, pose.xyz, _mat_mul(pose.rot, _mat_mul(tensor, _transpose(pose.rot)))


def _moving_below(reader: _Reader, joint: str) -> list[str]:
    """The moving joints in the subtree that starts with ``joint`` (itself included)."""
    out, stack = [], [joint]
    while stack:
        j = stack.pop()
        el = reader.joints[j]
        if el.get("type") in MOVING:
            out.append(j)
        stack.extend(reader.children[el.find("child").get("link")])
    return out


def _body(reader: _Reader, top: str) -> list[tuple[str, _Pose]]:
    """Links rigidly attached to ``top`` through fixed joints (``top`` first; the chain's fixed links and
    fixed side branches alike), with their poses in top's frame. Moving joints end a body."""
    out, stack = [], [(top, _Pose())]
    while stack:
        link, pose = stack.pop()
        out.append((link, pose))
        for j in reader.children[link]:
            el = reader.joints[j]
            if el.get("type") == "fixed":
                child = el.find("child").get("link")
                stack.append((child, pose.then(reader.origin(el, f'<joint name="{j}">'))))
    return out


def _merge(reader: _Reader, parts: list[tuple[str, _Pose]], moved_by: str) -> tuple[float, Vec3, Mat3]:
    """Mass, centre of mass and inertia about it of rigidly joined links, in the first one's frame."""
    items = []
    for link, pose in parts:
        inertial = reader.inertial(link)
        if inertial is not None:
            m, c, inertia = inertial
            items.append(
                (m, _add(_mat_vec(pose.rot, c), pose.xyz), _mat_mul(pose.rot, _mat_mul(inertia, _transpose(pose.rot))))
            )
    if not items:
        raise UrdfError(
            reader.path,
            f'<link name="{parts[0][0]}">',
            f"has no <inertial> but joint "
            f"{moved_by!r} moves it, so its mass matters: add <inertial> (mass 0 to declare it "
            "massless)",
        )
    mass = sum(m for m, _, _ in items)
    com = tuple(sum(m * c[i] for m, c, _ in items) / mass for i in range(3)) if mass > 0 else items[0][1]
    total = [[0.0] * 3 for _ in range(3)]
    for m, c, inertia in items:
        d = tuple(c[i] - com[i] for i in range(3))
        dd = sum(x * x for x in d)
        for r in range(3):
            for s in range(3):
                total[r][s] += inertia[r][s] + m * ((dd if r == s else 0.0) - d[r] * d[s])
    return mass, com, tuple(tuple(row) for row in total)


def load_urdf(path: str | Path, *, g: float = 9.81, tip: str | None = None) -> SerialArm:
    """The serial arm of a URDF file; gravity ``g`` (m/s²) along −z of the root link, as URDF tools assume.
    ``tip`` names the link whose origin is the wrench's end point (see the module docstring)."""
    reader = _Reader(Path(path))
    roots = [n for n in reader.links if n not in reader.parent_of]
    if len(roots) != 1:
        problem = (
            "every link is some joint's child: a closed loop"
            if not roots
            else f"links {roots[:3]} have no parent joint: the file holds more than one tree"
        )
        raise UrdfError(reader.path, "<robot>", problem)
    # walk down the one path that leads to moving joints
    chain: list[str] = []  # moving joints, base to tip
    poses: list[_Pose] = []  # each moving joint's origin in the previous body's frame
    link, pose_in_body = roots[0], _Pose()
    root_to_base = _Pose()
    while True:
        onward = [j for j in reader.children[link] if _moving_below(reader, j)]
        if len(onward) > 1:
            raise UrdfError(
                reader.path,
                f'<link name="{link}">',
                f"branches into joints {onward[:3]}, each leading to moving joints: selpres takes serial chains",
            )
        if not onward:
            break
        j = onward[0]
        el = reader.joints[j]
        step = reader.origin(el, f'<joint name="{j}">')
        if el.get("type") == "fixed":
            pose_in_body = pose_in_body.then(step)
        else:
            if not chain:  # the base frame: the link joint 1 hangs from
                root_to_base, pose_in_body = pose_in_body, _Pose()
                base = link
            chain.append(j)
            poses.append(pose_in_body.then(step))
            pose_in_body = _Pose()
        link = el.find("child").get("link")
    if not chain:
        raise UrdfError(reader.path, "<robot>", "has no revolute or continuous joint")
    bodies = [reader.joints[j].find("child").get("link") for j in chain]
    links = []
    for i, (j, body) in enumerate(zip(chain, bodies)):
        el = reader.joints[j]
        where = f'<joint name="{j}">'
        axis = reader.numbers(
            (el.find("axis").get("xyz") if el.find("axis") is not None else None),
            3,
            f"{where} <axis xyz>",
            (1.0, 0.0, 0.0),
        )
        limits = None
        limit_el = el.find("limit")
        if el.get("type") == "revolute" and limit_el is not None and "lower" in limit_el.attrib:
            lower = reader.numbers(limit_el.get("lower"), 1, f"{where} <limit lower>", ())[0]
            upper = reader.numbers(limit_el.get("upper"), 1, f"{where} <limit upper>", (0.0,))[0]
            if not lower < upper:
                raise UrdfError(reader.path, where, f"<limit lower={lower} upper={upper}>: need lower < upper")
            limits = (lower, upper)
        dyn = el.find("dynamics")
        if dyn is not None and any(float(dyn.get(k, "0") or 0) != 0.0 for k in ("damping", "friction")):
            log.warning(
                "%s: %s <dynamics %s> ignored: selpres simulates the rigid-body eq. (4) only",
                reader.path,
                where,
                " ".join(f'{k}="{v}"' for k, v in dyn.attrib.items()),
            )
        mass, com, inertia = _merge(reader, _body(reader, body), j)
        try:
            links.append(
                check_link(
                    Link(
                        body,
                        mass,
                        com,
                        inertia,
                        joint=j,
                        xyz=poses[i].xyz,
                        rotation=poses[i].rot,
                        axis=axis,
                        limits=limits,
                    ),
                    "link",
                )
            )
        except ConfigError as e:
            raise UrdfError(reader.path, where, str(e)) from None
    end, tip_name = _tip(reader, bodies[-1], tip)
    gravity = _mat_vec(_transpose(root_to_base.rot), (0.0, 0.0, -g))
    return SerialArm(links, gravity, end, name=reader.name, base=base, tip=tip_name)


def _tip(reader: _Reader, last: str, tip: str | None) -> tuple[Vec3, str]:
    """(end point in the last body's frame, tip link name)."""
    attached = dict(_body(reader, last))
    if tip is not None:
        if tip not in attached:
            raise UrdfError(
                reader.path,
                f'tip="{tip}"',
                f"is not a link fixed to the last moving link {last!r} (those are {sorted(attached)})",
            )
        return attached[tip].xyz, tip
    link, pose = last, _Pose()
    while len(reader.children[link]) == 1 and reader.joints[reader.children[link][0]].get("type") == "fixed":
        j = reader.children[link][0]
        pose = pose.then(reader.origin(reader.joints[j], f'<joint name="{j}">'))
        link = reader.joints[j].find("child").get("link")
    return pose.xyz, link


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
            f"root link (selpres: load_urdf(path, g={g!r})). The wrench of eq. (4) is expressed in link "
            f"{arm.base!r} and acts at the origin of link {arm.tip!r}. Effort and velocity limits are not part "
            "of selpres's model: written as 0 (= not given). "
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
            ET.SubElement(el, "limit", lower=repr(lk.limits[0]), upper=repr(lk.limits[1]), effort="0", velocity="0")
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
