"""The Hydra callback by which a sweep names its report's plug-ins: an experiment config sets

    hydra:
      callbacks:
        report: {_target_: selpres.report.callback.ReportSections, sections: [selpres_studies]}

Hydra records the node in the sweep's ``multirun.yaml``, where ``selpres-report`` reads it
(:func:`selpres.report.plugins.recorded`); the job's config, and so its identity, are untouched. At the sweep's start
it says, one line each, which plug-ins cannot be found here (an install without the repository's studies): the jobs
still run, and their report lacks those sections, saying so again.
"""

from __future__ import annotations

import sys
from typing import Any

from hydra.experimental.callback import Callback

from selpres.report.plugins import unavailable


class ReportSections(Callback):
    """``sections``: the plug-ins (import paths) whose sections the report of this sweep shows."""

    def __init__(self, sections: list[str]) -> None:
        self.sections = [str(s) for s in sections]

    def on_multirun_start(self, config: Any, **kwargs: Any) -> None:
        for line in unavailable(self.sections):
            print(f"warning: {line}", file=sys.stderr)
