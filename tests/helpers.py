"""Small helpers shared by the training tests (imported as a plain module: pytest puts tests/ on sys.path)."""

from __future__ import annotations

from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

import selpres.config  # noqa: F401  (registers the schema)

CONFIGS = str(Path(__file__).resolve().parents[1] / "configs")
SMALL = ["data.heldout=300", "eval.heldout_curve=300", "logging.progress=false"]


def cfg_of(*overrides):
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONFIGS, version_base="1.3"):
        return compose("train", overrides=[*SMALL, *overrides])


def numbers(res: dict) -> dict:
    """Everything in results.json that must be reproducible (wall times excluded)."""
    return {k: res[k] for k in ("summary", "replica_results", "curves", "schedule", "config_hash")}
