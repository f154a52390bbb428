"""TwoLinkArm (paper eq. 6) against an independent Euler–Lagrange derivation done with autograd."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

from selpres.arms.two_link import TwoLinkArm

ARM = TwoLinkArm(m1=0.42, m2=3.0, l1=0.2, l2=0.26, g=9.81)
D = torch.float64


def _positions(arm: TwoLinkArm, q: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Cartesian positions of the two point masses; θ1 from the horizontal, θ2 relative to link 1."""
    x1, y1 = arm.l1 * torch.cos(q[0]), arm.l1 * torch.sin(q[0])
    x2, y2 = x1 + arm.l2 * torch.cos(q[0] + q[1]), y1 + arm.l2 * torch.sin(q[0] + q[1])
    return torch.stack((x1, y1)), torch.stack((x2, y2))


def _lagrangian(arm: TwoLinkArm):
    def L(q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        p1, p2 = _positions(arm, q)
        # velocities from the Jacobians of the positions: v = (∂p/∂q) q̇
        v1 = torch.func.jvp(lambda x: _positions(arm, x)[0], (q,), (qd,))[1]
        v2 = torch.func.jvp(lambda x: _positions(arm, x)[1], (q,), (qd,))[1]
        T = 0.5 * arm.m1 * v1.dot(v1) + 0.5 * arm.m2 * v2.dot(v2)
        V = arm.g * (arm.m1 * p1[1] + arm.m2 * p2[1])
        return T - V

    return L


def reference_torque(arm: TwoLinkArm, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor) -> torch.Tensor:
    """τ = d/dt ∂L/∂q̇ − ∂L/∂q = (∂²L/∂q̇²) q̈ + (∂²L/∂q̇∂q) q̇ − ∂L/∂q, for a batch [B, 2]."""
    L = _lagrangian(arm)
    dL_dqd = torch.func.grad(L, argnums=1)
    M = torch.func.vmap(torch.func.jacrev(dL_dqd, argnums=1))(q, qd)  # ∂²L/∂q̇²
    K = torch.func.vmap(torch.func.jacrev(dL_dqd, argnums=0))(q, qd)  # ∂²L/∂q̇∂q
    dL_dq = torch.func.vmap(torch.func.grad(L, argnums=0))(q, qd)
    return (M @ qdd[..., None]).squeeze(-1) + (K @ qd[..., None]).squeeze(-1) - dL_dq


def _states(n: int, seed: int = 0, shape: tuple[int, ...] | None = None):
    g = torch.Generator().manual_seed(seed)
    shape = shape or (n,)
    q = (torch.rand(*shape, 2, dtype=D, generator=g) - 0.5) * 2 * torch.pi
    qd = (torch.rand(*shape, 2, dtype=D, generator=g) - 0.5) * 6
    qdd = (torch.rand(*shape, 2, dtype=D, generator=g) - 0.5) * 10
    return q, qd, qdd


@pytest.mark.parametrize("arm", [ARM, TwoLinkArm(1.3, 0.7, 0.9, 0.45, 3.7)])
def test_inverse_dynamics_matches_euler_lagrange(arm):
    q, qd, qdd = _states(64, seed=1)
    ref = reference_torque(arm, q, qd, qdd)
    torch.testing.assert_close(arm.inverse_dynamics(q, qd, qdd), ref, rtol=0, atol=1e-10)


def test_mass_matrix_matches_euler_lagrange_hessian():
    q, qd, _ = _states(32, seed=2)
    M = torch.func.vmap(torch.func.hessian(_lagrangian(ARM), argnums=1))(q, qd)
    torch.testing.assert_close(ARM.mass_matrix(q), M, rtol=0, atol=1e-12)
    torch.testing.assert_close(ARM.det_mass_matrix(q), torch.linalg.det(M), rtol=0, atol=1e-12)


def test_reference_detects_a_wrong_model():
    """Guards against a vacuous comparison: a slightly different arm must disagree with the reference."""
    q, qd, qdd = _states(16, seed=3)
    ref = reference_torque(ARM, q, qd, qdd)
    wrong = dataclasses.replace(ARM, m2=ARM.m2 * (1 + 1e-6))
    assert (wrong.inverse_dynamics(q, qd, qdd) - ref).abs().max() > 1e-8


def test_forward_inverts_inverse_dynamics():
    q, qd, _ = _states(1000, seed=4)
    tau = torch.rand(1000, 2, dtype=D, generator=torch.Generator().manual_seed(5)) * 20 - 5
    qdd = ARM.forward_dynamics(q, qd, tau)
    torch.testing.assert_close(ARM.inverse_dynamics(q, qd, qdd), tau, rtol=0, atol=1e-10)


def test_mass_matrix_symmetric_positive_definite():
    q, _, _ = _states(1000, seed=6)
    H = ARM.mass_matrix(q)
    assert torch.equal(H, H.transpose(-1, -2))
    assert (torch.linalg.eigvalsh(H) > 0).all()


def test_batch_shapes_and_broadcasting():
    q, qd, qdd = _states(0, seed=7, shape=(3, 4))
    assert ARM.mass_matrix(q).shape == (3, 4, 2, 2)
    assert ARM.coriolis(q, qd).shape == ARM.gravity(q).shape == (3, 4, 2)
    tau = ARM.inverse_dynamics(q, qd, qdd)
    assert tau.shape == (3, 4, 2) and tau.dtype == D
    flat = ARM.inverse_dynamics(q.reshape(-1, 2), qd.reshape(-1, 2), qdd.reshape(-1, 2))
    torch.testing.assert_close(tau.reshape(-1, 2), flat, rtol=0, atol=0)
    # state [S,1,2] against torques [T,2] broadcasts to [S,T,2], as the exemplar grid uses it
    out = ARM.forward_dynamics(q[0, :, None], qd[0, :, None], tau[1])
    assert out.shape == (4, 4, 2)
    torch.testing.assert_close(out[2, 3], ARM.forward_dynamics(q[0, 2], qd[0, 2], tau[1, 3]))


def test_dtype_follows_inputs():
    q, qd, qdd = (t.float() for t in _states(5, seed=8))
    assert ARM.inverse_dynamics(q, qd, qdd).dtype == torch.float32
    assert ARM.forward_dynamics(q, qd, qdd).dtype == torch.float32


def test_energy_balance_power_equals_torque_times_velocity():
    """dE/dt = q̇·τ with E = ½ q̇ᵀH q̇ + V(q): ties H, C and G together (C must be consistent with ∂H/∂q)."""
    q, qd, _ = _states(50, seed=9)
    tau = torch.rand(50, 2, dtype=D, generator=torch.Generator().manual_seed(10)) * 10
    qdd = ARM.forward_dynamics(q, qd, tau)

    def energy(q1, qd1):
        p1, p2 = _positions(ARM, q1)
        V = ARM.g * (ARM.m1 * p1[1] + ARM.m2 * p2[1])
        return 0.5 * qd1 @ ARM.mass_matrix(q1) @ qd1 + V

    dEdq = torch.func.vmap(torch.func.grad(energy, argnums=0))(q, qd)
    dEdqd = torch.func.vmap(torch.func.grad(energy, argnums=1))(q, qd)
    dEdt = (dEdq * qd).sum(-1) + (dEdqd * qdd).sum(-1)
    torch.testing.assert_close(dEdt, (qd * tau).sum(-1), rtol=0, atol=1e-10)


def test_static_equilibrium_gravity_only():
    """At rest with τ = G(q) the arm does not accelerate; horizontal arm carries the full lever arms."""
    q = torch.zeros(2, dtype=D)
    G = ARM.gravity(q)
    torch.testing.assert_close(
        G,
        torch.tensor([(ARM.m1 + ARM.m2) * ARM.l1 * ARM.g + ARM.m2 * ARM.l2 * ARM.g, ARM.m2 * ARM.l2 * ARM.g], dtype=D),
    )
    torch.testing.assert_close(ARM.forward_dynamics(q, torch.zeros(2, dtype=D), G), torch.zeros(2, dtype=D))


def test_from_config_accepts_dictconfig_and_dict():
    cfg = OmegaConf.create({"m1": 0.42, "m2": 3, "l1": 0.2, "l2": 0.26, "g": 9.81})
    assert TwoLinkArm.from_config(cfg) == ARM
    assert TwoLinkArm.from_config(dict(cfg)) == ARM
    assert TwoLinkArm.from_config(OmegaConf.load(Path(__file__).parents[1] / "configs/robot/two_link.yaml")) == ARM
