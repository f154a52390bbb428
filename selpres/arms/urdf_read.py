"""URDF reading for ``selpres.arms.urdf``: a file's links and joints as plain values, every error one line naming
the file, the element and the attribute (``UrdfError``), with the size and ``<!ENTITY`` guards applied before
any parsing. What the elements *mean* for an arm (chains, held joints, merged bodies) is ``urdf.py``'s.
"""

from __future__ import annotations

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
    rpy_matrix,
)
from selpres.errors import ConfigError, FileError, not_a_file

MODELLED = ("revolute", "continuous")
ONE_DOF = ("revolute", "continuous", "prismatic")
KINDS = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
MAX_BYTES = 32 * 2**20  # 32 MiB: the biggest robot description in example-robot-data is ~0.3 MB


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


# of the largest principal moment: published measured parameter sets break the triangle inequality by less (the
# PUMA 560's link 3 of Armstrong et al., 0.066 + 0.0125 < 0.086, by 8.7 %); the issue's 0.1 + 0.1 < 5 by 96 %
TRIANGLE_TOLERANCE = 0.10


def _impossible(tensor: Mat3) -> str | None:
    """Why a body of positive mass cannot have this inertia about its centre of mass (None: it can): its principal
    moments must each be at most the sum of the other two (a rigid body's triangle inequality; MuJoCo refuses the
    same). A massless link's tensor is left alone: a lumped parameter, as the PUMA 560's link 1 (0, 0.35, 0), which
    Armstrong et al. give without a mass. Negative moments are check_link's (positive semi-definite)."""
    import torch

    a, b, c = (float(x) for x in torch.linalg.eigvalsh(torch.tensor(tensor, dtype=torch.float64)))
    if c - a - b > TRIANGLE_TOLERANCE * c:
        return (
            f"is not a rigid body's: its principal moments {a:g}, {b:g}, {c:g} kg m^2 break the triangle inequality "
            f"({a:g} + {b:g} < {c:g}; allowed up to {TRIANGLE_TOLERANCE:.0%} of the largest)"
        )
    return None


def _add(a, b) -> Vec3:
    return tuple(x + y for x, y in zip(a, b))


def _axis_turn(axis: Vec3, q: float) -> Mat3:
    """Rot(axis, q) by Rodrigues' formula (``axis`` a unit vector)."""
    c, s = math.cos(q), math.sin(q)
    x, y, z = axis
    return (
        (c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s),
        (y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s),
        (z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)),
    )


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: _Pose
    axis: Vec3
    limits: tuple[float, float] | None
    velocity: float | None
    effort: float | None
    mimic: tuple[str, float, float] | None  # (master, multiplier, offset)
    dynamics: str  # "damping=... friction=..." when non-zero, else ""

    def at(self, q: float) -> _Pose:
        """The child's frame in the parent's at position q (held joints; 0 for fixed/floating/planar)."""
        if self.kind in ("revolute", "continuous") and q:
            return self.origin.then(_Pose(_axis_turn(self.axis, q)))
        if self.kind == "prismatic" and q:
            return self.origin.then(_Pose(IDENTITY, tuple(a * q for a in self.axis)))
        return self.origin


# ------------------------------------------------------------------------------------------------- reading
class _Reader:
    """One URDF file's links and joints, with errors that name the file, the element and the attribute."""

    def __init__(self, path: Path):
        self.path = path
        if not path.is_file():
            raise UrdfError(path, "file", f"{not_a_file(path)} (robot.path must name a URDF file)")
        try:
            size = path.stat().st_size
            data = path.read_bytes() if size <= MAX_BYTES else b""
        except OSError as e:  # removed or made unreadable since it was checked
            raise UrdfError(path, "file", f"cannot be read ({e.strerror or e})") from None
        if size > MAX_BYTES:
            raise UrdfError(
                path,
                "file",
                f"{size / 2**20:.0f} MiB, more than the {MAX_BYTES >> 20} MiB a robot description may have here "
                "(real ones are under 1 MB; meshes live in their own files): is this the URDF?",
            )
        if b"<!ENTITY" in data:
            raise UrdfError(path, "<!ENTITY>", "entity declarations are refused (URDF uses none; XML bomb guard)")
        try:
            root = ET.fromstring(data)
        except ET.ParseError as e:
            raise UrdfError(path, "XML", f"not well-formed ({e})") from None
        if path.suffix == ".xacro" or any(el.tag.startswith("{") and "xacro" in el.tag for el in root.iter()):
            raise UrdfError(path, "xacro", f"this is a xacro macro file: run `xacro {path.name} > robot.urdf` first")
        if root.tag != "robot":
            raise UrdfError(path, f"<{root.tag}>", "the root element must be <robot>")
        self.name = root.get("name", path.stem)
        self.links: dict[str, ET.Element] = {}
        for el in root.findall("link"):
            name = self.attr(el, "name", "<link>")
            if name in self.links:
                raise UrdfError(path, f'<link name="{name}">', "defined twice")
            self.links[name] = el
        if not self.links:
            raise UrdfError(path, "<robot>", "has no <link>: an empty robot description")
        self.joints: dict[str, _Joint] = {}
        self.parent_of: dict[str, str] = {}  # child link -> joint
        self.children: dict[str, list[str]] = {n: [] for n in self.links}  # link -> joints, document order
        for el in root.findall("joint"):
            j = self._joint(el)
            if j.child in self.parent_of:
                raise UrdfError(
                    path,
                    f'<link name="{j.child}">',
                    f"is the child of joints {self.parent_of[j.child]!r} and {j.name!r}: a closed loop "
                    "(selpres takes trees)",
                )
            self.joints[j.name] = j
            self.parent_of[j.child] = j.name
            self.children[j.parent].append(j.name)
        self._inertials: dict[str, tuple[float, Vec3, Mat3] | None] = {}

    def _joint(self, el: ET.Element) -> _Joint:
        name = self.attr(el, "name", "<joint>")
        where = f'<joint name="{name}">'
        if name in getattr(self, "joints", {}):
            raise UrdfError(self.path, where, "defined twice")
        kind = self.attr(el, "type", where)
        if kind not in KINDS:
            raise UrdfError(self.path, where, f"unknown type {kind!r}: expected one of {', '.join(KINDS)}")
        parent, child = (self.attr(self.one(el, tag, where), "link", f"{where} <{tag}>") for tag in ("parent", "child"))
        for tag, link in (("parent", parent), ("child", child)):
            if link not in self.links:
                raise UrdfError(self.path, where, f"<{tag} link={link!r}> names a link that no <link> defines")
        axis_el = el.find("axis")
        axis = self.numbers(None if axis_el is None else axis_el.get("xyz"), 3, f"{where} <axis xyz>", (1.0, 0.0, 0.0))
        norm = math.sqrt(sum(a * a for a in axis))
        if kind in ONE_DOF and not norm > 0:
            raise UrdfError(self.path, f"{where} <axis xyz>", f"{axis}: a non-zero direction")
        limits = velocity = effort = None
        lim = el.find("limit")
        if lim is not None:
            get = lambda k: self.numbers(lim.get(k), 1, f"{where} <limit {k}>", (0.0,))[0]
            lower, upper, velocity, effort = (get(k) for k in ("lower", "upper", "velocity", "effort"))
            if kind in ("revolute", "prismatic") and lower > upper:
                raise UrdfError(self.path, where, f"<limit lower={lower} upper={upper}>: need lower < upper")
            limits = (lower, upper) if kind in ("revolute", "prismatic") and lower < upper else None
            velocity, effort = (v if v > 0 else None for v in (velocity, effort))  # 0: not given
        mimic = None
        mim = el.find("mimic")
        if mim is not None:
            where_m = f"{where} <mimic>"
            mimic = (
                self.attr(mim, "joint", where_m),
                self.numbers(mim.get("multiplier"), 1, f"{where_m} multiplier", (1.0,))[0],
                self.numbers(mim.get("offset"), 1, f"{where_m} offset", (0.0,))[0],
            )
        dynamics = ""
        dyn = el.find("dynamics")
        if dyn is not None:
            keys = ("damping", "friction")  # the URDF spec's two; others (Gazebo's) are not read
            values = {k: self.numbers(dyn.get(k), 1, f"{where} <dynamics {k}>", (0.0,))[0] for k in keys}
            dynamics = " ".join(f"{k}={v:g}" for k, v in values.items() if v != 0.0)
        return _Joint(
            name,
            kind,
            parent,
            child,
            self.origin(el, where),
            tuple(a / norm for a in axis) if norm > 0 else axis,
            limits,
            velocity,
            effort,
            mimic,
            dynamics,
        )

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
        if link not in self._inertials:
            self._inertials[link] = self._read_inertial(link)
        return self._inertials[link]

    def _read_inertial(self, link: str) -> tuple[float, Vec3, Mat3] | None:
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
        if mass > 0 and (broken := _impossible(tensor)):
            said = ", ".join(f"{k}={v[k]:g}" for k in ("ixx", "iyy", "izz"))
            raise UrdfError(self.path, f'<link name="{link}"> <inertia {said}>', broken)
        return mass, pose.xyz, _mat_mul(pose.rot, _mat_mul(tensor, _transpose(pose.rot)))

    def child(self, joint: str) -> str:
        return self.joints[joint].child

    def path_up(self, link: str, top: str) -> list[str] | None:
        """The joints from ``top`` down to ``link`` (None when ``link`` is not below ``top``)."""
        out = []
        while link != top:
            if link not in self.parent_of:
                return None
            out.append(self.parent_of[link])
            link = self.joints[out[-1]].parent
        return out[::-1]
