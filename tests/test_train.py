"""The training loop end to end: loss falls, results are deterministic, replicas equal single-seed runs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

import selpres.config  # noqa: F401  (registers the schema)
from selpres.train import RESULTS, train

CONFIGS = str(Path(__file__).resolve().parents[1] / "configs")
SMALL = ["data.heldout=300", "eval.heldout_curve=300", "logging.progress=false"]


def cfg_of(*overrides):
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONFIGS, version_base="1.3"):
        return compose("train", overrides=[*SMALL, *overrides])


def numbers(res: dict) -> dict:
    """Everything in results.json that must be reproducible (wall times excluded)."""
    return {k: res[k] for k in ("summary", "replica_results", "curves", "schedule", "config_hash")}


@pytest.mark.parametrize("engine", ["reference", "fast"])
def test_loss_falls_and_results_are_complete(engine):
    res = train(cfg_of(f"engine={engine}", "schedule.epochs=[2,2,2,2,4]", "topology=6-8-2"))
    assert res["curves"][0]["presentations"] == 0  # the untrained network opens every curve
    curve = [rec["train_mse"][0] for rec in res["curves"][1:]]
    assert res["status"] == "complete"
    assert res["presentations_done"] == 2 * (50 + 100 + 400 + 800) + 4 * 1002
    # the first and last epoch on the full set: training reduces the error on the same patterns
    full = [rec["train_mse"][0] for rec in res["curves"] if rec["size"] == 1002]
    assert full[-1] < full[0]
    assert curve[-1] < curve[0]
    h0, h1 = res["curves"][0]["heldout_rms_nm"][0], res["curves"][-1]["heldout_rms_nm"][0]
    assert h1 < 0.7 * h0


def test_same_config_same_numbers(tmp_path):
    a = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2"), tmp_path / "a")
    b = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2"), tmp_path / "b")
    assert numbers(a) == numbers(b)
    wa = torch.load(tmp_path / "a" / "weights.pt")["params"]
    wb = torch.load(tmp_path / "b" / "weights.pt")["params"]
    assert all(torch.equal(x, y) for x, y in zip(wa, wb))
    assert json.loads((tmp_path / "a" / RESULTS).read_text())["summary"] == a["summary"]
    c = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2", "seed=5"))
    assert numbers(c)["summary"] != numbers(a)["summary"]


@pytest.mark.parametrize("engine", ["reference", "fast"])
def test_replica_r_equals_single_run_with_seed_plus_r(tmp_path, engine):
    """Weights are bit-identical; metrics agree to rounding (evaluation batches all replicas in one GEMM)."""
    many = train(cfg_of("schedule.epochs=[1,1,1,1,1]", "replicas=3", "seed=10", f"engine={engine}"), tmp_path / "many")
    one = train(cfg_of("schedule.epochs=[1,1,1,1,1]", "replicas=1", "seed=12", f"engine={engine}"), tmp_path / "one")
    w_many = torch.load(tmp_path / "many" / "weights.pt")["params"]
    w_one = torch.load(tmp_path / "one" / "weights.pt")["params"]
    assert all(torch.equal(a[2], b[0]) for a, b in zip(w_many, w_one))
    a, b = many["replica_results"][2], one["replica_results"][0]
    assert a["seed"] == b["seed"] == 12 and a["train_mse"] == b["train_mse"]
    for name in ("test10", "heldout"):
        for unit in ("nm", "scaled"):
            assert a["final"][name][unit] == pytest.approx(b["final"][name][unit], rel=1e-12)


def test_engines_agree_on_a_whole_run():
    ref = train(cfg_of("engine=reference", "schedule.epochs=[1,1,1,1,1]", "replicas=2"))
    fast = train(cfg_of("engine=fast", "schedule.epochs=[1,1,1,1,1]", "replicas=2"))
    for a, b in zip(ref["replica_results"], fast["replica_results"]):
        assert a["final"]["heldout"]["nm"]["overall"] == pytest.approx(b["final"]["heldout"]["nm"]["overall"], abs=1e-9)


def test_divergence_is_reported_not_fatal(monkeypatch):
    """Sigmoid nets saturate rather than overflow, so poison one replica's weights after epoch 3."""
    import selpres.train as T

    real = T.make_engine

    def poisoned(*args, **kwargs):
        engine = real(*args, **kwargs)
        step, calls = engine.train_epoch, []

        def train_epoch(X, Y, order):
            calls.append(1)
            if len(calls) == 4:  # before epoch 4's updates: replica 1 has a NaN weight
                state = engine.state_dict()
                state["params"][0][1, 0, 0] = float("nan")
                engine.load_state_dict(state)
            return step(X, Y, order)

        engine.train_epoch = train_epoch
        return engine

    clean = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2"))
    monkeypatch.setattr(T, "make_engine", poisoned)
    res = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2"))
    assert res["status"] == "complete" and res["diverged_replicas"] == 1
    bad, good = res["replica_results"][1], res["replica_results"][0]
    assert bad["status"] == "diverged" and bad["diverged"]["epoch"] == 4
    assert bad["diverged"]["presentations"] == 50 + 100 + 400 + 800
    assert bad["final"]["heldout"]["nm"]["overall"] is None
    assert good == clean["replica_results"][0]  # the other replica carries on untouched
    assert res["summary"]["heldout_rms_nm_overall"]["n"] == 1
    json.dumps(res, allow_nan=False)  # strict JSON: no NaN leaks into results.json


def test_a_job_whose_replicas_all_diverged_stops(monkeypatch):
    import selpres.train as T

    real = T.make_engine

    def poisoned(*args, **kwargs):
        engine = real(*args, **kwargs)
        state = engine.state_dict()
        state["params"][0][:, 0, 0] = float("inf")
        engine.load_state_dict(state)
        return engine

    monkeypatch.setattr(T, "make_engine", poisoned)
    res = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2"))
    assert res["status"] == "diverged" and res["diverged_replicas"] == 2
    assert len(res["curves"]) == 2 and res["presentations_done"] == 50  # stopped after the first epoch
    assert all(r["diverged"] == {"epoch": 1, "presentations": 50} for r in res["replica_results"])


def test_compute_matched_schedule_spends_the_budget():
    res = train(cfg_of("schedule=matched", "schedule.budget=2500"))
    assert res["presentations_done"] == 2500
    assert [rec["presentations"] for rec in res["curves"]][-1] == 2500
    assert res["schedule"]["epochs"] == [2] and res["schedule"]["extra_presentations"] == [2500 - 2 * 1002]
    assert all(math.isfinite(v) for v in res["curves"][-1]["train_mse"])
