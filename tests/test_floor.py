"""The task's floor and the nMSE (selpres.run.floor), checked against numpy by hand and in a real job."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from selpres.run import floor
from selpres.run.specs import task_specs

from conftest import REPO, compose, run_python


def test_nmse_and_floor_by_hand():
    g = np.random.default_rng(3)
    Y = g.normal([1.0, -4.0], [2.0, 0.5], size=(200, 2))
    err = g.normal(0, [0.3, 0.1], size=(4, 200, 2))  # four replicas' errors
    sums = torch.tensor((err**2).sum(1))
    got = floor.nmse(sums, 200, torch.tensor(Y))
    want = (err**2).mean(1) / Y.var(0)
    assert np.allclose(got["tau1"].numpy(), want[:, 0]) and np.allclose(got["tau2"].numpy(), want[:, 1])
    assert np.allclose(got["overall"].numpy(), want.mean(1))  # the literature's mean over joints
    train = g.normal([0.5, -3.0], 1.0, size=(300, 2))
    f = floor.task_floor(torch.tensor(train), {"heldout": (None, torch.tensor(Y))})["heldout"]
    d = Y - train.mean(0)
    assert math.isclose(f["nm"]["tau2"], float(np.sqrt((d[:, 1] ** 2).mean())))
    assert math.isclose(f["nm"]["overall"], float(np.sqrt((d**2).mean())))
    assert math.isclose(f["nmse"]["tau1"], float((d[:, 0] ** 2).mean() / Y[:, 0].var()))
    flat = floor.task_floor(torch.zeros(3, 1), {"heldout": (None, torch.ones(5, 1))})["heldout"]
    assert flat["nmse"]["tau1"] is None and flat["nm"]["tau1"] == 1.0  # a target that never varies: no nMSE


def test_warning_names_the_joint_within_the_margin():
    fl = {"heldout": {"nm": {"overall": 5.0, "tau1": 10.0, "tau2": 1.0}}}
    summary = {"heldout_rms_nm_tau1": {"mean": 9.5}, "heldout_rms_nm_tau2": {"mean": 0.5}}
    info = {"boxes": {"q": [[-3.0, 3.0], [0.0, 1.0]], "dq": [[-1.0, 1.0]] * 2}}
    (line,) = floor.floor_warnings(summary, fl, info, "12-5-2")
    assert line.startswith("tau1: held-out RMS 9.5 Nm is no better than predicting the training mean (10 Nm)")
    assert "data.q up to 6 wide" in line and "topology 12-5-2" in line
    assert floor.floor_warnings({"heldout_rms_nm_tau1": {"mean": 8.9}}, fl, info) == []  # 11 % better: fine


@pytest.mark.slow
def test_a_real_job_records_floor_and_nmse_consistently(tmp_path):
    """The default job: results.json's nMSE is its own RMS² ÷ the held-out torques' variance, per joint."""
    out = tmp_path / "run"
    res = run_python(str(REPO / "train.py"), f"hydra.run.dir={out}", cwd=tmp_path, timeout=600)
    assert res.returncode == 0, res.stderr
    r = json.loads((out / "results.json").read_text())
    from selpres.data.task import load_task

    cfg = compose()  # the default job's config
    task = load_task(*task_specs(cfg))
    var = task.tests.heldout.Y.var(0, unbiased=False)
    final = r["replica_results"][0]["final"]["heldout"]
    for k, joint in enumerate(("tau1", "tau2")):
        assert math.isclose(final["nmse"][joint], final["nm"][joint] ** 2 / float(var[k]), rel_tol=1e-9)
    mean = task.exemplar.Y.mean(0)
    assert math.isclose(
        r["floor"]["heldout"]["nm"]["tau1"], float((task.tests.heldout.Y[:, 0] - mean[0]).pow(2).mean().sqrt())
    )
    assert r["summary"]["heldout_rms_nmse_overall"]["mean"] == pytest.approx(final["nmse"]["overall"])
    assert r["floor_warnings"] == []
