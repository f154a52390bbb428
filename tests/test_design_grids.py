"""Every study grid is written by one script (scripts/make_*_designs.py): running it again into an empty folder
gives exactly the files on disk, so no design point is edited by hand and none is missing or left over."""

from __future__ import annotations

import runpy
import subprocess
import sys

import pytest

from conftest import REPO

SCRIPTS = sorted((REPO / "scripts").glob("make_*_designs.py"))


def test_the_known_grids_have_their_generators():
    names = {p.stem for p in SCRIPTS}
    assert {"make_modern_designs", "make_selection_designs", "make_sensitivity_designs"} <= names


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_regenerating_a_grid_changes_nothing(script, tmp_path):
    out = runpy.run_path(str(script))["OUT"]  # where the script writes its grid by default
    subprocess.run([sys.executable, str(script), str(tmp_path)], check=True, capture_output=True)
    written = {p.name: p.read_text() for p in tmp_path.glob("*.yaml")}
    on_disk = {p.name: p.read_text() for p in out.glob("*.yaml")}
    assert written, f"{script.name} wrote nothing"
    assert sorted(written) == sorted(on_disk), "design points missing or left over"
    changed = [name for name in written if written[name] != on_disk[name]]
    assert changed == [], f"edited by hand (or the script changed without a re-run): {changed}"
