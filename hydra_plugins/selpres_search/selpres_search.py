"""Registers selpres's schedule-search sweeper with Hydra where the Optuna sweeper plugin is installed.

Hydra imports every module of ``hydra_plugins`` at start-up; without ``hydra-optuna-sweeper`` (the search's
optional dependencies) this module registers nothing, so plain runs stay quiet, and ``experiment=search``
stops at Hydra's own message that ``hydra/sweeper=optuna`` is not available.
"""

import importlib.util

if importlib.util.find_spec("hydra_plugins.hydra_optuna_sweeper") is not None:
    from hydra_plugins.selpres_search._sweeper import ShapedScheduleSweeper  # noqa: F401
