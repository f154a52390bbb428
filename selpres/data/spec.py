"""The data node as plain Python: what ``selpres.run`` hands this room in place of the composed config.

``DataSpec`` holds a ``data`` node's keys (``selpres.run.config.DataConfig``) as plain values: strings for the
enums, dicts for the grid ranges and the scaling, lists for boxes. The functions of this room read it by
attribute (or ``cfg_get``, which also takes a plain dict, as tests and library users write one).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from selpres.registry import construct


@dataclasses.dataclass(frozen=True)
class DataSpec:
    kind: str  # grid | sampled | file (selpres.data.task)
    test_patterns: int
    test_from_exemplar: int
    heldout: Any  # a count, or a fraction of the patterns
    test_seed: int
    scaling: Mapping[str, Any]  # {mode, margin, lo, hi}
    theta: Mapping[str, float] | None = None  # grid: {lo, hi, step}
    dtheta: Mapping[str, float] | None = None
    tau1: Mapping[str, float] | None = None
    tau2: Mapping[str, float] | None = None
    accel_limit: float | None = None
    n: int | None = None  # sampled
    route: str | None = None
    draw: str | None = None
    seed: int | None = None
    q: list | None = None
    dq: list | None = None
    tau: list | None = None
    wrench: list | None = None
    path: str | None = None  # file
    inputs: list | None = None
    outputs: list | None = None

    @classmethod
    def of(cls, node: Mapping[str, Any]) -> DataSpec:
        """From a plain data node; a key this schema lacks is refused naming ``data.<key>``."""
        return construct(cls, dict(node), "data")

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)
