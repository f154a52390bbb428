"""Exported data carries the hash of the robot/data config that made it; another config is refused."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from selpres.data.export import DataMismatchError, load_csv, load_exported

from conftest import cfg_of

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow  # subprocesses


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    stem = tmp_path_factory.mktemp("data") / "ex"
    out = subprocess.run(
        [sys.executable, "-m", "selpres.run.export", "--out", str(stem), "data.heldout=300"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    return stem


def test_files_load_under_the_training_config_that_matches(exported):
    cfg = cfg_of("data.heldout=300")  # composed as train.py composes it: same schema, same test_seed
    arrays = load_exported(exported.with_suffix(".npz"), cfg.robot, cfg.data)
    assert arrays["exemplar_X"].shape == (1002, 6) and arrays["heldout_X"].shape == (300, 6)
    h, names, table = load_csv(exported.with_name("ex_exemplar.csv"), cfg.robot, cfg.data)
    assert h == str(arrays["config_hash"]) and names[:3] == ("theta1", "dtheta1", "ddtheta1")
    assert np.array_equal(table[:, :6], arrays["exemplar_X"])  # %.17g round-trips float64 exactly


@pytest.mark.parametrize("change", ["robot.m2=3.01", "data.test_seed=1", "data.heldout=301", "data.accel_limit=2.1"])
def test_files_made_under_another_config_are_refused(exported, change):
    cfg = cfg_of("data.heldout=300", change)
    with pytest.raises(DataMismatchError, match="config_hash"):
        load_exported(exported.with_suffix(".npz"), cfg.robot, cfg.data)
    with pytest.raises(DataMismatchError):
        load_csv(exported.with_name("ex_heldout.csv"), cfg.robot, cfg.data)


def test_export_refuses_bad_overrides_without_a_traceback(tmp_path):
    for bad in ("data.tau1.step=0.3", "seed=3", "data.nope=1", "--bogus", "nonsense"):
        out = subprocess.run(
            [sys.executable, "-m", "selpres.run.export", "--out", str(tmp_path / "x"), bad],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert out.returncode == 2 and "error:" in out.stderr and "Traceback" not in out.stderr, bad
        assert not list(tmp_path.iterdir())  # nothing half-written


def test_export_help_prints_usage_and_writes_nothing(tmp_path):
    """--help is an option, not an output stem (it used to write --help.npz into the checkout)."""
    out = subprocess.run(
        [sys.executable, "-m", "selpres.run.export", "--help"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0 and "usage:" in out.stdout and "--out" in out.stdout
    assert not list(tmp_path.iterdir())
