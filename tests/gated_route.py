"""``data.kind=gated_route.GatedGrid``: the paper's grid route (``data=paper``) whose ``build`` first writes the file
``$SELPRES_TEST_GATE.reached`` and then waits (at most 120 s) for ``$SELPRES_TEST_GATE.go``. A test that signals a
job between the two knows where the job is, however fast the machine: inside its set-up, its record and log
written, its data being made, no epoch run. Found by its import path, as a user's own route is (tests/ on the
job's PYTHONPATH); run it with the data cache off, or a cached task skips the build."""

from __future__ import annotations

import os
import time
from pathlib import Path

from selpres.data.routes.grid import Grid


class GatedGrid(Grid):
    def build(self, robot, data):
        gate = Path(os.environ["SELPRES_TEST_GATE"])
        gate.with_suffix(".reached").write_text(str(os.getpid()))
        deadline = time.monotonic() + 120
        while not gate.with_suffix(".go").exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        return super().build(robot, data)
