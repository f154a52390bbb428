"""``_target_: two_link``: the paper's arm in the closed form of eq. (6), from m1, m2, l1, l2 and g."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from selpres.arms.sources import ArmSource
from selpres.arms.two_link import TwoLinkArm
from selpres.errors import ConfigError


@dataclass(frozen=True)
class TwoLink(ArmSource):
    """Point masses m1, m2 (kg) at the ends of links l1, l2 (m); gravity g (m/s²) along −y."""

    m1: float
    m2: float
    l1: float
    l2: float
    g: float = 9.81

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ConfigError(f"robot.{f.name}", v, "a positive number (kg, m, m/s²)")

    def arm(self) -> TwoLinkArm:
        return TwoLinkArm(float(self.m1), float(self.m2), float(self.l1), float(self.l2), float(self.g))


SOURCE = TwoLink
