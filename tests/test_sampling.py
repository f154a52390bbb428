"""Sampled exemplar sets for any arm and any n (selpres.data.sampled through selpres.data.task): what each route
keeps, the acceptance rate against an independent change-of-variables estimate, the wrench against virtual
work, Sobol evenness, independent streams, and the errors."""

from __future__ import annotations

import math

import pytest
import torch

from selpres.arms.sources import make_arm
from selpres.data.task import _task, load_task
from selpres.errors import ConfigError
from selpres.run.specs import robot_spec, task_specs

from conftest import cfg_of

F64 = torch.float64
PAPER_BOX = [
    "data.q=[0.0,0.5]",
    "data.dq=[0.0,1.0]",
    "data.tau=[[14.0,18.0],[4.0,8.0]]",
]  # the paper's ranges


def task_of(*overrides: str):
    cfg = cfg_of("data=sampled", *overrides)
    return load_task(*task_specs(cfg)), cfg


def split(X: torch.Tensor, dof: int):
    return X[:, :dof], X[:, dof : 2 * dof], X[:, 2 * dof :]


def test_inverse_route_targets_are_eq4_and_simulate_back(tmp_path):
    """τ = ID(q, q̇, q̈) for every pattern: the forward simulator (an LDLᵀ solve, another code path) turns
    (q, q̇, τ) back into the drawn q̈; every input lies in its box; nothing is dropped."""
    task, cfg = task_of("robot=puma560", "data.n=3000", "data.heldout=500", "topology.layers=18-40-6")
    arm = make_arm(robot_spec(cfg.robot))
    q, qd, qdd = split(task.exemplar.X, 6)
    assert torch.allclose(arm.forward_dynamics(q, qd, task.exemplar.Y), qdd, atol=1e-8, rtol=0)
    limits = arm.joint_limits()
    assert ((q >= limits[:, 0]) & (q <= limits[:, 1])).all()
    assert qd.abs().max() <= 1.0 and qdd.abs().max() <= 2.0
    assert task.info["candidates"] == 3000 and task.info["acceptance_rate"] == 1.0
    assert task.input_names[:2] == ("q1", "q2") and task.input_names[6] == "dq1" and task.input_names[-1] == "ddq6"
    assert task.output_names == tuple(f"tau{i}" for i in range(1, 7))


def test_forward_route_acceptance_matches_change_of_variables():
    """The paper's route on its own ranges, continuous: q, q̇, τ uniform, keep |q̈| <= 2. For a fixed state
    τ = Hq̈ + b maps the square |q̈| <= a onto a parallelogram of area (2a)² det H, so the acceptance rate is
    (2a)²/area(τ box) · E[det H(q) · 1(τ in box)] over q, q̇, q̈ uniform: estimated here from 10^6 draws of
    the closed form (eq. 6), independently of the route's simulation."""
    task, cfg = task_of(*PAPER_BOX, "data.route=forward", "data.draw=uniform", "data.n=2000", "data.heldout=200")
    arm = make_arm(robot_spec(cfg.robot))
    q, qd, qdd = split(task.exemplar.X, 2)
    assert qdd.abs().max() <= 2.0  # the filter
    assert (task.exemplar.Y[:, 0] >= 14).all() and (task.exemplar.Y[:, 1] <= 8).all()
    assert torch.allclose(arm.inverse_dynamics(q, qd, qdd), task.exemplar.Y, atol=1e-10, rtol=0)
    rate = task.info["acceptance_rate"]
    assert rate == 2000 / task.info["candidates"]

    g = torch.Generator().manual_seed(5)
    m = 1_000_000
    qs, qds = 0.5 * torch.rand(m, 2, dtype=F64, generator=g), torch.rand(m, 2, dtype=F64, generator=g)
    qdds = 4 * torch.rand(m, 2, dtype=F64, generator=g) - 2
    tau = arm.inverse_dynamics(qs, qds, qdds)
    inside = (tau[:, 0] >= 14) & (tau[:, 0] <= 18) & (tau[:, 1] >= 4) & (tau[:, 1] <= 8)
    expected = 16.0 / 16.0 * float((arm.det_mass_matrix(qs) * inside).mean())
    sigma = math.sqrt(expected * (1 - expected) / task.info["candidates"])  # the route's binomial error
    assert abs(rate - expected) < 4 * sigma, (rate, expected, sigma)


def test_wrench_enters_as_jacobian_transpose():
    """τ − ID(q, q̇, q̈) without the wrench = K(q)ᵀk (virtual work; K from the kinematics, not the RNEA)."""
    k = [3.0, -2.0, 0.0, 0.0, 0.0, 0.5]
    task, cfg = task_of(
        "robot=planar3",
        "data.n=500",
        "data.heldout=50",
        "topology.layers=9-5-3",
        f"data.wrench=[{','.join(map(str, k))}]",
    )
    arm = make_arm(robot_spec(cfg.robot))
    q, qd, qdd = split(task.exemplar.X, 3)
    jt_k = (arm.jacobian(q).transpose(-1, -2) @ torch.tensor(k, dtype=F64)).squeeze(-1)
    assert torch.allclose(task.exemplar.Y - arm.inverse_dynamics(q, qd, qdd), jt_k, atol=1e-10, rtol=0)
    assert task.info["wrench"] == k and task.wrench.tolist() == k


def test_sobol_points_cover_their_box_more_evenly_than_random():
    """Column means of q, q̇, q̈ against their box centres: scrambled Sobol points are off by O(1/n),
    pseudo-random ones by O(1/sqrt n)."""
    errors = {}
    for draw in ("sobol", "uniform"):
        task, _ = task_of(
            "robot=puma560",
            "data.n=4096",
            "data.heldout=100",
            "topology.layers=18-40-6",
            f"data.draw={draw}",
            "data.q=[-1.0,1.0]",
        )
        errors[draw] = float(task.exemplar.X.mean(0).abs().max())  # every box is centred on 0 here
    assert errors["sobol"] < 2e-3 < errors["uniform"], errors


def test_streams_are_independent_and_deterministic(monkeypatch):
    monkeypatch.setenv("SELPRES_DATA_CACHE", "off")  # both builds simulate (selpres.data.cache)
    base = (
        "robot=planar3",
        "data.n=300",
        "data.heldout=100",
        "topology.layers=9-5-3",
        "data.seed=0",
        "data.test_seed=0",
    )
    a, _ = task_of(*base)
    _task.cache_clear()
    b, _ = task_of(*base)
    assert torch.equal(a.exemplar.X, b.exemplar.X) and torch.equal(a.tests.heldout.X, b.tests.heldout.X)
    shared = torch.isin(a.tests.heldout.X[:, 0], a.exemplar.X[:, 0])
    assert not shared.any()  # equal seeds, yet the test stream is another stream
    c, _ = task_of(*base[:-2], "data.seed=1", "data.test_seed=0")
    assert not torch.equal(c.exemplar.X, a.exemplar.X) and torch.equal(c.tests.heldout.X, a.tests.heldout.X)
    d, _ = task_of(*base[:-1], "data.test_seed=1")
    assert torch.equal(d.exemplar.X, a.exemplar.X) and not torch.equal(d.tests.heldout.X, a.tests.heldout.X)


def test_test_sets_are_drawn_the_same_way():
    task, _ = task_of(*PAPER_BOX, "data.route=forward", "data.n=500", "data.heldout=300")
    X10, from_ex = task.tests.test10.X, task.tests.test10_from_exemplar
    assert from_ex.tolist() == [True] * 5 + [False] * 5
    for row in X10[:5]:
        assert (task.exemplar.X == row).all(1).any()
    for row in X10[5:]:
        assert not (task.exemplar.X == row).all(1).any()
    _, _, qdd = split(task.tests.heldout.X, 2)
    assert len(task.tests.heldout) == 300 and qdd.abs().max() <= 2.0


def test_every_test_pattern_from_the_exemplar_set_draws_none_outside():
    """data.test_from_exemplar = data.test_patterns is allowed: the outside draw asks for 0 patterns."""
    task, _ = task_of("data.n=1000", "data.heldout=100", "data.test_from_exemplar=10")
    assert task.tests.test10_from_exemplar.tolist() == [True] * 10
    assert all((task.exemplar.X == row).all(1).any() for row in task.tests.test10.X)


def test_heldout_as_a_fraction_of_n():
    task, _ = task_of("data.n=1000", "data.heldout=0.25")
    assert len(task.tests.heldout) == 250


def test_joint_limits_or_a_full_turn():
    task, _ = task_of("data.n=2000", "data.heldout=10")  # two_link: no limits
    q = task.exemplar.X[:, :2]
    assert q.min() >= -math.pi and q.max() <= math.pi and q.min() < -3.0 and q.max() > 3.0


def test_commanded_scaling_uses_the_boxes():
    task, _ = task_of(
        *PAPER_BOX, "data.n=500", "data.heldout=10", "data.scaling.mode=commanded", "data.scaling.margin=0"
    )
    s = task.scaler
    assert s.x_min.tolist() == [0.0, 0.0, 0.0, 0.0, -2.0, -2.0] and s.x_max.tolist() == [
        0.5,
        0.5,
        1.0,
        1.0,
        2.0,
        2.0,
    ]
    assert s.y_min.tolist() == [14.0, 4.0] and s.y_max.tolist() == [18.0, 8.0]


@pytest.mark.parametrize(
    "overrides, key, value",
    [
        (["data.q=[1.0,0.0]"], "data.q", "[1.0, 0.0]"),
        (["data.q=[[0.0,1.0],[0.0,1.0],[0.0,1.0]]"], "data.q", "[[0.0, 1.0]"),  # three pairs for two joints
        (["data.dq=[0.0,nan]"], "data.dq", "nan"),
        (["data.route=forward"], "data.tau", "None"),  # forward draws torques: it needs their box
        (["data.wrench=[1.0,0.0,0.0,0.0,0.0,0.0]"], "data.wrench", "[1.0"),  # eq. 6 has no wrench
        (["data.wrench=[1.0,0.0]", "robot=planar3", "topology.layers=9-5-3"], "data.wrench", "[1.0, 0.0]"),
        (["data.n=0"], "data.n", "0"),
        (["data.n=2000000"], "data.n", "2000000"),
        (["data.accel_limit=0"], "data.accel_limit", "0.0"),
        (["data.heldout=1.5"], "data.heldout", "1.5"),
        (["+data.path=x.csv"], "data.path", "x.csv"),  # a key of another kind
        (["data.route=sideways"], "data.route", "one of forward, inverse"),  # the route's own keys' types
        (["data.n=1e3"], "data.n", "a whole number"),
        (["data.wrench=[1,0,0,0,0,x]"], "data.wrench[5]", "a number"),
        (["data.draw=null"], "data.draw", "None"),
        (["data.scaling.mode=commanded"], "data.scaling.mode", "commanded"),  # no torque box
        (
            ["data.route=forward", "data.tau=[100.0,101.0]"],
            "data.route=forward data.accel_limit",
            "acceptance 0",
        ),
    ],
)
def test_bad_sampled_configs_name_the_key(overrides, key, value):
    from selpres.run.problem import prepare
    from selpres.run.resolve import resolve

    with pytest.raises(ConfigError) as ei:
        prepare(resolve(cfg_of("data=sampled", "data.n=500", *overrides)))
    msg = str(ei.value)
    assert ei.value.key.startswith(key) and value in msg and "\n" not in msg, msg


def test_the_paper_grid_refuses_other_arms_and_says_what_to_use():
    from selpres.run.resolve import resolve

    # an arm's file picks data=sampled for it; asking for the paper's grid explicitly is refused
    assert cfg_of("robot=puma560", "topology.layers=18-40-6").data.kind == "sampled"
    with pytest.raises(ConfigError) as ei:
        resolve(cfg_of("robot=puma560", "data=paper", "topology.layers=18-40-6"))
    assert ei.value.key == "data.kind" and "data=sampled" in str(ei.value) and "puma560" in str(ei.value)


def test_topology_that_does_not_fit_names_both():
    from selpres.run.resolve import resolve

    with pytest.raises(ConfigError) as ei:
        resolve(cfg_of("robot=puma560", "data=sampled"))
    assert str(ei.value) == (
        "topology.layers='6-13-2' is not allowed: expected a network that fits robot=puma560 (6 joints): "
        "18 inputs (q1..q6, dq1..dq6, ddq1..ddq6) and 6 outputs (tau1..tau6), e.g. 18-13-6"
    )
