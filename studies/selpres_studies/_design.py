"""A study's design file: the roles, orders and rules a study states in YAML before it runs, read into its dataclass."""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf


def read_design(cls, path: Path):
    """``cls(**path's mapping)``, its ``order`` as a tuple (the rows' order, listed first in every table)."""
    d = OmegaConf.to_container(OmegaConf.load(path))
    return cls(**{**d, "order": tuple(d.get("order") or ())})
