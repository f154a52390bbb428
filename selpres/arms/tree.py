"""A serial chain cut from any robot tree: the chain, the held joints and the merged bodies, for every reader.

A reader (``selpres.arms.urdf`` for URDF; an MJCF or SDF reader the same way) parses its file into a *tree*: links
and joints as plain values (:class:`Tree`), and hands it to :func:`cut_chain`, which picks the chain from link
``base`` to link ``tip`` (defaults: the root, and the one path that leads to revolute/continuous joints, refused with
the branch named when there are several). The chain's revolute and continuous joints are *modelled* (``joints`` may
name a subset); every other joint is *held*: fixed joints as always, prismatic joints, off-chain and unlisted joints
at ``hold[name]`` (default 0, or the nearest limit when 0 lies outside), a mimic joint at its master's held value
times multiplier plus offset. Held bodies merge rigidly into the body they hang from (masses, centres of mass and
inertias by the parallel-axis rule, as Pinocchio's ``buildReducedModel`` does); bodies above ``base`` never move
and drop out. A mimic on a fixed joint does nothing and is ignored; one that couples a modelled joint is refused
with both names. ``arm.source`` records the file, the modelled and the held joints (with their values).

Frames: the wrench k of eq. (4) is expressed in the frame of the link the first modelled joint hangs from (the
arm's ``base``; an explicit ``base`` link when given); its end point is the origin of the ``tip`` link (default:
follow the fixed joints after the last modelled joint while there is exactly one).

Errors are :class:`TreeError` (one line: the file, the element, the problem; element names are URDF's, which MJCF
shares: ``<link>``/``<body>`` aside); a reader re-raises them as its own file error.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Protocol

from selpres.arms.kinematics import Link, Mat3, Vec3, _mat_mul, _mat_vec, _transpose, check_link
from selpres.arms.serial import SerialArm
from selpres.arms.urdf_read import MODELLED, ONE_DOF, _add, _Joint, _Pose
from selpres.errors import ConfigError, FileError

log = logging.getLogger(__name__)

Joint, Pose = _Joint, _Pose  # a tree's joints and rigid transforms (defined with the URDF reader, shared by all)


class TreeError(FileError):
    """A robot tree whose chain cannot be cut: the file, the element and the problem."""


class Tree(Protocol):
    """What :func:`cut_chain` reads from a parsed robot file (``selpres.arms.urdf_read._Reader`` is one)."""

    path: object  # the file, for errors and ``arm.source``
    name: str  # the robot's name
    links: Mapping[str, object]  # link name -> anything (only the names are read)
    joints: Mapping[str, Joint]  # joint name -> joint (kind, parent, child, origin, axis, limits, mimic, ...)
    parent_of: Mapping[str, str]  # child link -> the joint it hangs from
    children: Mapping[str, list[str]]  # link -> the joints hanging from it, in file order

    def child(self, joint: str) -> str: ...

    def path_up(self, link: str, top: str) -> list[str] | None:
        """The joints from ``top`` down to ``link`` (None: ``link`` is not below ``top``)."""

    def inertial(self, link: str) -> tuple[float, Vec3, Mat3] | None:
        """(mass, centre of mass, inertia about it) in the link's frame, or None when the file gives none."""


def _chain_path(reader: Tree, base: str, tip: str | None) -> list[str]:
    """The joints from ``base`` to ``tip``, or (no tip) along the one path that leads to modellable joints."""
    if tip is not None:
        path = reader.path_up(tip, base)
        if path is None:
            raise TreeError(reader.path, f'tip="{tip}"', f"is not a link below the base link {base!r}")
        return path
    leads: dict[str, bool] = {}  # link -> a modellable joint lies below it (one pass, deepest first)

    def below(link: str) -> bool:
        stack, order = [link], []
        while stack:
            x = stack.pop()
            order.append(x)
            stack.extend(reader.child(j) for j in reader.children[x] if reader.child(j) not in leads)
        for x in reversed(order):
            js = reader.children[x]
            leads[x] = any(_modellable(reader.joints[j]) or leads[reader.child(j)] for j in js)
        return leads[link]

    below(base)
    path, link = [], base
    while True:
        onward = [j for j in reader.children[link] if _modellable(reader.joints[j]) or leads[reader.child(j)]]
        if len(onward) > 1:
            raise TreeError(
                reader.path,
                f'<link name="{link}">',
                f"branches into joints {onward[:4]}, each leading to revolute joints: choose one chain with "
                "robot.tip=<link> (and robot.base=<link>)",
            )
        if not onward:
            return path
        path.append(onward[0])
        link = reader.child(onward[0])


def _modellable(j: _Joint) -> bool:
    return j.kind in MODELLED and j.mimic is None


def _held_values(reader: Tree, modelled: set[str], hold: dict[str, float]) -> dict[str, float]:
    """Every held one-dof joint's value: ``hold``, a mimic's master's value, else 0 (or its nearest limit)."""
    for name, value in hold.items():
        if name not in reader.joints:
            raise TreeError(reader.path, f"robot.hold.{name}", "names no <joint> of the file")
        if name in modelled:
            raise TreeError(reader.path, f"robot.hold.{name}", "is a modelled joint: hold it or model it, not both")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise TreeError(reader.path, f"robot.hold.{name}", f"{value!r}: a finite position (rad or m)")
    values: dict[str, float] = {}
    for name, j in reader.joints.items():
        if j.mimic is not None and j.kind != "fixed":
            master = j.mimic[0]
            if master not in reader.joints:
                raise TreeError(reader.path, f'<joint name="{name}"> <mimic>', f"joint={master!r} names no <joint>")
            if name in modelled or master in modelled:
                raise TreeError(
                    reader.path,
                    f'<joint name="{name}"> <mimic joint="{master}">',
                    "couples a modelled joint: selpres needs independent joints; list only independent ones in "
                    "robot.joints (the others are held)",
                )
        if j.kind not in ONE_DOF or name in modelled:
            continue
        lo, hi = j.limits or (-math.inf, math.inf)
        values[name] = float(hold.get(name, min(max(0.0, lo), hi)))
    for name, j in reader.joints.items():  # mimics follow their (held) masters unless held explicitly
        if j.mimic is not None and name in values and name not in hold:
            master, mult, off = j.mimic
            values[name] = mult * values.get(master, 0.0) + off
    return values


def _body(reader: Tree, top: str, stop: set[str], held: dict[str, float]) -> tuple[list, dict[str, _Pose]]:
    """Links rigidly attached to ``top`` (through fixed and held joints, never a modelled one: ``stop``) with
    their poses in top's frame, and the poses of the ``stop`` joints' origins met on the way."""
    out, ends, stack = [], {}, [(top, _Pose())]
    while stack:
        link, pose = stack.pop()
        out.append((link, pose))
        for name in reader.children[link]:
            j = reader.joints[name]
            if name in stop:
                ends[name] = pose.then(j.origin)
            else:
                stack.append((j.child, pose.then(j.at(held.get(name, 0.0)))))
    return out, ends


def _merge(reader: Tree, parts: list, moved_by: str) -> tuple[float, Vec3, Mat3]:
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
        raise TreeError(
            reader.path,
            f'<link name="{parts[0][0]}">',
            f"has no <inertial> but joint {moved_by!r} moves it, so its mass matters: add <inertial> (mass 0 to "
            "declare it massless)",
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


def cut_chain(
    tree: Tree,
    *,
    gravity: Vec3 = (0.0, 0.0, -9.81),
    base: str | None = None,
    tip: str | None = None,
    joints: tuple[str, ...] | list[str] | None = None,
    hold: Mapping[str, float] | None = None,
) -> SerialArm:
    """The serial arm of ``tree``'s chain from link ``base`` to link ``tip`` (see the module docstring);
    ``gravity`` in the root link's frame, ``joints`` restricts the modelled joints, ``hold`` sets held joints'
    positions. Raises TreeError naming ``tree.path`` and the element (a reader re-raises it as its own error)."""
    reader, path, hold = tree, tree.path, dict(hold or {})
    roots = [n for n in reader.links if n not in reader.parent_of]
    if len(roots) != 1:
        problem = (
            "every link is some joint's child: a closed loop"
            if not roots
            else f"links {roots[:3]} have no parent joint: the file holds more than one tree"
        )
        raise TreeError(reader.path, "<robot>", problem)
    if not reader.joints:
        raise TreeError(reader.path, "<robot>", "has no <joint>: nothing moves")
    for name, value in (("robot.base", base), ("robot.tip", tip)):
        if value is not None and value not in reader.links:
            raise TreeError(reader.path, f"{name}={value!r}", "names no <link> of the file")
    top = base if base is not None else roots[0]
    path_joints = _chain_path(reader, top, tip)
    on_path = [j for j in path_joints if reader.joints[j].kind in MODELLED]
    if joints is not None:
        bad = [j for j in joints if j not in on_path]
        if bad or len(set(joints)) != len(joints):
            raise TreeError(
                reader.path,
                f"robot.joints={list(joints)}",
                f"names {bad or 'a joint twice'}: give distinct revolute joints of the chain {on_path}",
            )
    chain = [j for j in on_path if (joints is None or j in joints)]
    if not chain:
        held = [n for n, j in reader.joints.items() if j.kind != "fixed"][:4]
        why = f" (joints {held} would be held: selpres models revolute joints)" if held else ""
        raise TreeError(reader.path, "<robot>", f"has no revolute or continuous joint on the chain from {top!r}{why}")
    modelled = set(chain)
    held = _held_values(reader, modelled, dict(hold))
    # the base frame: the link joint 1 hangs from (or the base named), and the root's frame in it
    arm_base = base if base is not None else reader.joints[chain[0]].parent
    root_to_base = _Pose()
    for j in reader.path_up(arm_base, roots[0]):
        root_to_base = root_to_base.then(reader.joints[j].at(held.get(j, 0.0)))
    _, ends = _body(reader, arm_base, {chain[0]}, held)
    if chain[0] not in ends:  # a base below joint 1's parent: the first joint's origin is not rigid to it
        raise TreeError(reader.path, f"robot.base={arm_base!r}", f"is not rigidly attached to joint {chain[0]!r}")
    origins, links = [ends[chain[0]]], []
    for i, name in enumerate(chain):
        j = reader.joints[name]
        parts, ends = _body(reader, j.child, set(chain[i + 1 : i + 2]), held)
        if i + 1 < len(chain):
            origins.append(ends[chain[i + 1]])
        mass, com, inertia = _merge(reader, parts, name)
        try:
            link = Link(j.child, mass, com, inertia, name, origins[i].xyz, origins[i].rot, j.axis, j.limits)
            links.append(check_link(replace(link, velocity=j.velocity, effort=j.effort), "link"))
        except ConfigError as e:
            raise TreeError(reader.path, f'<joint name="{name}">', str(e)) from None
    _check_not_empty(reader, links)
    end, tip_name = _tip(reader, parts, tip)
    gravity_base = _mat_vec(_transpose(root_to_base.rot), gravity)
    notes = _notes(reader, chain, held)
    source = {"file": str(path), "modelled": chain, "held": held, "notes": notes}
    arm = SerialArm(links, gravity_base, end, name=reader.name, base=arm_base, tip=tip_name, source=source)
    log.info("%s: modelled joints %s; held %s", path, chain, {k: round(v, 6) for k, v in held.items()} or "none")
    for note in notes:
        log.info("%s: %s", path, note)
    if any(reader.joints[j].dynamics for j in reader.joints):
        listed = ", ".join(f"{j} ({reader.joints[j].dynamics})" for j in reader.joints if reader.joints[j].dynamics)
        log.warning("%s: <dynamics> ignored (selpres simulates the rigid-body eq. (4) only): %s", path, listed)
    return arm


def _check_not_empty(reader: Tree, links: list[Link]) -> None:
    """Refuse joints whose torque is identically 0: they move no mass and no inertia (nothing to learn)."""
    empty, mass, inertia = [], 0.0, 0.0
    for lk in reversed(links):
        mass += lk.mass
        inertia += sum(abs(x) for row in lk.inertia for x in row)
        if mass == 0.0 and inertia == 0.0:
            empty.append(lk.joint)
    if len(empty) == len(links):
        raise TreeError(
            reader.path,
            "<inertial>",
            f"every body the joints {[lk.joint for lk in links]} move has mass 0 and inertia 0: every torque "
            "would be 0 (give the links their <inertial> mass and inertia)",
        )
    if empty:
        raise TreeError(
            reader.path,
            f'<joint name="{empty[-1]}">',
            f"joints {empty[::-1]} move no mass and no inertia, so their torques are always 0: leave them out of "
            "robot.joints (held) or give their links an <inertial>",
        )


def _notes(reader: Tree, chain: list[str], held: dict[str, float]) -> list[str]:
    """What the file says that selpres reads its own way (logged once per load, recorded in arm.source)."""
    notes = []
    zero = [n for n, j in reader.joints.items() if j.kind == "revolute" and j.limits is None and n in chain]
    if zero:
        notes.append(f"joints {zero} have <limit lower = upper> (or none): read as 'no position limits'")
    fixed_mimic = [n for n, j in reader.joints.items() if j.kind == "fixed" and j.mimic is not None]
    if fixed_mimic:
        notes.append(f"<mimic> on fixed joints {fixed_mimic} ignored (a fixed joint does not move)")
    prismatic = [n for n in held if reader.joints[n].kind == "prismatic"]
    if prismatic:
        notes.append(f"prismatic joints {prismatic} held (selpres models revolute joints)")
    return notes


def _tip(reader: Tree, attached_parts: list, tip: str | None) -> tuple[Vec3, str]:
    """(end point in the last body's frame, tip link name)."""
    attached = dict(attached_parts)
    last = attached_parts[0][0]
    if tip is not None:
        if tip not in attached:
            raise TreeError(
                reader.path,
                f'tip="{tip}"',
                f"is not a link rigidly attached to the last modelled link {last!r} (those are {sorted(attached)[:8]})",
            )
        return attached[tip].xyz, tip
    link, pose = last, _Pose()
    while len(reader.children[link]) == 1 and reader.joints[reader.children[link][0]].kind == "fixed":
        j = reader.joints[reader.children[link][0]]
        pose = pose.then(j.origin)
        link = j.child
    return pose.xyz, link
