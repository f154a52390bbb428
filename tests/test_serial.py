"""SerialArm (eq. 4/5 for N revolute joints) against independent derivations written here.

The reference kinematics below share nothing with selpres.arms.serial but the arm's parameters: joint rotations
come from unit quaternions, frames are composed as 4x4 homogeneous transforms, and every velocity,
Jacobian and energy derivative is taken by autograd. Published numbers (Corke's Robotics Toolbox tests for
the PUMA 560) and the paper's closed form (eq. 6, selpres.arms.two_link) are the other two references.
"""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch
from omegaconf import OmegaConf

import selpres.arms.kinematics as serial
import selpres.arms.serial as serial_arm
from selpres.arms.kinematics import Link
from selpres.arms.serial import SerialArm
from selpres.arms.two_link import TwoLinkArm
from selpres.errors import ConfigError

from conftest import load_group

D = torch.float64
PAPER = dict(m1=0.42, m2=3.0, l1=0.2, l2=0.26, g=9.81)


def load(name: str) -> SerialArm:
    return SerialArm.from_config(OmegaConf.to_container(load_group("robot", name)))


# ----------------------------------------------------------------------------------- independent reference
def _quat_rot(axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Rotation by ``angle`` about unit ``axis`` from the unit quaternion (cos θ/2, sin θ/2 axis)."""
    w = torch.cos(angle / 2)
    x, y, z = axis * torch.sin(angle / 2)
    return torch.stack(
        [
            torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)]),
            torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)]),
            torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]),
        ]
    )


def _homogeneous(rot: torch.Tensor, xyz: torch.Tensor) -> torch.Tensor:
    top = torch.cat((rot, xyz[:, None]), 1)
    return torch.cat((top, torch.tensor([[0.0, 0.0, 0.0, 1.0]], dtype=D)), 0)


def reference_frames(arm: SerialArm, q: torch.Tensor) -> list[torch.Tensor]:
    """Base-frame 4x4 pose of every link for one state q [N]: T_i = T_{i-1} · origin_i · Rot(axis_i, q_i)."""
    pose, out = torch.eye(4, dtype=D), []
    for i, lk in enumerate(arm.links):
        origin = _homogeneous(torch.tensor(lk.rotation, dtype=D), torch.tensor(lk.xyz, dtype=D))
        turn = _homogeneous(_quat_rot(torch.tensor(lk.axis, dtype=D), q[i]), torch.zeros(3, dtype=D))
        pose = pose @ origin @ turn
        out.append(pose)
    return out


def _vee(skew: torch.Tensor) -> torch.Tensor:
    return torch.stack((skew[2, 1] - skew[1, 2], skew[0, 2] - skew[2, 0], skew[1, 0] - skew[0, 1])) / 2


def energies(arm: SerialArm, q: torch.Tensor, qd: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(kinetic, potential) for one state: ½ m |v_c|² + ½ ω_bᵀ I ω_b per link, and −m gᵀ p_c."""
    frames = lambda x: reference_frames(arm, x)
    poses, rates = torch.func.jvp(frames, (q,), (qd,))
    gravity = torch.tensor(arm.gravity_vector, dtype=D)
    kinetic = potential = torch.zeros((), dtype=D)
    for lk, pose, rate in zip(arm.links, poses, rates):
        com = torch.tensor([*lk.com, 1.0], dtype=D)
        p_c, v_c = (pose @ com)[:3], (rate @ com)[:3]
        w_body = _vee(pose[:3, :3].T @ rate[:3, :3])  # Rᵀ Ṙ = [ω_b]×
        inertia = torch.tensor(lk.inertia, dtype=D)
        kinetic = kinetic + 0.5 * lk.mass * v_c.dot(v_c) + 0.5 * w_body.dot(inertia @ w_body)
        potential = potential - lk.mass * gravity.dot(p_c)
    return kinetic, potential


def reference_torque(arm: SerialArm, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor) -> torch.Tensor:
    """Euler–Lagrange over a batch: τ = d/dt ∂L/∂q̇ − ∂L/∂q = (∂²L/∂q̇²) q̈ + (∂²L/∂q̇∂q) q̇ − ∂L/∂q."""
    lagrangian = lambda x, v: (lambda t, u: t - u)(*energies(arm, x, v))
    dl_dqd = torch.func.grad(lagrangian, argnums=1)
    mass = torch.func.vmap(torch.func.jacrev(dl_dqd, argnums=1))(q, qd)
    mixed = torch.func.vmap(torch.func.jacrev(dl_dqd, argnums=0))(q, qd)
    dl_dq = torch.func.vmap(torch.func.grad(lagrangian, argnums=0))(q, qd)
    return (mass @ qdd[..., None] + mixed @ qd[..., None]).squeeze(-1) - dl_dq


def reference_mass_matrix(arm: SerialArm, q: torch.Tensor) -> torch.Tensor:
    """H = ∂²T/∂q̇² (T is quadratic in q̇, so any q̇ gives the same Hessian)."""
    kinetic = lambda x, v: energies(arm, x, v)[0]
    return torch.func.vmap(torch.func.hessian(kinetic, argnums=1))(q, torch.zeros_like(q))


def reference_wrench_torque(arm: SerialArm, q: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
    """Virtual work: Kᵀk = J_vᵀ f + J_ωᵀ n, with J_v the autograd Jacobian of the end point and J_ω's column i
    = vee((∂R_N/∂q_i) R_Nᵀ) from the last link's orientation."""
    end = torch.tensor([*arm.end_point, 1.0], dtype=D)

    def one(x: torch.Tensor, wrench: torch.Tensor) -> torch.Tensor:
        j_v = torch.func.jacrev(lambda y: (reference_frames(arm, y)[-1] @ end)[:3])(x)  # [3, N]
        rot = reference_frames(arm, x)[-1][:3, :3]
        d_rot = torch.func.jacrev(lambda y: reference_frames(arm, y)[-1][:3, :3])(x)  # [3, 3, N]
        j_w = torch.stack([_vee(d_rot[..., i] @ rot.T) for i in range(x.shape[0])], 1)
        return j_v.T @ wrench[:3] + j_w.T @ wrench[3:]

    return torch.func.vmap(one)(q, k)


# ------------------------------------------------------------------------------------------------- helpers
def random_arm(n: int, seed: int, *, point_masses: bool = False) -> SerialArm:
    """A random chain: any joint origins (xyz, rpy), axes, masses, coms, physically valid inertias."""
    g = torch.Generator().manual_seed(seed)
    u = lambda *s: torch.rand(*s, dtype=D, generator=g) * 2 - 1
    links = []
    for i in range(n):
        axis = u(3)
        inertia = torch.zeros(3, 3, dtype=D)
        if not point_masses:  # a cloud of 4 point masses about the com: a realisable tensor
            for r in 0.2 * u(4, 3):
                inertia += 0.5 * (r.dot(r) * torch.eye(3, dtype=D) - torch.outer(r, r))
        links.append(
            Link(
                f"l{i}",
                float(0.2 + 2.8 * torch.rand((), dtype=D, generator=g)),
                tuple((0.3 * u(3)).tolist()),
                tuple(map(tuple, inertia.tolist())),
                joint=f"j{i}",
                xyz=tuple((0.4 * u(3)).tolist()),
                rotation=serial.rpy_matrix((math.pi * u(3)).tolist()),
                axis=tuple((axis / axis.norm()).tolist()),
            )
        )
    gravity = u(3)
    return SerialArm(
        links, tuple((9.81 * gravity / gravity.norm()).tolist()), tuple((0.2 * u(3)).tolist()), name=f"rand{n}"
    )


def states(n_states: int, dof: int, seed: int) -> tuple[torch.Tensor, ...]:
    g = torch.Generator().manual_seed(seed)
    q = (torch.rand(n_states, dof, dtype=D, generator=g) * 2 - 1) * math.pi
    qd = (torch.rand(n_states, dof, dtype=D, generator=g) * 2 - 1) * 3
    qdd = (torch.rand(n_states, dof, dtype=D, generator=g) * 2 - 1) * 5
    k = (torch.rand(n_states, 6, dtype=D, generator=g) * 2 - 1) * 10
    return q, qd, qdd, k


def assert_rel(actual: torch.Tensor, expected: torch.Tensor, rel: float) -> None:
    """max |actual − expected| <= rel · max(1, max |expected|), reported with the ratio reached."""
    err = float((actual - expected).abs().max())
    scale = max(1.0, float(expected.abs().max()))
    assert err <= rel * scale, f"error {err:.3e} exceeds {rel:g} x {scale:.3g}"


ARMS = {
    "two_link": lambda: SerialArm.two_link(**PAPER),
    "planar3": lambda: load("planar3"),
    "puma560": lambda: load("puma560"),
    "random4_points": lambda: random_arm(4, seed=11, point_masses=True),
    "random5": lambda: random_arm(5, seed=12),
    "random7": lambda: random_arm(7, seed=13),
}


# --------------------------------------------------------------------------------------------- the paper
def test_two_link_equals_the_papers_closed_form():
    """eq. (6) (θ1 from the horizontal, gravity along −y) and the general code agree to 5e-14 (seen: 8.9e-15 Nm)."""
    closed, general = TwoLinkArm(**PAPER), SerialArm.two_link(**PAPER)
    q, qd, qdd, _ = states(4096, 2, seed=1)
    tau = closed.inverse_dynamics(q, qd, qdd)
    assert (general.inverse_dynamics(q, qd, qdd) - tau).abs().max() <= 5e-14
    assert (general.mass_matrix(q) - closed.mass_matrix(q)).abs().max() <= 5e-14
    assert (general.coriolis(q, qd) - closed.coriolis(q, qd)).abs().max() <= 5e-14
    assert (general.gravity(q) - closed.gravity(q)).abs().max() <= 5e-14
    assert (general.bias(q, qd) - closed.bias(q, qd)).abs().max() <= 5e-14
    assert (general.det_mass_matrix(q) - closed.det_mass_matrix(q)).abs().max() <= 1e-12
    # the simulator (eq. 5): both solve the same H q̈ = τ − b
    assert_rel(general.forward_dynamics(q, qd, tau), closed.forward_dynamics(q, qd, tau), 1e-10)


def test_two_link_comparison_detects_a_different_arm():
    """Guards the comparison above: a 1e-6 change of m2 must show."""
    q, qd, qdd, _ = states(64, 2, seed=2)
    other = SerialArm.two_link(**{**PAPER, "m2": PAPER["m2"] * (1 + 1e-6)})
    paper = TwoLinkArm(**PAPER).inverse_dynamics(q, qd, qdd)
    assert (other.inverse_dynamics(q, qd, qdd) - paper).abs().max() > 1e-9


def test_planar3_without_its_hand_is_the_papers_arm():
    """planar3's links 1-2 are configs/robot/two_link.yaml: with m3 = 0 its first two torques are eq. (6)."""
    spec = OmegaConf.to_container(load_group("robot", "planar3"))
    spec["links"][2]["mass"] = 0.0
    arm = SerialArm.from_config(spec)
    paper = TwoLinkArm.from_config(load_group("robot", "two_link"))
    q, qd, qdd, _ = states(512, 3, seed=3)
    tau = arm.inverse_dynamics(q, qd, qdd)
    assert (tau[:, :2] - paper.inverse_dynamics(q[:, :2], qd[:, :2], qdd[:, :2])).abs().max() <= 1e-12
    assert tau[:, 2].abs().max() == 0.0


# ---------------------------------------------------------------------------------- Euler–Lagrange (4a)
@pytest.mark.parametrize("name", ARMS)
def test_inverse_dynamics_matches_euler_lagrange(name):
    arm = ARMS[name]()
    q, qd, qdd, _ = states(24, arm.dof, seed=4)
    assert_rel(arm.inverse_dynamics(q, qd, qdd), reference_torque(arm, q, qd, qdd), 1e-14)  # seen: <= 9e-16


@pytest.mark.parametrize("name", ["planar3", "puma560", "random5"])
def test_mass_matrix_matches_the_kinetic_energy_hessian(name):
    arm = ARMS[name]()
    q = states(24, arm.dof, seed=5)[0]
    ref = reference_mass_matrix(arm, q)
    assert_rel(arm.mass_matrix(q), ref, 1e-9)
    assert_rel(arm.det_mass_matrix(q), torch.linalg.det(ref), 1e-9)


@pytest.mark.parametrize("name", ["puma560", "random5"])
def test_terms_of_eq4_add_up(name):
    """τ = H q̈ + C q̇ + G + Kᵀk, each term from its own method, b = τ at q̈ = 0 (eq. 5)."""
    arm = ARMS[name]()
    q, qd, qdd, k = states(64, arm.dof, seed=6)
    parts = (
        (arm.mass_matrix(q) @ qdd[..., None]).squeeze(-1)
        + arm.coriolis(q, qd)
        + arm.gravity(q)
        + arm.wrench_torque(q, k)
    )
    assert_rel(arm.inverse_dynamics(q, qd, qdd, k), parts, 1e-12)
    assert_rel(arm.bias(q, qd, k), arm.inverse_dynamics(q, qd, torch.zeros_like(qdd), k), 1e-14)


def test_euler_lagrange_reference_detects_a_wrong_model():
    """Guards against a vacuous reference: one inertia entry changed by 1e-6 must disagree."""
    arm = random_arm(5, seed=12)
    q, qd, qdd, _ = states(8, 5, seed=7)
    ref = reference_torque(arm, q, qd, qdd)
    lk = arm.links[3]
    bumped = [list(row) for row in lk.inertia]
    bumped[2][2] += 1e-6
    links = list(arm.links)
    links[3] = dataclasses.replace(lk, inertia=tuple(map(tuple, bumped)))
    wrong = SerialArm(links, arm.gravity_vector, arm.end_point)
    assert (wrong.inverse_dynamics(q, qd, qdd) - ref).abs().max() > 1e-9


# ------------------------------------------------------------------------------------ energy identity (4b)
@pytest.mark.parametrize("name", ["planar3", "puma560", "random4_points", "random7"])
def test_power_balance(name):
    """d/dt (kinetic + potential) = q̇ᵀτ with k = 0, along (q̇, q̈) for arbitrary q̈."""
    arm = ARMS[name]()
    q, qd, qdd, _ = states(32, arm.dof, seed=8)
    energy = lambda x, v: sum(energies(arm, x, v))
    rate = torch.func.vmap(lambda x, v, a: torch.func.jvp(energy, (x, v), (v, a))[1])(q, qd, qdd)
    power = (qd * arm.inverse_dynamics(q, qd, qdd)).sum(-1)
    assert_rel(power, rate, 1e-9)


# ---------------------------------------------------------------------------------- virtual work (4c)
@pytest.mark.parametrize("name", ["two_link", "planar3", "puma560", "random5"])
def test_wrench_term_is_the_jacobian_transpose(name):
    arm = ARMS[name]()
    q, qd, qdd, k = states(32, arm.dof, seed=9)
    ref = reference_wrench_torque(arm, q, k)
    assert_rel(arm.wrench_torque(q, k), ref, 1e-9)
    assert_rel(arm.inverse_dynamics(q, qd, qdd, k) - arm.inverse_dynamics(q, qd, qdd), ref, 1e-9)
    assert_rel((arm.jacobian(q).mT @ k[..., None]).squeeze(-1), ref, 1e-9)


def test_wrench_sign_follows_eq4():
    """+Kᵀk with k what the arm exerts: pressing down with 10 N at the end of the paper's arm, stretched along
    x, takes the torques of a downward turn. By hand: joint i at x_i gives −10·(0.46 − x_i) Nm."""
    arm = SerialArm.two_link(**PAPER)
    k = torch.tensor([0.0, -10.0, 0.0, 0.0, 0.0, 0.0], dtype=D)
    assert torch.allclose(
        arm.wrench_torque(torch.zeros(2, dtype=D), k), torch.tensor([-4.6, -2.6], dtype=D), rtol=0, atol=1e-14
    )
    twist = torch.tensor([0.0, 0.0, 0.0, 0.0, 0.0, 3.0], dtype=D)  # a pure moment about z: 3 Nm on each joint
    assert torch.allclose(
        arm.wrench_torque(torch.tensor([0.3, -1.2], dtype=D), twist),
        torch.tensor([3.0, 3.0], dtype=D),
        rtol=0,
        atol=1e-14,
    )


# -------------------------------------------------------------------------------- simulator (eq. 5, 4d)
@pytest.mark.parametrize("name", ["two_link", "planar3", "puma560", "random7"])
def test_forward_dynamics_inverts_inverse_dynamics(name):
    arm = ARMS[name]()
    q, qd, qdd, k = states(2000, arm.dof, seed=10)
    tau = arm.inverse_dynamics(q, qd, qdd, k)
    assert_rel(arm.forward_dynamics(q, qd, tau, k), qdd, 1e-9)


@pytest.mark.parametrize("name", ["puma560", "random7"])
def test_mass_matrix_is_symmetric_positive_definite(name):
    arm = ARMS[name]()
    h = arm.mass_matrix(states(500, arm.dof, seed=11)[0])
    assert torch.equal(h, h.mT)
    assert float(torch.linalg.eigvalsh(h).min()) > 0


def test_singular_mass_matrix_is_a_clear_error():
    massless = SerialArm.two_link(0.0, 0.0, 0.2, 0.26)
    with pytest.raises(ValueError, match=r"not positive definite at q=\[0.5, 0.25\] \(joint 1"):
        massless.forward_dynamics(torch.tensor([0.5, 0.25], dtype=D), torch.zeros(2, dtype=D), torch.zeros(2, dtype=D))


# ---------------------------------------------------------------------------------- the PUMA 560 data
def test_puma560_matches_the_toolbox_published_values():
    """Corke's Robotics Toolbox (robotics-toolbox-python, tests of Puma560 at qn = [0, π/4, π, 0, π/4, 0]):
    gravload = [0, 31.6399, 6.0351, 0, 0.0283, 0] Nm; inertia(qn) printed below includes the motors'
    armature Jm·G², which selpres leaves out (the toolbox's Jm, G per joint)."""
    arm = load("puma560")
    qn = torch.tensor([0.0, math.pi / 4, math.pi, 0.0, math.pi / 4, 0.0], dtype=D)
    assert torch.allclose(arm.gravity(qn), torch.tensor([0, 31.6399, 6.0351, 0, 0.0283, 0], dtype=D), atol=5e-5, rtol=0)
    toolbox_inertia = torch.tensor(
        [
            [3.6594, -0.4044, 0.1006, -0.0025, 0.0000, -0.0000],
            [-0.4044, 4.4137, 0.3509, 0.0000, 0.0024, 0.0000],
            [0.1006, 0.3509, 0.9378, 0.0000, 0.0015, 0.0000],
            [-0.0025, 0.0000, 0.0000, 0.1925, 0.0000, 0.0000],
            [0.0000, 0.0024, 0.0015, 0.0000, 0.1713, 0.0000],
            [-0.0000, 0.0000, 0.0000, 0.0000, 0.0000, 0.1941],
        ],
        dtype=D,
    )
    jm = torch.tensor([200e-6, 200e-6, 200e-6, 33e-6, 33e-6, 33e-6], dtype=D)
    gear = torch.tensor([-62.6111, 107.815, -53.7063, 76.0364, 71.923, 76.686], dtype=D)
    assert torch.allclose(arm.mass_matrix(qn) + torch.diag(jm * gear**2), toolbox_inertia, atol=5e-5, rtol=0)


def test_dh_rows_reproduce_the_dh_product():
    """from_dh's URDF-style frames against the textbook product Π Rz(θ_i) Tz(d_i) Tx(a_i) Rx(α_i)."""
    rows = [
        dict(a=0.3, alpha=0.7, d=0.1, offset=0.2),
        dict(a=-0.2, alpha=-1.1, d=0.25, offset=-0.4),
        dict(a=0.15, alpha=math.pi / 2, d=0.0, offset=0.0),
    ]
    arm = SerialArm.from_dh(
        [{**r, "mass": 1.0, "com": [0.0, 0.0, 0.0]} for r in rows], (0.0, 0.0, -9.81), end_point=(0.05, -0.02, 0.1)
    )
    q = states(16, 3, seed=12)[0]
    rot_w, _, end = arm.forward_kinematics(q)

    def dh(theta, r):
        c, s, ca, sa = torch.cos(theta), torch.sin(theta), math.cos(r["alpha"]), math.sin(r["alpha"])
        z, o = torch.zeros_like(c), torch.ones_like(c)
        rows_ = [
            [c, -s * ca, s * sa, r["a"] * c],
            [s, c * ca, -c * sa, r["a"] * s],
            [z, z + sa, z + ca, z + r["d"]],
            [z, z, z, o],
        ]
        return torch.stack([torch.stack(row) for row in rows_]).permute(2, 0, 1)

    pose = torch.eye(4, dtype=D).expand(16, 4, 4)
    for i, r in enumerate(rows):
        pose = pose @ dh(q[:, i] + r["offset"], r)
    assert torch.allclose(end, (pose @ torch.tensor([0.05, -0.02, 0.1, 1.0], dtype=D))[:, :3], atol=1e-14)
    rx = torch.tensor(serial.rot_x(rows[-1]["alpha"]), dtype=D)
    assert torch.allclose(rot_w[:, -1] @ rx, pose[:, :3, :3], atol=1e-14)


# ----------------------------------------------------------------------------------------- batching
def test_any_leading_shape_and_chunks(monkeypatch):
    """[..., N] in, same numbers whether the states come in one chunk or many, in any leading shape."""
    arm = load("puma560")
    q, qd, qdd, k = states(300, 6, seed=13)
    whole = arm.inverse_dynamics(q, qd, qdd, k)
    monkeypatch.setattr(serial_arm, "CHUNK", 7)
    assert torch.equal(arm.inverse_dynamics(q, qd, qdd, k), whole)
    assert torch.equal(
        arm.inverse_dynamics(
            q.reshape(3, 10, 10, 6), qd.reshape(3, 10, 10, 6), qdd.reshape(3, 10, 10, 6), k.reshape(3, 10, 10, 6)
        ),
        whole.reshape(3, 10, 10, 6),
    )
    tau_grid = torch.rand(4, 5, 6, dtype=D)  # states [S, 1, 1, N] against torques [T1, T2, N] (selpres.data.paper)
    acc = arm.forward_dynamics(q[:3, None, None], qd[:3, None, None], tau_grid)
    assert acc.shape == (3, 4, 5, 6)
    assert_rel(acc[2, 3, 4], arm.forward_dynamics(q[2], qd[2], tau_grid[3, 4]), 1e-15)
    assert arm.det_mass_matrix(q[0]).shape == ()


def test_wrong_shapes_name_the_argument():
    arm = load("planar3")
    with pytest.raises(ValueError, match=r"qd has shape \(4, 2\): expected a tensor \[\.\.\., 3\]"):
        arm.inverse_dynamics(torch.zeros(4, 3, dtype=D), torch.zeros(4, 2, dtype=D), torch.zeros(4, 3, dtype=D))
    with pytest.raises(ValueError, match=r"k has shape \(3,\): expected a tensor \[\.\.\., 6\]"):
        arm.wrench_torque(torch.zeros(3, dtype=D), torch.zeros(3, dtype=D))


# ---------------------------------------------------------------------------------------- configuration
def test_config_round_trip():
    for name in ("planar3", "puma560"):
        arm = load(name)
        again = SerialArm.from_config(arm.to_config())
        q, qd, qdd, k = states(50, arm.dof, seed=14)
        assert_rel(again.inverse_dynamics(q, qd, qdd, k), arm.inverse_dynamics(q, qd, qdd, k), 1e-14)
        assert again.to_config() == arm.to_config()
    lim = load("puma560").joint_limits()
    assert lim.shape == (6, 2) and math.isclose(float(lim[1, 1]), math.radians(225), rel_tol=1e-15)
    assert torch.isinf(load("planar3").joint_limits()).all()


def _planar3_with(path: tuple, value):
    spec = OmegaConf.to_container(load_group("robot", "planar3"))
    node = spec
    for key in path[:-1]:
        node = node[key]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return spec


@pytest.mark.parametrize(
    "path, value, message",
    [
        (("links", 1, "mass"), -1.0, "robot.links[1].mass=-1.0 is not allowed: expected a finite mass >= 0 kg"),
        (("links", 0, "joint", "axis"), [0, 0, 0], "robot.links[0].joint.axis=(0.0, 0.0, 0.0) is not allowed"),
        (("links", 0, "joint", "axis"), KeyError, "robot.links[0].joint.axis=None is not allowed: expected a value"),
        (("links", 2, "com"), [0.1, 0.0], "robot.links[2].com=[0.1, 0.0] is not allowed: expected a list of 3"),
        (
            ("links", 2, "inertia"),
            {"ixx": 1.0, "iyy": 1.0, "izz": 1.0, "ixy": 5.0},
            "robot.links[2].inertia=((1.0, 5.0, 0.0), (5.0, 1.0, 0.0), (0.0, 0.0, 1.0)) is not allowed: expected a "
            "positive semi-definite",
        ),
        (("links", 1, "masss"), 1.0, "robot.links[1].masss=1.0 is not allowed: expected one of the keys"),
        (("links", 1, "joint", "limits"), [1.0, -1.0], "robot.links[1].joint.limits=(1.0, -1.0) is not allowed"),
        (("gravity",), "down", "robot.gravity='down' is not allowed: expected a list of 3 finite numbers"),
        (("kind",), "two_link", "robot.kind='two_link' is not allowed: expected 'serial'"),
        (("links",), [], "robot.links=[] is not allowed: expected a non-empty list"),
    ],
)
def test_bad_config_names_key_value_and_what_is_allowed(path, value, message):
    with pytest.raises(ConfigError) as err:
        SerialArm.from_config(_planar3_with(path, value))
    assert message in str(err.value)


def test_duplicate_names_are_refused():
    lk = Link("a", 1.0, (0.1, 0.0, 0.0))
    with pytest.raises(ConfigError, match="link names='a' is not allowed: expected unique link names"):
        SerialArm([lk, lk], (0.0, -9.81, 0.0))
