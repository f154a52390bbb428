"""Exemplar set (paper section 5.1), outside/test sets, scaling, RMS metric and export."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from selpres import patterns as P
from selpres.arms.two_link import TwoLinkArm
from selpres.data import export as E
from selpres.data import paper as D

CONFIGS = Path(__file__).parents[1] / "configs"
ROBOT_CFG = OmegaConf.load(CONFIGS / "robot/two_link.yaml")
DATA_CFG = OmegaConf.load(CONFIGS / "data/paper.yaml")
ARM = TwoLinkArm.from_config(ROBOT_CFG)
F64 = torch.float64


@pytest.fixture(scope="module")
def exemplar() -> P.ExemplarSet:
    return D.build_exemplar_set(ARM, DATA_CFG)


@pytest.fixture(scope="module")
def tests_small(exemplar) -> P.TestSets:
    cfg = OmegaConf.merge(DATA_CFG, {"heldout": 500})
    return D.make_test_sets(ARM, cfg, exemplar, seed=3)


def _data(**over):
    return OmegaConf.merge(DATA_CFG, over)


# ------------------------------------------------------------------------------------------ config


def test_data_config_has_exactly_the_agreed_keys():
    assert set(DATA_CFG.keys()) == {
        "kind",
        "theta",
        "dtheta",
        "tau1",
        "tau2",
        "accel_limit",
        "test_patterns",
        "test_from_exemplar",
        "heldout",
        "test_seed",
        "scaling",
    }
    assert DATA_CFG.kind == "grid" and ROBOT_CFG._target_ == "selpres.arms.sources.two_link.TwoLink"
    assert set(DATA_CFG.scaling.keys()) == {"mode", "margin", "lo", "hi"}
    assert set(ROBOT_CFG.keys()) == {"_target_", "m1", "m2", "l1", "l2", "g"}


# ------------------------------------------------------------------------------------------ grid


def test_grid_axis_endpoints_exact_and_counts():
    t1 = D.grid_axis(14.0, 18.0, 0.1)
    assert t1.dtype == F64 and len(t1) == 41 and t1[0] == 14.0 and t1[-1] == 18.0
    assert t1[10].item() == 14.0 + 10 * 0.1  # built as lo + i*step, not by repeated addition
    t2 = D.grid_axis(4.0, 8.0, 0.1)
    assert len(t2) == 41 and t2[-1] == 8.0
    th = D.grid_axis(0.0, 0.5, 0.125)
    assert th.tolist() == [0.0, 0.125, 0.25, 0.375, 0.5]
    assert D.grid_axis(0.0, 1.0, 0.25).tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert D.grid_axis(2.0, 2.0, 0.5).tolist() == [2.0]


@pytest.mark.parametrize("lo,hi,step", [(0, 1, 0), (0, 1, -0.1), (1, 0, 0.1), (0, 1, 0.3)])
def test_grid_axis_rejects_bad_ranges_naming_the_key(lo, hi, step):
    with pytest.raises(ValueError, match="tau1"):
        D.grid_axis(lo, hi, step, name="tau1")


def test_bad_config_range_names_key():
    with pytest.raises(ValueError, match="dtheta"):
        D.build_exemplar_set(ARM, _data(dtheta={"lo": 1.0, "hi": 0.0}))


def test_accel_filter_boundary_is_inclusive():
    a = torch.tensor(
        [[2.0, -2.0], [-2.0, 0.0], [math.nextafter(2.0, 3.0), 0.0], [0.0, -math.nextafter(2.0, 3.0)]], dtype=F64
    )
    assert D.accel_filter(a, 2.0).tolist() == [True, True, False, False]


# -------------------------------------------------------------------------------------- exemplar set


def test_exemplar_set_has_paper_size(exemplar):
    assert exemplar.n_candidates == 5**4 * 41**2 == 1_050_625
    assert len(exemplar) == 1002
    assert exemplar.X.shape == (1002, 6) and exemplar.Y.shape == (1002, 2)
    assert exemplar.X.dtype == exemplar.Y.dtype == F64


def test_exemplar_rows_are_grid_points_and_consistent_with_the_simulator(exemplar):
    X, Y = exemplar
    q, qd, qdd = X[:, [0, 3]], X[:, [1, 4]], X[:, [2, 5]]
    on_grid = lambda v, lo, step: torch.allclose((v - lo) / step, ((v - lo) / step).round(), atol=1e-9)
    assert on_grid(q, 0.0, 0.125) and on_grid(qd, 0.0, 0.25)
    assert on_grid(Y[:, 0], 14.0, 0.1) and on_grid(Y[:, 1], 4.0, 0.1)
    assert (qdd.abs() <= 2.0).all()
    torch.testing.assert_close(ARM.inverse_dynamics(q, qd, qdd), Y, rtol=0, atol=1e-10)
    assert len(torch.unique(torch.cat((X, Y), 1), dim=0)) == 1002


def test_default_robot_count_is_not_a_rounding_accident():
    """No candidate within 1e-9 of the ±2 boundary, and gravity torques at θ = 0 inside the commanded boxes."""
    th, w = D.grid_axis(0, 0.5, 0.125), D.grid_axis(0, 1, 0.25)
    s = torch.cartesian_prod(th, w, th, w)
    tau = torch.cartesian_prod(D.grid_axis(14, 18, 0.1), D.grid_axis(4, 8, 0.1))
    qdd = ARM.forward_dynamics(s[:, None, [0, 2]], s[:, None, [1, 3]], tau)
    assert (qdd.abs() - 2.0).abs().min() > 1e-9
    assert int(D.accel_filter(qdd, 2.0).sum()) == 1002
    G = ARM.gravity(torch.zeros(2, dtype=F64))
    assert 14 <= G[0] <= 18 and 4 <= G[1] <= 8


def test_exemplar_set_deterministic_fast_and_config_driven(exemplar):
    t0 = time.perf_counter()
    again = D.build_exemplar_set(ARM, DATA_CFG)
    assert time.perf_counter() - t0 < 1.0
    assert torch.equal(again.X, exemplar.X) and torch.equal(again.Y, exemplar.Y)
    # lexicographic order θ1, θ̇1, θ2, θ̇2, τ1, τ2
    key = torch.stack(
        (exemplar.X[:, 0], exemplar.X[:, 1], exemplar.X[:, 3], exemplar.X[:, 4], exemplar.Y[:, 0], exemplar.Y[:, 1]), 1
    )
    diffs = key[1:] - key[:-1]
    first_nonzero = diffs[torch.arange(len(diffs)), (diffs != 0).int().argmax(1)]
    assert (first_nonzero > 0).all()
    wider = D.build_exemplar_set(ARM, _data(accel_limit=3.0))
    assert wider.n_candidates == exemplar.n_candidates and len(wider) > len(exemplar)


# ---------------------------------------------------------------------------------- outside patterns


def _check_outside(X, Y, cfg=DATA_CFG):
    q, qd, qdd = X[:, [0, 3]], X[:, [1, 4]], X[:, [2, 5]]
    assert ((q >= cfg.theta.lo) & (q <= cfg.theta.hi)).all()
    assert ((qd >= cfg.dtheta.lo) & (qd <= cfg.dtheta.hi)).all()
    assert D.accel_filter(qdd, cfg.accel_limit).all()
    assert ((Y[:, 0] >= cfg.tau1.lo) & (Y[:, 0] <= cfg.tau1.hi)).all()
    assert ((Y[:, 1] >= cfg.tau2.lo) & (Y[:, 1] <= cfg.tau2.hi)).all()
    torch.testing.assert_close(ARM.forward_dynamics(q, qd, Y), qdd, rtol=0, atol=1e-9)


def test_sample_outside_rows_pass_filter_and_lie_in_the_box():
    X, Y = D.sample_outside(ARM, DATA_CFG, 2000, torch.Generator().manual_seed(0))
    assert X.shape == (2000, 6) and Y.shape == (2000, 2) and X.dtype == F64
    _check_outside(X, Y)


def test_sample_outside_deterministic_for_a_generator_state():
    a = D.sample_outside(ARM, DATA_CFG, 300, torch.Generator().manual_seed(5))
    b = D.sample_outside(ARM, DATA_CFG, 300, torch.Generator().manual_seed(5))
    c = D.sample_outside(ARM, DATA_CFG, 300, torch.Generator().manual_seed(6))
    assert torch.equal(a.X, b.X) and torch.equal(a.Y, b.Y) and not torch.equal(a.X, c.X)


def _plain_rejection(count: int, seed: int, chunk: int = 1_000_000):
    """Reference: state and τ uniform in their boxes, simulate, keep |θ̈| <= a (accepts ~0.09 %)."""
    g = torch.Generator().manual_seed(seed)
    c = DATA_CFG
    rows = []
    have = 0
    while have < count:
        u = lambda lo, hi: lo + (hi - lo) * torch.rand(chunk, dtype=F64, generator=g)
        q = torch.stack((u(c.theta.lo, c.theta.hi), u(c.theta.lo, c.theta.hi)), -1)
        qd = torch.stack((u(c.dtheta.lo, c.dtheta.hi), u(c.dtheta.lo, c.dtheta.hi)), -1)
        tau = torch.stack((u(c.tau1.lo, c.tau1.hi), u(c.tau2.lo, c.tau2.hi)), -1)
        qdd = ARM.forward_dynamics(q, qd, tau)
        k = D.accel_filter(qdd, c.accel_limit)
        rows.append(torch.cat((q[k, :1], qd[k, :1], qdd[k, :1], q[k, 1:], qd[k, 1:], qdd[k, 1:], tau[k]), 1))
        have += int(k.sum())
    return torch.cat(rows)[:count]


def _distribution_mismatches(a: torch.Tensor, b: torch.Tensor) -> list[str]:
    """Per column: mean difference beyond 5 standard errors, or two-sample KS statistic beyond its α = 1e-4 level."""
    n, m = len(a), len(b)
    ks_crit = math.sqrt(-math.log(1e-4 / 2) / 2) * math.sqrt((n + m) / (n * m))
    bad = []
    for j, name in enumerate(D.COLUMN_NAMES):
        x, y = a[:, j], b[:, j]
        se = math.sqrt(x.var().item() / n + y.var().item() / m)
        if abs(x.mean().item() - y.mean().item()) > 5 * se:
            bad.append(f"{name}: mean")
        grid = torch.cat((x, y)).sort().values
        cdf = lambda v: torch.searchsorted(v.sort().values, grid, right=True).to(F64) / len(v)
        if (cdf(x) - cdf(y)).abs().max().item() > ks_crit:
            bad.append(f"{name}: KS")
    return bad


@pytest.fixture(scope="module")
def rejection_reference():
    return _plain_rejection(3000, seed=11)


def test_sample_outside_matches_plain_rejection_sampling(rejection_reference):
    X, Y = D.sample_outside(ARM, DATA_CFG, 3000, torch.Generator().manual_seed(12))
    assert _distribution_mismatches(torch.cat((X, Y), 1), rejection_reference) == []


def test_distribution_test_detects_missing_det_h_reweighting(rejection_reference):
    """The comparison above has power: dropping the det H(q) reweighting is caught."""
    X, Y = D.sample_outside(ARM, DATA_CFG, 3000, torch.Generator().manual_seed(12), _reweight=False)
    assert any(s.startswith("theta2") for s in _distribution_mismatches(torch.cat((X, Y), 1), rejection_reference))


# ------------------------------------------------------------------------------------------ test sets


def test_make_test_sets_composition_and_determinism(exemplar, tests_small):
    t = tests_small
    assert t.test10.X.shape == (10, 6) and t.test10.Y.shape == (10, 2)
    assert t.heldout.X.shape == (500, 6)
    assert t.test10_from_exemplar.tolist() == [True] * 5 + [False] * 5
    ex_rows = torch.cat(tuple(exemplar), 1)
    rows = torch.cat(tuple(t.test10), 1)
    in_ex = (rows[:, None, :] == ex_rows[None]).all(-1).any(-1)
    assert in_ex.tolist() == t.test10_from_exemplar.tolist()
    assert len(torch.unique(rows[:5], dim=0)) == 5
    _check_outside(t.test10.X[5:], t.test10.Y[5:])
    _check_outside(*t.heldout)
    again = D.make_test_sets(ARM, _data(heldout=500), exemplar, seed=3)
    other = D.make_test_sets(ARM, _data(heldout=500), exemplar, seed=4)
    assert torch.equal(again.test10.X, t.test10.X) and torch.equal(again.heldout.Y, t.heldout.Y)
    assert not torch.equal(other.test10.X, t.test10.X)


def test_make_test_sets_rejects_impossible_split(exemplar):
    with pytest.raises(ValueError, match="test_from_exemplar"):
        D.make_test_sets(ARM, _data(test_from_exemplar=11), exemplar, seed=0)


# ---------------------------------------------------------------------------------------------- scaling


@pytest.mark.parametrize("mode", ["exemplar", "commanded"])
def test_scaler_is_invertible(exemplar, tests_small, mode):
    cfg = _data(scaling={"mode": mode})
    s = P.Scaler.fit(exemplar, cfg.scaling, D.grid_bounds(cfg))
    for X, Y in (exemplar, tests_small.heldout):
        torch.testing.assert_close(s.inverse_y(s.transform_y(Y)), Y, rtol=0, atol=1e-12)
        torch.testing.assert_close(s.inverse_x(s.transform_x(X)), X, rtol=0, atol=1e-12)


def test_exemplar_scaling_maps_into_sigmoid_range_with_margin(exemplar):
    s = P.Scaler.fit(exemplar, DATA_CFG.scaling)
    for v in (s.transform_y(exemplar.Y), s.transform_x(exemplar.X)):
        lo_in = 0.1 + 0.8 * 0.1 / 1.2  # margin 0.1 of the range on each side
        torch.testing.assert_close(v.min(0).values, torch.full((v.shape[1],), lo_in, dtype=F64))
        torch.testing.assert_close(v.max(0).values, torch.full((v.shape[1],), 0.9 - (lo_in - 0.1), dtype=F64))
        assert ((v >= 0.1) & (v <= 0.9)).all()


def test_commanded_scaling_squeezes_targets(exemplar):
    """Why 'exemplar' is the default: with the commanded boxes the exemplar targets use a fraction of (lo, hi)."""
    cfg = _data(scaling={"mode": "commanded"})
    s = P.Scaler.fit(exemplar, cfg.scaling, D.grid_bounds(cfg))
    ys = s.transform_y(exemplar.Y)
    spread = ys.max(0).values - ys.min(0).values
    assert (spread < 0.4).all()  # exemplar mode gives 0.667 for both
    torch.testing.assert_close(
        s.transform_y(torch.tensor([14.0, 4.0], dtype=F64)), torch.full((2,), 0.1 + 0.8 / 12, dtype=F64)
    )


def test_scaler_rejects_unknown_mode(exemplar):
    with pytest.raises(ValueError, match="scaling.mode"):
        P.Scaler.fit(exemplar, _data(scaling={"mode": "minmax"}).scaling)
    with pytest.raises(ValueError, match="commanded boxes"):  # the boxes are the route's, never guessed here
        P.Scaler.fit(exemplar, _data(scaling={"mode": "commanded"}).scaling)


# -------------------------------------------------------------------------------------------- metric


def test_rms_errors_units_and_replica_dim(exemplar, tests_small):
    s = P.Scaler.fit(exemplar, DATA_CFG.scaling)
    Y = tests_small.test10.Y
    offset = torch.tensor([[0.0, 0.0], [0.3, 0.0], [0.3, 0.4]], dtype=F64)  # three replicas, Nm
    pred = s.transform_y(Y[None] + offset[:, None, :])  # [3, 10, 2]
    r = P.rms_errors(pred, Y, s)
    assert set(r) == {f"{k}_{u}" for k in ("tau1", "tau2", "overall") for u in ("Nm", "scaled")}
    assert all(v.shape == (3,) for v in r.values())
    torch.testing.assert_close(r["tau1_Nm"], torch.tensor([0.0, 0.3, 0.3], dtype=F64))
    torch.testing.assert_close(r["tau2_Nm"], torch.tensor([0.0, 0.0, 0.4], dtype=F64))
    torch.testing.assert_close(
        r["overall_Nm"], torch.tensor([0.0, math.sqrt(0.09 / 2), math.sqrt(0.25 / 2)], dtype=F64)
    )
    gain = (s.hi - s.lo) / (s.y_max - s.y_min)
    torch.testing.assert_close(r["tau1_scaled"], r["tau1_Nm"] * gain[0])
    torch.testing.assert_close(r["tau2_scaled"], r["tau2_Nm"] * gain[1])
    single = P.rms_errors(pred[2], Y, s)
    assert single["overall_Nm"].shape == () and torch.isclose(single["overall_Nm"], r["overall_Nm"][2])


# --------------------------------------------------------------------------------------------- export


def test_config_hash_is_canonical():
    h = E.config_hash(ROBOT_CFG, DATA_CFG)
    assert len(h) == 16 and int(h, 16) >= 0
    as_dict = OmegaConf.to_container(ROBOT_CFG)
    as_dict["m2"] = 3  # int vs float, plain dict vs DictConfig, key order: same data, same hash
    assert E.config_hash(dict(reversed(list(as_dict.items()))), DATA_CFG) == h
    assert E.config_hash(OmegaConf.merge(ROBOT_CFG, {"m1": 0.43}), DATA_CFG) != h
    assert E.config_hash(ROBOT_CFG, _data(accel_limit=2.5)) != h


def test_export_round_trip_exact(tmp_path, exemplar, tests_small):
    stem = tmp_path / "sub" / "exemplar"
    paths = E.export(stem, exemplar, tests_small, ROBOT_CFG, DATA_CFG)
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == [
        "exemplar.npz",
        "exemplar_exemplar.csv",
        "exemplar_heldout.csv",
        "exemplar_test10.csv",
    ]  # no temp files left behind
    arr = E.load_exported(paths["npz"], ROBOT_CFG, DATA_CFG)
    h = E.config_hash(ROBOT_CFG, DATA_CFG)
    assert str(arr["config_hash"]) == h
    assert tuple(arr["input_names"]) == D.INPUT_NAMES and tuple(arr["target_names"]) == D.TARGET_NAMES
    sets = {"exemplar": exemplar, "test10": tests_small.test10, "heldout": tests_small.heldout}
    for name, p in sets.items():
        assert np.array_equal(arr[f"{name}_X"], p.X.numpy()) and np.array_equal(arr[f"{name}_Y"], p.Y.numpy())
        found, cols, table = E.load_csv(paths[name], ROBOT_CFG, DATA_CFG)
        assert found == h and cols == D.COLUMN_NAMES
        assert np.array_equal(table, torch.cat((p.X, p.Y), 1).numpy())  # bit-identical via %.17g
        assert paths[name].read_text().splitlines()[0] == f"# config_hash={h}"
    assert np.array_equal(arr["test10_from_exemplar"], tests_small.test10_from_exemplar.numpy())


def test_load_refuses_data_made_with_another_config(tmp_path, exemplar, tests_small):
    paths = E.export(tmp_path / "d", exemplar, tests_small, ROBOT_CFG, DATA_CFG)
    other_robot = OmegaConf.merge(ROBOT_CFG, {"l2": 0.27})
    h_old, h_new = E.config_hash(ROBOT_CFG, DATA_CFG), E.config_hash(other_robot, DATA_CFG)
    with pytest.raises(E.DataMismatchError, match=f"{h_old}.*{h_new}"):
        E.load_exported(paths["npz"], other_robot, DATA_CFG)
    with pytest.raises(ValueError):
        E.load_exported(paths["npz"], ROBOT_CFG, _data(heldout=10))
    with pytest.raises(E.DataMismatchError):
        E.load_csv(paths["exemplar"], other_robot, DATA_CFG)
