"""Same config + same seed => bit-identical results.json numbers and weights, for every engine."""

from __future__ import annotations

import json

import pytest
import torch

import selpres.data.task as task
from selpres.run.train import train
from selpres.storage import RESULTS

from conftest import cfg_of, numbers, requires_native


@pytest.mark.parametrize(
    "engine",
    [pytest.param("reference", marks=pytest.mark.slow), "torch", pytest.param("native", marks=requires_native)],
)
def test_same_config_same_numbers(tmp_path, engine, monkeypatch):
    monkeypatch.setenv("SELPRES_DATA_CACHE", "off")  # both runs simulate their data (selpres.data.cache)
    a = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2", f"engine={engine}"), tmp_path / "a")
    task._task.cache_clear()  # the second run rebuilds its data too, as a new process would
    b = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2", f"engine={engine}"), tmp_path / "b")
    assert numbers(a) == numbers(b)
    wa = torch.load(tmp_path / "a" / "weights.pt")["params"]
    wb = torch.load(tmp_path / "b" / "weights.pt")["params"]
    assert all(torch.equal(x, y) for x, y in zip(wa, wb))
    assert json.loads((tmp_path / "a" / RESULTS).read_text())["summary"] == a["summary"]
    c = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2", "seed=5", f"engine={engine}"))
    assert numbers(c)["summary"] != numbers(a)["summary"]
