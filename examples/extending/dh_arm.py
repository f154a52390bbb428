"""A user's own arm source, outside selpres: a robot read from a Denavit-Hartenberg table file.

Run it from the command line (the ``~robot`` drops the default arm's node, ``+robot.*`` writes this one):

    PYTHONPATH=examples/extending python train.py '~robot' +robot._target_=dh_arm.DHTable \\
        +robot.path=examples/extending/two_link.dh '+robot.gravity=[0,-9.81,0]' data=sampled

or from a robot YAML of your own (``_target_: dh_arm.DHTable``, ``path: ...``). results.json records the class
that ran (``data.arm_source: dh_arm.DHTable``).

A source is any class that takes the robot node's keys as keyword arguments, checks them (a ConfigError naming
``robot.<key>``), and offers ``arm()``. A source that reads files says which in ``reads_files()``: selpres keys
the task by their stamps and never stores it, so an edited table is read again, never served stale.

The table: one row per joint, from the base outwards, whitespace-separated, ``#`` starts a comment:

    a  alpha  d  mass  cx  cy  cz  ixx  iyy  izz  [lo  hi]

standard DH (m, rad), the link's mass (kg), its centre of mass and principal inertias (kg m^2) in DH frame i,
as Corke's toolbox writes them, and optional joint limits (rad).
"""

from __future__ import annotations

import math
from pathlib import Path

from selpres.arms.serial import SerialArm
from selpres.errors import ConfigError, FileError

COLUMNS = ("a", "alpha", "d", "mass", "cx", "cy", "cz", "ixx", "iyy", "izz")


class DHTable:
    """The serial arm of a DH-table file; ``gravity`` in the base frame (m/s^2), ``name`` (default: the file's)."""

    def __init__(self, path: str, gravity: list | None = None, name: str | None = None):
        if not isinstance(path, str) or not path:
            raise ConfigError("robot.path", path, "the DH table file to read")
        gravity = [0.0, 0.0, -9.81] if gravity is None else gravity
        ok = isinstance(gravity, (list, tuple)) and len(gravity) == 3
        if not ok or not all(isinstance(g, (int, float)) and math.isfinite(g) for g in gravity):
            raise ConfigError("robot.gravity", gravity, "[gx, gy, gz]: three finite numbers (m/s^2, base frame)")
        self.path, self.gravity, self.name = Path(path).expanduser(), tuple(map(float, gravity)), name

    def reads_files(self) -> tuple[Path, ...]:
        return (self.path,)

    def arm(self) -> SerialArm:
        rows = [self._row(n, line) for n, line in self._lines()]
        if not rows:
            raise FileError(self.path, "file", "has no joint rows")
        return SerialArm.from_dh(rows, self.gravity, name=self.name or self.path.stem)

    def _lines(self):
        try:
            text = self.path.read_text()
        except OSError as e:
            raise FileError(self.path, "file", f"cannot be read ({e.strerror or e})") from None
        for n, line in enumerate(text.splitlines(), 1):
            line = line.split("#", 1)[0].strip()
            if line:
                yield n, line

    def _row(self, n: int, line: str) -> dict:
        cells = line.split()
        if len(cells) not in (len(COLUMNS), len(COLUMNS) + 2):
            raise FileError(self.path, f"line {n}", f"{len(cells)} numbers: expected {' '.join(COLUMNS)} [lo hi]")
        try:
            x = [float(c) for c in cells]
        except ValueError as e:
            raise FileError(self.path, f"line {n}", f"not a number ({e})") from None
        v = dict(zip(COLUMNS, x))
        row = {
            "a": v["a"],
            "alpha": v["alpha"],
            "d": v["d"],
            "mass": v["mass"],
            "com": (v["cx"], v["cy"], v["cz"]),
            "inertia": ((v["ixx"], 0.0, 0.0), (0.0, v["iyy"], 0.0), (0.0, 0.0, v["izz"])),
        }
        if len(x) > len(COLUMNS):
            row["limits"] = (x[-2], x[-1])
        return row
