"""Real robot files as they come (issue 21): published URDFs from ``example-robot-data`` load, chains cut from
trees and held joints included, and give Pinocchio's torques to <= 1e-9 Nm on drawn states.

The independent side (``selpres.arms.check.pinocchio_torques``): Pinocchio (``pin``) builds the whole file's
model and ``pin.buildReducedModel`` locks every joint selpres holds at the value selpres held it at (Pinocchio
merges the bodies itself), then its RNEA is compared with ``SerialArm.inverse_dynamics``. Both packages are
the ``robots`` extra (pyproject.toml); without them these tests skip, saying so.
"""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import numpy as np
import pytest

from selpres.arms.check import drawn_states, pinocchio_torques
from selpres.arms.urdf import load_urdf

pin = pytest.importorskip("pinocchio", reason="Pinocchio (`pin`, the robots extra) is not installed")


def _robots() -> Path | None:
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    root = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    return root if root.is_dir() else None


ROBOTS = _robots()
if ROBOTS is None:
    pytest.skip("example-robot-data (the robots extra) is not installed", allow_module_level=True)


CASES = {
    "ur5": ("ur_description/urdf/ur5_robot.urdf", {}, 6, 0),
    "panda, fingers held": ("panda_description/urdf/panda.urdf", {}, 7, 2),
    "panda, 3 joints, others held off zero": (
        "panda_description/urdf/panda.urdf",
        {
            "joints": ["panda_joint1", "panda_joint2", "panda_joint4"],
            "hold": {"panda_joint3": 0.5, "panda_joint7": -1.0, "panda_finger_joint1": 0.03},
        },
        3,
        6,
    ),
    "kinova": ("kinova_description/robots/kinova.urdf", {}, 6, 0),
    "talos left arm (fixed-joint mimics)": ("talos_data/robots/talos_left_arm.urdf", {}, 7, 0),
    "talos arm cut from the full robot": (
        "talos_data/robots/talos_full_v2.urdf",
        {"base": "torso_2_link", "tip": "arm_left_7_link"},
        7,
        37,
    ),
    "baxter left arm cut from the tree": ("baxter_description/urdf/baxter.urdf", {"tip": "left_hand_link"}, 7, 12),
    "solo12 leg": ("solo_description/robots/solo12.urdf", {"tip": "FL_FOOT"}, 3, 9),
    "double pendulum (limits 0 0)": ("double_pendulum_description/urdf/double_pendulum.urdf", {}, 2, 0),
}


@pytest.mark.parametrize("case", list(CASES))
def test_real_files_give_pinocchios_torques(case):
    rel, kw, dof, held = CASES[case]
    path = ROBOTS / rel
    arm = load_urdf(path, **kw)
    assert (arm.dof, len(arm.source["held"])) == (dof, held)
    q, qd, qdd = drawn_states(dof, 60, 7)
    ours = arm.inverse_dynamics(q, qd, qdd).numpy()
    theirs = pinocchio_torques(path, arm, q, qd, qdd)
    assert np.abs(ours - theirs).max() <= 1e-9
    assert np.abs(theirs).max() > 0.1  # a comparison that can fail: torques far above the tolerance


def test_what_real_files_say_is_read_as_they_mean_it():
    pend = load_urdf(ROBOTS / "double_pendulum_description/urdf/double_pendulum.urdf")
    assert all(lk.limits is None for lk in pend.links)  # <limit lower="0" upper="0">: not given
    assert any("no position limits" in n for n in pend.source["notes"])
    talos = load_urdf(ROBOTS / "talos_data/robots/talos_left_arm.urdf")
    assert any("<mimic> on fixed joints" in n for n in talos.source["notes"])
    panda = load_urdf(ROBOTS / "panda_description/urdf/panda.urdf")
    assert panda.source["held"] == {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}
    assert panda.links[0].velocity == 2.175 and panda.links[0].effort == 87.0
    with pytest.raises(Exception, match=r"<link name=\"torso\">: branches into joints .* choose one chain"):
        load_urdf(ROBOTS / "baxter_description/urdf/baxter.urdf")
    with pytest.raises(Exception, match=r"<robot>: has no <link>: an empty robot description"):
        load_urdf(ROBOTS / "ur_description/urdf/ur3.urdf")  # a xacro output with nothing in it
