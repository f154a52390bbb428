"""``_target_: urdf``: one serial chain of a URDF file (``selpres.arms.urdf``; chain and held joints:
``selpres.arms.tree``). The file is what the arm depends on, so the source declares it (``reads_files``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from selpres.arms.serial import SerialArm
from selpres.arms.sources import ArmSource
from selpres.errors import ConfigError


def _number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


@dataclass(frozen=True)
class Urdf(ArmSource):
    """``path`` the file; ``gravity`` [gx, gy, gz] in the root link's frame, or its magnitude ``g`` along −z;
    ``base``/``tip`` the chain's links; ``joints`` the modelled joints; ``hold`` held joints' positions."""

    path: str | None = None
    gravity: list | None = None
    g: float | None = None
    base: str | None = None
    tip: str | None = None
    joints: list | None = None
    hold: Mapping | None = None

    def __post_init__(self):
        path, g, gravity, joints, hold = self.path, self.g, self.gravity, self.joints, self.hold
        if not isinstance(path, str) or not path or path == "???":
            raise ConfigError("robot.path", path, "the URDF file to load (robot=urdf robot.path=my_arm.urdf)")
        if g is not None and not (_number(g) and g >= 0):
            raise ConfigError("robot.g", g, "gravity's magnitude in m/s² (>= 0), along -z of the URDF's root")
        if gravity is not None and not (
            isinstance(gravity, (list, tuple)) and len(gravity) == 3 and all(map(_number, gravity))
        ):
            raise ConfigError(
                "robot.gravity", gravity, "[gx, gy, gz]: three finite numbers (m/s², the root link's frame)"
            )
        if joints is not None and not (isinstance(joints, list) and joints and all(isinstance(j, str) for j in joints)):
            raise ConfigError("robot.joints", joints, "a list of joint names to model (null: every revolute joint)")
        if hold is not None and not isinstance(hold, Mapping):
            raise ConfigError("robot.hold", hold, "{joint name: position (rad or m)} for held joints")

    def reads_files(self) -> tuple[Path, ...]:
        return (Path(self.path).expanduser(),)

    def arm(self) -> SerialArm:
        from selpres.arms.urdf import load_urdf  # the XML reader only when a URDF is asked for

        hold = dict(self.hold or {})
        return load_urdf(
            self.reads_files()[0],
            g=self.g,
            gravity=self.gravity,
            base=self.base,
            tip=self.tip,
            joints=self.joints,
            hold=hold,
        )


SOURCE = Urdf
