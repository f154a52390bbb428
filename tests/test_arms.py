"""Arms as configs (robot=two_link|planar3|puma560|urdf): arm sources, canonical identity, URDF export that
loads back as the same dynamics, exported CSVs that name their columns and carry the arm, and errors."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from selpres.arms.serial import SerialArm
from selpres.arms.sources import make_arm
from selpres.arms.two_link import TwoLinkArm
from selpres.arms.urdf import UrdfError, load_urdf, to_urdf
from selpres.data.export import config_hash, load_csv, load_exported
from selpres.errors import ConfigError
from selpres.run.specs import data_spec, robot_spec

from conftest import cfg_of, load_group, run_python

ROOT = Path(__file__).resolve().parents[1]
F64 = torch.float64


def states(dof: int, m: int = 64, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    return tuple(4 * torch.rand(m, dof, dtype=F64, generator=g) - 2 for _ in range(3))


@pytest.mark.parametrize(
    "option, kind, dof", [("two_link", TwoLinkArm, 2), ("planar3", SerialArm, 3), ("puma560", SerialArm, 6)]
)
def test_shipped_arms(option, kind, dof):
    arm = make_arm(robot_spec(cfg_of(f"robot={option}").robot))
    assert isinstance(arm, kind) and arm.dof == dof and arm.name == option
    again = make_arm(arm.to_config())
    assert again.to_config() == arm.to_config()


def test_two_link_config_is_the_closed_form_and_agrees_with_the_general_code():
    arm = make_arm(load_group("robot", "two_link"))
    q, qd, qdd = states(2)
    assert torch.allclose(
        arm.as_serial().inverse_dynamics(q, qd, qdd), arm.inverse_dynamics(q, qd, qdd), atol=1e-12, rtol=0
    )


@pytest.mark.parametrize(
    "overrides, key, value",
    [
        (["robot.m1=null"], "robot.m1", "None"),
        (["robot.m2=-1"], "robot.m2", "-1"),
        (["+robot.links=[]"], "robot.links", "[]"),  # a two_link config that sets a serial key
        (["robot=puma560", "+robot.m1=1"], "robot.m1", "1"),
        (["robot=puma560", "robot.links.1.mass=-2"], "robot.links[1].mass", "-2"),
        (["robot=urdf"], "robot.path", "None"),
        (["robot=urdf", "robot.path=x.urdf", "robot.g=-9.81"], "robot.g", "-9.81"),
    ],
)
def test_bad_robot_configs_name_the_key(overrides, key, value):
    from selpres.run.resolve import resolve

    with pytest.raises(ConfigError) as ei:
        resolve(cfg_of("data=sampled", *overrides))
    assert ei.value.key == key and value in str(ei.value), str(ei.value)


def test_a_bad_urdf_names_file_and_element(tmp_path):
    path = tmp_path / "slider.urdf"
    path.write_text(
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j" type="prismatic"><parent link="a"/><child link="b"/></joint></robot>'
    )
    with pytest.raises(UrdfError) as ei:
        make_arm({"kind": "urdf", "path": str(path), "g": 9.81})
    assert str(ei.value) == (
        f"{path}: <robot>: has no revolute or continuous joint on the chain from 'a' (joints ['j'] would be held: "
        "selpres models revolute joints)"
    )


def test_identity_is_the_arm_not_the_file(tmp_path):
    """The same arm hashes alike from its YAML or from a URDF of it, wherever the file lies; another mass
    changes the hash."""
    data = data_spec(cfg_of("data=sampled").data)
    puma = robot_spec(cfg_of("robot=puma560").robot)
    a, b = to_urdf(make_arm(puma), tmp_path / "a.urdf"), to_urdf(make_arm(puma), tmp_path / "sub" / "b.urdf")
    from_a = robot_spec(cfg_of("robot=urdf", f"robot.path={a}").robot)
    from_b = robot_spec(cfg_of("robot=urdf", f"robot.path={b}").robot)
    assert config_hash(puma, data) == config_hash(from_a, data) == config_hash(from_b, data)
    heavier = robot_spec(cfg_of("robot=puma560", "robot.links.2.mass=4.9").robot)
    assert config_hash(heavier, data) != config_hash(puma, data)


def _export(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    return run_python("-m", "selpres.run.export", "--out", str(tmp_path / "ex"), *args, timeout=300)


@pytest.mark.slow
def test_export_names_columns_carries_the_arm_and_writes_its_urdf(tmp_path):
    wrench = [1.0, 0.0, -2.0, 0.0, 0.5, 0.0]
    out = _export(
        tmp_path,
        "robot=puma560",
        "data=sampled",
        "data.n=300",
        "data.heldout=40",
        f"data.wrench=[{','.join(map(str, wrench))}]",
        "--urdf",
        str(tmp_path / "puma.urdf"),
    )
    assert out.returncode == 0, out.stderr
    with open(tmp_path / "ex_exemplar.csv") as f:
        assert f.readline().startswith("# config_hash=")
        arm_line = f.readline()
    arm = make_arm(robot_spec(cfg_of("robot=puma560").robot))
    assert arm_line.startswith("# arm=") and json.loads(arm_line[6:]) == json.loads(json.dumps(arm.to_config()))
    _, names, table = load_csv(tmp_path / "ex_exemplar.csv")
    assert names == (
        *(f"{p}{i}" for p in ("q", "dq", "ddq") for i in range(1, 7)),
        *(f"tau{i}" for i in range(1, 7)),
        "k_fx",
        "k_fy",
        "k_fz",
        "k_mx",
        "k_my",
        "k_mz",
    )
    assert table.shape == (300, 30) and (table[:, 24:] == wrench).all()
    cfg = cfg_of("robot=puma560", "data=sampled", "data.n=300", "data.heldout=40", f"data.wrench={wrench}")
    arrays = load_exported(tmp_path / "ex.npz", cfg.robot, cfg.data)
    assert arrays["exemplar_X"].shape == (300, 18) and arrays["exemplar_Y"].shape == (300, 6)
    # the URDF is the same dynamics, wrench included
    loaded = load_urdf(tmp_path / "puma.urdf", g=9.81)
    X, Y = torch.from_numpy(arrays["exemplar_X"]), torch.from_numpy(arrays["exemplar_Y"])
    k = torch.tensor(wrench, dtype=F64)
    assert torch.allclose(loaded.inverse_dynamics(X[:, :6], X[:, 6:12], X[:, 12:], k), Y, atol=1e-12, rtol=0)


@pytest.mark.slow
def test_two_link_urdf_loads_as_eq6(tmp_path):
    out = _export(tmp_path, "data.heldout=20", "--urdf", str(tmp_path / "two.urdf"))
    assert out.returncode == 0, out.stderr
    loaded = load_urdf(tmp_path / "two.urdf", g=9.81)
    q, qd, qdd = states(2)
    arm = make_arm(load_group("robot", "two_link"))
    assert torch.allclose(loaded.inverse_dynamics(q, qd, qdd), arm.inverse_dynamics(q, qd, qdd), atol=1e-12, rtol=0)
    _, names, _ = load_csv(tmp_path / "ex_exemplar.csv")
    assert names == ("theta1", "dtheta1", "ddtheta1", "theta2", "dtheta2", "ddtheta2", "tau1", "tau2")


@pytest.mark.slow
@pytest.mark.parametrize(
    "args",
    [
        ["robot=urdf", "data=sampled", "robot.path=missing.urdf"],
        ["robot=puma560", "data=paper"],  # the paper's grid asked for on a 6-joint arm
        ["data=file", "data.path=missing.csv", "--urdf", "x.urdf"],
    ],
)
def test_export_refusals_exit_2_and_write_nothing(tmp_path, args):
    out = subprocess.run(
        [sys.executable, "-m", "selpres.run.export", "--out", str(tmp_path / "ex"), *args],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert out.returncode == 2 and out.stderr.startswith("error: ") and "Traceback" not in out.stderr, out.stderr
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
def test_train_refuses_a_bad_urdf_with_exit_2(tmp_path):
    path = tmp_path / "loop.urdf"
    path.write_text('<robot name="r"><link name="a"/></robot>')
    run = tmp_path / "run"
    out = run_python(
        str(ROOT / "train.py"),
        "robot=urdf",
        f"robot.path={path}",
        "data=sampled",
        f"hydra.run.dir={run}",
        cwd=tmp_path,
        timeout=300,
    )
    assert out.returncode == 2 and f"error: {path}: <robot>: has no <joint>: nothing moves" in out.stderr
    assert not run.exists()


def test_planar3_with_a_massless_hand_is_the_paper_arm():
    """m3 = 0: joints 1-2 carry the two-link arm's torques (eq. 6), joint 3 none."""
    cfg = cfg_of("robot=planar3", "robot.links.2.mass=0.0")
    arm, paper = make_arm(robot_spec(cfg.robot)), make_arm(load_group("robot", "two_link"))
    q, qd, qdd = states(3)
    tau = arm.inverse_dynamics(q, qd, qdd)
    assert torch.allclose(tau[:, :2], paper.inverse_dynamics(q[:, :2], qd[:, :2], qdd[:, :2]), atol=1e-12, rtol=0)
    assert torch.allclose(tau[:, 2], torch.zeros(64, dtype=F64), atol=1e-15)
    assert np.isfinite(tau.numpy()).all()


def test_urdf_chain_keys_from_the_command_line(tmp_path):
    """robot.joints / robot.hold / robot.gravity / robot.g as a user types them; bad values name the key."""
    from test_urdf import HAND

    path = tmp_path / "hand.urdf"
    path.write_text(HAND)
    base = ("robot=urdf", f"robot.path={path}")
    arm = make_arm(robot_spec(cfg_of(*base, "robot.joints=[j1]", "robot.hold={j2: 0.25}").robot))
    assert arm.source["held"] == {"j2": 0.25} and arm.dof == 1
    flat = robot_spec(cfg_of(*base, "robot.gravity=null", "robot.g=3").robot)
    assert make_arm(flat).gravity_vector == (0.0, 0.0, -3.0)
    for overrides, key in (
        (("robot.g=3",), "robot.g=3 is not allowed: expected unset when robot.gravity is given"),
        (("robot.hold=3",), "robot.hold=3 is not allowed"),
        (("robot.gravity=[0,1]",), "robot.gravity=[0, 1] is not allowed"),
    ):
        with pytest.raises(ConfigError, match=re.escape(key)):
            make_arm(robot_spec(cfg_of(*base, *overrides).robot))
