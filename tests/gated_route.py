"""``data.kind=gated_route.GatedGrid``: the paper's grid route (``data=paper``) whose ``build`` first writes the file
``$SELPRES_TEST_GATE.reached`` and then waits (at most 120 s) for ``$SELPRES_TEST_GATE.go``. A test that signals a
job between the two knows where the job is, however fast the machine: inside its set-up, its record and log
written, its data being made, no epoch run. Found by its import path, as a user's own route is (tests/ on the
job's PYTHONPATH); :func:`env` turns the data cache off, or a cached task would skip the build."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

from selpres.data.routes.grid import Grid

OVERRIDE = "data.kind=gated_route.GatedGrid"


class GatedGrid(Grid):
    def build(self, robot, data):
        gate = Path(os.environ["SELPRES_TEST_GATE"])
        gate.with_suffix(".reached").write_text(str(os.getpid()))
        deadline = time.monotonic() + 120
        while not gate.with_suffix(".go").exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        return super().build(robot, data)


def env(gate: Path) -> dict[str, str]:
    """The variables a job run through ``gate`` needs besides its usual ones (tests/ on its path is the caller's)."""
    return {"SELPRES_TEST_GATE": str(gate), "SELPRES_DATA_CACHE": "off"}


def reached(gate: Path) -> Path:
    """The file a gated job writes as it is held in its build."""
    return gate.with_suffix(".reached")


def signal_when(p: subprocess.Popen, mark: Path, sig: int, gate: Path | None = None, timeout: float = 120) -> None:
    """Send ``sig`` to ``p`` once ``mark`` exists (or ``p`` has ended), then open ``gate``: a job held in its build
    goes on if its stop waits for the set-up's next check. ``mark`` is ``gate``'s ``.reached`` for a gated job."""
    deadline = time.monotonic() + timeout
    while not mark.exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    p.send_signal(sig)
    if gate is not None:
        gate.with_suffix(".go").touch()
