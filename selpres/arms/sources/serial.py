"""``_target_: serial``: N revolute joints from links or DH rows written in the node (``selpres.arms.serial``)."""

from __future__ import annotations

from typing import Any

from selpres.arms.serial import SerialArm
from selpres.arms.sources import ArmSource


class Serial(ArmSource):
    """The spec of ``selpres.arms.serial`` (links from the base outwards, or DH rows with ``convention: dh``);
    every key and each link's physics is checked when the arm is built, errors naming ``robot.<key>``."""

    def __init__(
        self,
        *,
        links: list | None = None,
        gravity: list | None = None,
        name: str | None = None,
        convention: str | None = None,
        end_point: list | None = None,
        base: str | None = None,
        tip: str | None = None,
    ):
        given = dict(links=links, gravity=gravity, name=name, convention=convention, end_point=end_point)
        self.spec: dict[str, Any] = {k: v for k, v in {**given, "base": base, "tip": tip}.items() if v is not None}

    def arm(self) -> SerialArm:
        return SerialArm.from_config(self.spec, "robot")


SOURCE = Serial
