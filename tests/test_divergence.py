"""A replica whose loss or weights turn NaN/inf is marked diverged; the others carry on."""

from __future__ import annotations

import json

from selpres.run.train import train

from conftest import cfg_of


def test_divergence_is_reported_not_fatal(monkeypatch):
    """Sigmoid nets saturate rather than overflow, so poison one replica's weights after epoch 3."""
    import selpres.run.problem as T

    real = T.build_engine

    def poisoned(*args, **kwargs):
        engine = real(*args, **kwargs)
        step, calls = engine.train_epoch, []

        def train_epoch(X, Y, order, **kw):  # the one epoch call (weights, counts, spent)
            calls.append(1)
            if len(calls) == 4:  # before epoch 4's updates: replica 1 has a NaN weight
                state = engine.state_dict()
                state["params"][0][1, 0, 0] = float("nan")
                engine.load_state_dict(state)
            return step(X, Y, order, **kw)

        engine.train_epoch = train_epoch
        return engine

    clean = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2"))
    monkeypatch.setattr(T, "build_engine", poisoned)
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
    import selpres.run.problem as T

    real = T.build_engine

    def poisoned(*args, **kwargs):
        engine = real(*args, **kwargs)
        state = engine.state_dict()
        state["params"][0][:, 0, 0] = float("inf")
        engine.load_state_dict(state)
        return engine

    monkeypatch.setattr(T, "build_engine", poisoned)
    res = train(cfg_of("schedule.epochs=[1,1,1,1,2]", "replicas=2"))
    assert res["status"] == "diverged" and res["diverged_replicas"] == 2
    assert len(res["curves"]) == 2 and res["presentations_done"] == 50  # stopped after the first epoch
    assert all(r["diverged"] == {"epoch": 1, "presentations": 50} for r in res["replica_results"])
