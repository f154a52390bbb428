"""URDF import/export: round trips give the same dynamics, fixed joints merge as rigid bodies do, and every
file selpres cannot simulate is refused with an error naming the file and the element."""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import pickle
import re

import pytest
import test_serial as serial_tests  # tests/ is on sys.path (pytest's rootdir-relative import)
import torch
from test_serial import states

from selpres.arms.kinematics import Link, rot_z, rpy_matrix
from selpres.arms.serial import SerialArm
from selpres.arms.urdf import UrdfError, load_urdf, to_urdf
from selpres.errors import ConfigError

D = torch.float64


def same_dynamics(a: SerialArm, b: SerialArm, tol: float = 1e-12) -> None:
    """Inverse dynamics with a wrench, H and the simulator agree to ``tol`` (absolute, Nm / rad/s²)."""
    q, qd, qdd, k = states(500, a.dof, seed=0)
    assert (a.inverse_dynamics(q, qd, qdd, k) - b.inverse_dynamics(q, qd, qdd, k)).abs().max() <= tol
    assert (a.mass_matrix(q) - b.mass_matrix(q)).abs().max() <= tol
    tau = a.inverse_dynamics(q, qd, qdd, k)
    assert (a.forward_dynamics(q, qd, tau, k) - b.forward_dynamics(q, qd, tau, k)).abs().max() <= 1e3 * tol


def random_arm(seed: int) -> SerialArm:
    """test_serial's random chain of six rigid bodies, with limits on every other joint and its own frame
    names, so that everything a URDF can carry is exercised."""
    arm = serial_tests.random_arm(6, seed)
    links = [dataclasses.replace(lk, limits=(-2.0, 2.5) if i % 2 else None) for i, lk in enumerate(arm.links)]
    return SerialArm(links, arm.gravity_vector, arm.end_point, name="random6", base="mount", tip="tool")


ARMS = {
    "two_link": lambda: SerialArm.two_link(0.42, 3.0, 0.2, 0.26),
    "planar3": lambda: serial_tests.load("planar3"),
    "puma560": lambda: serial_tests.load("puma560"),
    "random6": lambda: random_arm(3),
}


# --------------------------------------------------------------------------------------------- round trip
@pytest.mark.parametrize("name", ARMS)
def test_export_import_round_trip(name, tmp_path):
    arm = ARMS[name]()
    g = math.sqrt(sum(x * x for x in arm.gravity_vector))
    back = load_urdf(to_urdf(arm, tmp_path / f"{name}.urdf"), g=g)
    same_dynamics(arm, back)
    assert back.dof == arm.dof and [lk.name for lk in back.links] == [lk.name for lk in arm.links]
    assert (back.base, back.tip) == (arm.base, arm.tip)
    assert [lk.limits for lk in back.links] == [lk.limits for lk in arm.links]
    assert max(abs(x - y) for x, y in zip(back.gravity_vector, arm.gravity_vector)) <= 1e-14


def test_exported_two_link_arm_hangs_gravity_on_minus_z_of_a_world_root(tmp_path):
    """The paper's gravity (−y) becomes −z of a 'world' root, as URDF tools assume; joints stay continuous."""
    import xml.etree.ElementTree as ET

    path = to_urdf(SerialArm.two_link(0.42, 3.0, 0.2, 0.26), tmp_path / "arm.urdf")
    root = ET.parse(path).getroot()
    world = root.find("joint[@name='world_to_base']")
    assert world is not None and world.get("type") == "fixed"
    rot = rpy_matrix([float(x) for x in world.find("origin").get("rpy").split()])
    assert all(abs(a - b) < 1e-15 for a, b in zip((rot[2][0], rot[2][1], rot[2][2]), (0.0, 1.0, 0.0)))
    assert [j.get("type") for j in root.findall("joint")] == ["fixed", "continuous", "continuous", "fixed"]
    assert load_urdf(path).gravity_vector == (0.0, -9.81, 0.0)


def test_pinocchio_computes_the_same_torques(tmp_path):
    """Optional: only where Pinocchio is installed (it is not a selpres dependency)."""
    pin = pytest.importorskip("pinocchio")
    np = pytest.importorskip("numpy")
    for name in ("two_link", "puma560", "random6"):
        arm = ARMS[name]()
        model = pin.buildModelFromUrdf(str(to_urdf(arm, tmp_path / f"{name}.urdf")))
        data = model.createData()
        model.gravity.linear = np.array([0.0, 0.0, -math.sqrt(sum(x * x for x in arm.gravity_vector))])
        q, qd, qdd, _ = states(20, arm.dof, seed=1)
        for x, v, a, tau in zip(q, qd, qdd, arm.inverse_dynamics(q, qd, qdd)):
            config = []
            for joint, angle in zip(model.joints[1:], x.tolist()):
                # a continuous joint is "unbounded" in Pinocchio, configured by (cos, sin)
                config += [math.cos(angle), math.sin(angle)] if joint.nq == 2 else [angle]
            ref = pin.rnea(model, data, np.array(config), v.numpy(), a.numpy())
            assert np.abs(ref - tau.numpy()).max() <= 1e-9 * max(1.0, np.abs(ref).max())


# ---------------------------------------------------------------------------------- fixed joints merged
HAND = """<?xml version="1.0"?>
<robot name="hand">
  <link name="base"/>
  <joint name="stand_joint" type="fixed"><parent link="base"/><child link="stand"/></joint>
  <link name="stand"><inertial><mass value="50"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>
  </inertial></link>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="a"/>
    <origin xyz="0 0 0.1" rpy="0.3 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="2" effort="5" velocity="1"/>
    <dynamics damping="0" friction="0"/>
  </joint>
  <link name="a"><inertial><origin xyz="0.1 0 0"/><mass value="1.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/></inertial></link>
  <joint name="a_fixed" type="fixed"><parent link="a"/><child link="a2"/>
    <origin xyz="0.2 0 0" rpy="0 0 1.5707963267948966"/></joint>
  <link name="a2"><inertial><origin xyz="0.05 0 0" rpy="0.4 0 0"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.003"/></inertial></link>
  <joint name="camera_joint" type="fixed"><parent link="a"/><child link="camera"/>
    <origin xyz="0 0.1 0"/></joint>
  <link name="camera"><inertial><mass value="0.2"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>
  </inertial></link>
  <joint name="j2" type="continuous"><parent link="a2"/><child link="b"/><origin xyz="0.1 0 0"/>
    <axis xyz="0 1 0"/></joint>
  <link name="b"><inertial><origin xyz="0 0 0.3"/><mass value="2"/>
    <inertia ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.01"/></inertial></link>
  <joint name="tool_joint" type="fixed"><parent link="b"/><child link="flange"/>
    <origin xyz="0 0 0.4"/></joint>
  <link name="flange"/>
</robot>
"""


def _frame(rot, xyz) -> torch.Tensor:
    t = torch.eye(4, dtype=D)
    t[:3, :3], t[:3, 3] = torch.tensor(rot, dtype=D), torch.tensor(xyz, dtype=D)
    return t


def _pseudo(mass: float, principal: tuple, pose: torch.Tensor) -> torch.Tensor:
    """4x4 pseudo-inertia ∫ x̃ x̃ᵀ dm of a body whose com frame (axes along ``principal`` moments) has
    ``pose``: J = T diag(Σ, m) Tᵀ with Σ = ½ tr(I) 1 − I. Independent of selpres's parallel-axis code."""
    i_c = torch.diag(torch.tensor(principal, dtype=D))
    local = torch.zeros(4, 4, dtype=D)
    local[:3, :3], local[3, 3] = 0.5 * torch.trace(i_c) * torch.eye(3, dtype=D) - i_c, mass
    return pose @ local @ pose.T


def _body(j: torch.Tensor) -> tuple[float, tuple, tuple]:
    """(mass, com, inertia about the com) from a pseudo-inertia."""
    mass = float(j[3, 3])
    c = j[:3, 3] / mass
    sigma = j[:3, :3] - mass * torch.outer(c, c)
    inertia = torch.trace(sigma) * torch.eye(3, dtype=D) - sigma
    return mass, tuple(c.tolist()), tuple(map(tuple, inertia.tolist()))


def test_fixed_joints_merge_into_their_moving_body(tmp_path):
    path = tmp_path / "hand.urdf"
    path.write_text(HAND)
    arm = load_urdf(path)
    eye = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    a2_in_a = _frame(rot_z(math.pi / 2), (0.2, 0.0, 0.0))
    # body "a" = a + a2 (via the fixed joint, its inertial turned 0.4 rad about x) + the camera; the 50 kg
    # stand hangs off the base and does not move
    body_a = _body(
        _pseudo(1.0, (0.01, 0.02, 0.03), _frame(eye, (0.1, 0.0, 0.0)))
        + _pseudo(0.5, (0.001, 0.002, 0.003), a2_in_a @ _frame(rpy_matrix((0.4, 0.0, 0.0)), (0.05, 0.0, 0.0)))
        + _pseudo(0.2, (0.0, 0.0, 0.0), _frame(eye, (0.0, 0.1, 0.0)))
    )
    expected = SerialArm(
        [
            Link(
                "a",
                *body_a,
                joint="j1",
                xyz=(0.0, 0.0, 0.1),
                rotation=rpy_matrix((0.3, 0.0, 0.0)),
                axis=(0.0, 0.0, 1.0),
                limits=(-1.0, 2.0),
            ),
            Link(
                "b",
                2.0,
                (0.0, 0.0, 0.3),
                ((0.05, 0, 0), (0, 0.05, 0), (0, 0, 0.01)),
                joint="j2",
                xyz=(0.2, 0.1, 0.0),
                rotation=rot_z(math.pi / 2),
                axis=(0.0, 1.0, 0.0),
            ),  # by hand: a2 ∘ origin
        ],
        gravity=(0.0, 0.0, -9.81),
        end_point=(0.0, 0.0, 0.4),
    )
    assert math.isclose(arm.links[0].mass, 1.7) and (arm.base, arm.tip) == ("base", "flange")
    same_dynamics(arm, expected)
    lighter = SerialArm(
        [
            Link(
                "a",
                *_body(_pseudo(1.0, (0.01, 0.02, 0.03), _frame(eye, (0.1, 0.0, 0.0)))),
                joint="j1",
                xyz=(0.0, 0.0, 0.1),
                rotation=rpy_matrix((0.3, 0.0, 0.0)),
            ),
            expected.links[1],
        ],
        gravity=(0.0, 0.0, -9.81),
        end_point=(0.0, 0.0, 0.4),
    )
    q, qd, qdd, _ = states(50, 2, seed=4)  # the comparison can fail: without the merged parts it does
    assert (lighter.inverse_dynamics(q, qd, qdd) - arm.inverse_dynamics(q, qd, qdd)).abs().max() > 1e-3


def test_tip_can_be_named(tmp_path):
    path = tmp_path / "hand.urdf"
    path.write_text(HAND)
    assert load_urdf(path, tip="b").end_point == (0.0, 0.0, 0.0)
    one = load_urdf(path, tip="camera")  # the tip chooses the chain: base -> a -> camera models j1 only
    assert [lk.joint for lk in one.links] == ["j1"] and one.tip == "camera"
    assert one.source["held"] == {"j2": 0.0} and one.source["modelled"] == ["j1"]
    with pytest.raises(UrdfError, match=r'tip="stand": is not a link below the base link \'a\''):
        load_urdf(path, base="a", tip="stand")


def test_axis_defaults_to_x_and_damping_is_reported(tmp_path, caplog):
    """URDF's default axis is (1, 0, 0); joint damping/friction are not simulated, and say so."""
    text = HAND.replace('<axis xyz="0 1 0"/>', "").replace('damping="0" friction="0"', 'damping="0.5"')
    path = tmp_path / "hand.urdf"
    path.write_text(text)
    with caplog.at_level(logging.WARNING, logger="selpres.arms.urdf"):
        arm = load_urdf(path)
    assert arm.links[1].axis == (1.0, 0.0, 0.0)
    assert any("<dynamics> ignored" in r.getMessage() and "j1 (damping=0.5)" in r.getMessage() for r in caplog.records)
    assert sum("<dynamics>" in r.getMessage() for r in caplog.records) == 1  # once per file, listing the joints


# ------------------------------------------------------------------------------------------------ errors
@pytest.mark.parametrize(
    "edit, element, problem",
    [
        (('type="continuous"', 'type="ball"'), '<joint name="j2">', "unknown type 'ball'"),
        (
            ('<axis xyz="0 1 0"/>', '<axis xyz="0 1 0"/><mimic joint="j1"/>'),
            '<joint name="j2"> <mimic joint="j1">',
            "couples a modelled joint",
        ),
        (('damping="0"', 'damping="abc"'), '<joint name="j1"> <dynamics damping>', "'abc' is not a finite number"),
        (
            ('<child link="flange"/>', '<child link="flang"/>'),
            '<joint name="tool_joint">',
            "<child link='flang'> names a link that no <link> defines",
        ),
        (
            ('<parent link="a"/><child link="camera"/>', '<parent link="b"/><child link="a"/>'),
            '<link name="a">',
            "is the child of joints 'j1' and 'camera_joint': a closed loop",
        ),
        (
            (
                '<link name="flange"/>',
                '<link name="flange"/><joint name="j3" type="revolute"><parent link="a"/>'
                '<child link="c"/></joint><link name="c"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" '
                'iyy="1" iyz="0" izz="1"/></inertial></link>',
            ),
            '<link name="a">',
            "branches into joints ['a_fixed', 'j3'], each leading to revolute joints: choose one chain",
        ),
        (
            (
                '<link name="b"><inertial><origin xyz="0 0 0.3"/><mass value="2"/>\n    <inertia ixx="0.05" ixy="0" '
                'ixz="0" iyy="0.05" iyz="0" izz="0.01"/></inertial></link>',
                '<link name="b"/>',
            ),
            '<link name="b">',
            "has no <inertial> but joint 'j2' moves it",
        ),
        (('<mass value="2"/>', '<mass value="-2"/>'), '<link name="b">', "mass=-2.0 is not allowed"),
        (('<mass value="2"/>', "<mass/>"), '<link name="b"> <inertial> <mass>', "missing attribute 'value'"),
        (('ixx="0.05" ixy="0"', 'ixx="0.05" ixy="0.9"'), '<link name="b">', "positive semi-definite"),
        (('izz="0.01"', 'izz="abc"'), '<link name="b"> <inertial> <inertia izz>', "'abc' is not a finite number"),
        (
            ('<origin xyz="0 0 0.4"/>', '<origin xyz="0 0.4"/>'),
            '<joint name="tool_joint"> <origin xyz>',
            "'0 0.4' is not 3 finite numbers",
        ),
        (('lower="-1" upper="2"', 'lower="2" upper="-1"'), '<joint name="j1">', "need lower < upper"),
        (('<link name="camera">', '<link name="a">'), '<link name="a">', "defined twice"),
        (
            ('<robot name="hand">', '<robot name="hand"><link name="loose"/>'),
            "<robot>",
            "have no parent joint: the file holds more than one tree",
        ),
    ],
)
def test_unsupported_files_name_the_element(edit, element, problem, tmp_path):
    path = tmp_path / "bad.urdf"
    assert edit[0] in HAND
    path.write_text(HAND.replace(edit[0], edit[1], 1))
    with pytest.raises(UrdfError) as err:
        load_urdf(path)
    assert str(err.value).startswith(f"{path}: {element}: "), str(err.value)
    assert problem in str(err.value)


def test_loops_without_a_root_and_files_that_are_not_urdf(tmp_path):
    loop = tmp_path / "loop.urdf"
    loop.write_text(
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="ab" type="revolute"><parent link="a"/><child link="b"/></joint>'
        '<joint name="ba" type="revolute"><parent link="b"/><child link="a"/></joint></robot>'
    )
    with pytest.raises(UrdfError, match="<robot>: every link is some joint's child: a closed loop"):
        load_urdf(loop)
    frozen = tmp_path / "frozen.urdf"
    frozen.write_text(
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint></robot>'
    )
    with pytest.raises(UrdfError, match="has no revolute or continuous joint"):
        load_urdf(frozen)
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot><link name='a'>")
    with pytest.raises(UrdfError, match=r"broken.urdf: XML: not well-formed"):
        load_urdf(broken)
    other = tmp_path / "scene.xml"
    other.write_text("<mujoco/>")
    with pytest.raises(UrdfError, match=r"<mujoco>: the root element must be <robot>"):
        load_urdf(other)
    with pytest.raises(UrdfError, match=r"missing.urdf: file: not found"):
        load_urdf(tmp_path / "missing.urdf")


def test_urdf_error_is_a_config_error_that_survives_pickling(tmp_path):
    """The CLI turns ConfigError into one line and exit code 2; launchers pickle errors home."""
    err = UrdfError(tmp_path / "x.urdf", '<joint name="j">', "bad")
    assert isinstance(err, ConfigError)
    again = pickle.loads(pickle.dumps(err))
    assert str(again) == str(err) == f'{tmp_path / "x.urdf"}: <joint name="j">: bad'


def test_export_refuses_a_tip_named_like_a_link(tmp_path):
    arm = SerialArm.two_link(0.42, 3.0, 0.2, 0.26)
    clash = SerialArm(arm.links, arm.gravity_vector, arm.end_point, tip="link1")
    with pytest.raises(ValueError, match="tip name 'link1' is already a link"):
        to_urdf(clash, tmp_path / "x.urdf")


# ------------------------------------------------------------------------- chains, held joints, guards
def _hand(tmp_path, *edits, name="hand.urdf"):
    text = HAND
    for old, new in edits:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_held_joint_is_the_full_arm_frozen_there(tmp_path):
    """Holding j2 at 0.7 merges b into a turned by 0.7 rad: joint 1's torque equals the two-joint arm's at
    q2 = 0.7 with q2 not moving (an independent derivation: the full model's own equations)."""
    path = _hand(tmp_path)
    full, held = load_urdf(path), load_urdf(path, joints=["j1"], hold={"j2": 0.7})
    assert held.source == {"file": str(path), "modelled": ["j1"], "held": {"j2": 0.7}, "notes": []}
    q, qd, qdd, _ = states(40, 1, seed=5)
    pad = lambda x, v: torch.cat((x, torch.full_like(x, v)), 1)
    want = full.inverse_dynamics(pad(q, 0.7), pad(qd, 0.0), pad(qdd, 0.0))[:, :1]
    assert (held.inverse_dynamics(q, qd, qdd) - want).abs().max() <= 1e-12
    assert (
        held.inverse_dynamics(q, qd, qdd) - full.inverse_dynamics(pad(q, 0.0), pad(qd, 0), pad(qdd, 0))[:, :1]
    ).abs().max() > 1e-3


def test_gravity_is_a_vector_in_the_root_frame(tmp_path):
    path = _hand(tmp_path)
    assert load_urdf(path).gravity_vector == (0.0, 0.0, -9.81)
    assert load_urdf(path, gravity=(1.0, -2.0, 3.0)).gravity_vector == (1.0, -2.0, 3.0)  # base = root here
    assert load_urdf(path, g=3.0).gravity_vector == (0.0, 0.0, -3.0)
    with pytest.raises(ConfigError, match="robot.g=3.0 is not allowed: expected unset when robot.gravity is given"):
        load_urdf(path, g=3.0, gravity=(0.0, 0.0, -9.81))


def test_one_parse_per_file_version(tmp_path):
    path = _hand(tmp_path)
    assert load_urdf(path) is load_urdf(str(path))  # a job's checks, hash and data share one parse
    os.utime(path, ns=(1, 1))
    assert load_urdf(path) is not load_urdf(path, tip="b") and load_urdf(path).source["file"] == str(path)


@pytest.mark.parametrize(
    "edits, kw, element, problem",
    [
        ((), {"joints": ["j1", "jx"]}, "robot.joints=['j1', 'jx']", "names ['jx']: give distinct revolute joints"),
        ((), {"hold": {"nope": 1.0}}, "robot.hold.nope", "names no <joint> of the file"),
        ((), {"hold": {"j1": 1.0}}, "robot.hold.j1", "is a modelled joint"),
        ((), {"tip": "nowhere"}, "robot.tip='nowhere'", "names no <link> of the file"),
        (
            [('<mass value="1.0"/>', '<mass value="0"/>'), ('<mass value="0.5"/>', '<mass value="0"/>')]
            + [('<mass value="0.2"/>', '<mass value="0"/>'), ('<mass value="2"/>', '<mass value="0"/>')]
            + [
                (
                    'ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"',
                    'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"',
                )
            ]
            + [
                (
                    'ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.003"',
                    'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"',
                )
            ]
            + [
                (
                    'ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.01"',
                    'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"',
                )
            ],
            {},
            "<inertial>",
            "every body the joints ['j1', 'j2'] move has mass 0 and inertia 0: every torque would be 0",
        ),
        (
            [
                ('<mass value="2"/>', '<mass value="0"/>'),
                (
                    'ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.01"',
                    'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"',
                ),
            ],
            {},
            '<joint name="j2">',
            "joints ['j2'] move no mass and no inertia, so their torques are always 0",
        ),
        (
            [('<robot name="hand">', '<robot name="hand"><!DOCTYPE x [<!ENTITY a "aaaa">]>')],
            {},
            "<!ENTITY>",
            "XML bomb guard",
        ),
        (
            [
                (
                    '<link name="flange"/>',
                    '<link name="flange"/><xacro:macro xmlns:xacro="http://wiki.ros.org/xacro" name="m"/>',
                )
            ],
            {},
            "xacro",
            "this is a xacro macro file: run `xacro hand.urdf > robot.urdf` first",
        ),
    ],
)
def test_chain_options_and_physically_empty_arms_are_refused_naming_them(tmp_path, edits, kw, element, problem):
    path = _hand(tmp_path, *edits)
    with pytest.raises(UrdfError) as err:
        load_urdf(path, **kw)
    assert str(err.value).startswith(f"{path}: {element}: ") and problem in str(err.value), str(err.value)


def test_size_guard_refuses_before_reading(tmp_path, monkeypatch):
    import selpres.arms.urdf_read as U

    path = _hand(tmp_path)
    monkeypatch.setattr(U, "MAX_BYTES", 1000)
    with pytest.raises(UrdfError, match=r"hand.urdf: file: 0 MiB, more than the 0 MiB"):
        U._Reader(path)
    empty = tmp_path / "empty.urdf"
    empty.write_text("<robot name='e'/>")
    with pytest.raises(UrdfError, match="<robot>: has no <link>: an empty robot description"):
        load_urdf(empty)


def test_zero_width_limits_mean_none_and_velocity_effort_give_the_default_boxes(tmp_path):
    from selpres.data import sampled as S

    path = _hand(tmp_path, ('lower="-1" upper="2"', 'lower="0" upper="0"'))
    arm = load_urdf(path)
    assert arm.links[0].limits is None and "no position limits" in arm.source["notes"][0]
    wide = load_urdf(_hand(tmp_path, ('lower="-1" upper="2"', 'lower="-6.3" upper="6.2"'), name="wide.urdf"))
    cfg = {"route": "forward", "q": None, "dq": None, "tau": None, "accel_limit": 2.0, "wrench": None}
    with pytest.raises(ConfigError, match="data.tau"):  # j2 has no effort limit: forward needs a box
        S.boxes(wide, cfg)
    box = S.boxes(wide, {**cfg, "route": "inverse"})
    assert torch.allclose(box.q, torch.tensor([[-0.05 - math.pi, -0.05 + math.pi], [-math.pi, math.pi]], dtype=D))
    assert box.dq.tolist() == [[-0.5, 0.5], [-1.0, 1.0]]  # half of j1's velocity limit 1 rad/s; j2: none
    both = load_urdf(
        _hand(
            tmp_path, ('<axis xyz="0 1 0"/></joint>', '<axis xyz="0 1 0"/><limit effort="3"/></joint>'), name="eff.urdf"
        )
    )
    assert S.boxes(both, cfg).tau.tolist() == [[-5.0, 5.0], [-3.0, 3.0]]
    assert S.boxes(both, {**cfg, "dq": [-2.0, 2.0]}).dq.tolist() == [[-2.0, 2.0]] * 2  # an explicit box wins


def test_a_job_parses_its_urdf_once(tmp_path, monkeypatch):
    """Checks, data hash and data share one parse (issue 18: a 150 MB file was parsed 3 times per job)."""
    import selpres.arms.urdf_read as U
    from selpres.run.train import train

    from conftest import compose

    path, parses = _hand(tmp_path), []
    original = U._Reader.__init__
    monkeypatch.setattr(U._Reader, "__init__", lambda self, p: (parses.append(p), original(self, p))[1])
    cfg = compose(
        "robot=urdf", f"robot.path={path}", "topology.layers=6-3-2", "data.n=200", "data.heldout=50",
        "schedule=conventional", "schedule.epochs=[2]",
    )  # fmt: skip
    res = train(cfg, None)
    assert parses == [path] and res["data"]["urdf"]["modelled"] == ["j1", "j2"]


def test_a_gravity_vector_is_exported_faithfully(tmp_path):
    """robot.gravity pointing anywhere: to_urdf turns a world root so that it is -z there, and the file reads
    back (gravity's magnitude along -z of that root) as the same dynamics."""
    arm = load_urdf(_hand(tmp_path), gravity=(1.0, -2.0, 3.0))
    back = load_urdf(to_urdf(arm, tmp_path / "out.urdf"), g=math.sqrt(14.0))
    same_dynamics(arm, back, 1e-11)
    assert back.base == arm.base and back.source["modelled"] == ["j1", "j2"]


B_INERTIA = 'ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.01"'


@pytest.mark.parametrize(
    "inertia, moments",
    [
        ('ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="5"', (0.1, 0.1, 5.0)),  # the link
        ('ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.25"', (0.1, 0.1, 0.25)),  # by 20 %: beyond 10 %
        # the same kind of body turned 45 degrees about z: off-diagonal terms, the principal moments tell
        ('ixx="2.55" ixy="2.45" ixz="0" iyy="2.55" iyz="0" izz="0.1"', (0.1, 0.1, 5.0)),
    ],
)
def test_an_inertia_no_rigid_body_has_is_refused_naming_the_link_and_its_values(tmp_path, inertia, moments):
    path = _hand(tmp_path, (B_INERTIA, inertia))
    with pytest.raises(UrdfError) as err:
        load_urdf(path)
    said = str(err.value)
    v = dict(re.findall(r'(i[xyz]{2})="([^"]+)"', inertia))
    assert said.startswith(f'{path}: <link name="b"> <inertia ixx={float(v["ixx"]):g}, iyy={float(v["iyy"]):g}, '
                           f'izz={float(v["izz"]):g}>: is not a rigid body\'s'), said  # fmt: skip
    a, b, c = moments  # worked out by hand (the turned tensor's eigenvalues: 2.55 +- 2.45 and 0.1)
    assert f"principal moments {a:g}, {b:g}, {c:g} kg m^2 break the triangle inequality" in said, said


@pytest.mark.parametrize(
    "edit",
    [
        (B_INERTIA, 'ixx="0.066" ixy="0" ixz="0" iyy="0.086" iyz="0" izz="0.0125"'),  # the PUMA's link 3: by 8.7 %
        (B_INERTIA, 'ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.2"'),  # a flat plate: equality
        (B_INERTIA, 'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"'),  # a point mass
        # a massless link's lumped tensor (the PUMA 560's link 1, given without a mass)
        ('<mass value="0.2"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>',
         '<mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0.35" iyz="0" izz="0"/>'),
    ],
)  # fmt: skip
def test_inertias_a_body_can_have_load(tmp_path, edit):
    assert load_urdf(_hand(tmp_path, edit)).dof == 2
