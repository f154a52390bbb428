"""Kinematics of a serial chain: frames, links and rotations, as plain floats and as batched rows.

Plain-float 3x3 algebra (``rot_x``…, ``rpy_matrix``) builds each link's fixed geometry once; ``Link`` is one
URDF <joint> + <link> pair and ``check_link`` its physical sanity. The batched part works on *rows*: a vector
is a tuple of three entries and a matrix a tuple of three rows, each entry a [B] tensor or a float constant,
so eager torch streams every product over contiguous rows, products with an exact-zero constant (most of a
planar or DH arm's geometry) are skipped and sums of products are fused (``_lin``). ``link_rotations`` and
``world`` are the forward kinematics the dynamics (``selpres.arms.dynamics``) and ``SerialArm`` share.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import torch

from selpres.errors import ConfigError

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]
IDENTITY: Mat3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
ZERO3: Vec3 = (0.0, 0.0, 0.0)
ZERO33: Mat3 = (ZERO3, ZERO3, ZERO3)
INERTIA_KEYS = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")


# ----------------------------------------------------------------------------------------------- rotations
def _mat_mul(a: Mat3, b: Mat3) -> Mat3:
    return tuple(tuple(sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)) for i in range(3))


def _mat_vec(a: Mat3, v: Sequence[float]) -> Vec3:
    return tuple(sum(a[i][k] * v[k] for k in range(3)) for i in range(3))


def _transpose(a: Mat3) -> Mat3:
    return tuple(tuple(a[j][i] for j in range(3)) for i in range(3))


def _cos_sin(t: float) -> tuple[float, float]:
    """cos and sin with the rounding residue of multiples of π/2 (cos(π/2) = 6e-17) set to exact 0, so the
    structural zeros of DH twists and URDF rpy stay zeros (and their products are skipped)."""
    c, s = math.cos(t), math.sin(t)
    return (0.0 if abs(c) < 1e-15 else c), (0.0 if abs(s) < 1e-15 else s)


def rot_x(t: float) -> Mat3:
    c, s = _cos_sin(t)
    return ((1.0, 0.0, 0.0), (0.0, c, -s), (0.0, s, c))


def rot_y(t: float) -> Mat3:
    c, s = _cos_sin(t)
    return ((c, 0.0, s), (0.0, 1.0, 0.0), (-s, 0.0, c))


def rot_z(t: float) -> Mat3:
    c, s = _cos_sin(t)
    return ((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0))


def rpy_matrix(rpy: Sequence[float]) -> Mat3:
    """URDF's fixed-axis roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    return _mat_mul(rot_z(y), _mat_mul(rot_y(p), rot_x(r)))


def matrix_rpy(m: Mat3) -> Vec3:
    """Inverse of ``rpy_matrix`` (pitch in [−π/2, π/2]; at pitch ±π/2 roll is set to 0)."""
    cp = math.hypot(m[0][0], m[1][0])
    pitch = math.atan2(-m[2][0], cp)
    if cp < 1e-9:  # gimbal lock: only yaw ∓ roll is defined
        return (0.0, pitch + 0.0, math.atan2(-m[0][1], m[1][1]) + 0.0)
    angles = (math.atan2(m[2][1], m[2][2]), pitch, math.atan2(m[1][0], m[0][0]))
    return tuple(a + 0.0 for a in angles)  # + 0.0: no -0.0 in exported files


# -------------------------------------------------------------------------------------------------- links
@dataclass(frozen=True)
class Link:
    """Link i with the revolute joint i that moves it (one URDF <joint> + <link> pair).

    ``xyz``/``rotation``: joint i's frame in link i−1's frame (the base frame for the first link);
    ``axis``: unit rotation axis in that frame; ``com``, ``inertia`` (about the com): in link i's frame.
    """

    name: str
    mass: float
    com: Vec3
    inertia: Mat3 = ZERO33
    joint: str = ""
    xyz: Vec3 = ZERO3
    rotation: Mat3 = IDENTITY
    axis: Vec3 = (0.0, 0.0, 1.0)
    limits: tuple[float, float] | None = None
    velocity: float | None = None  # |q̇| limit (rad/s) and |τ| limit (Nm) of the joint, where a file gives them
    effort: float | None = None

    @property
    def rpy(self) -> Vec3:
        return matrix_rpy(self.rotation)


def joint_parts(link: Link) -> tuple[Mat3, Mat3, Mat3]:
    """R0 a aᵀ, R0 (I − a aᵀ), R0 [a]×: the joint's rotation R0 Rot(a, q) = sum of these weighted 1, cos q,
    sin q (Rodrigues)."""
    a = link.axis
    outer = tuple(tuple(a[i] * a[j] for j in range(3)) for i in range(3))
    rest = tuple(tuple(IDENTITY[i][j] - outer[i][j] for j in range(3)) for i in range(3))
    skew = ((0.0, -a[2], a[1]), (a[2], 0.0, -a[0]), (-a[1], a[0], 0.0))
    return tuple(_mat_mul(link.rotation, m) for m in (outer, rest, skew))  # type: ignore[return-value]


def about_origin(link: Link) -> Mat3:
    """The link's inertia about its own frame's origin (parallel axes): I + m(|c|² 1 − c cᵀ)."""
    c, m = link.com, link.mass
    sq = sum(x * x for x in c)
    return tuple(
        tuple(link.inertia[r][k] + m * ((sq if r == k else 0.0) - c[r] * c[k]) for k in range(3)) for r in range(3)
    )  # type: ignore[return-value]


def _finite(values: Sequence[float]) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values)


def _is_matrix(m: Any) -> bool:
    return isinstance(m, Sequence) and len(m) == 3 and all(isinstance(r, Sequence) and len(r) == 3 for r in m)


def check_link(link: Link, where: str) -> Link:
    """Physical sanity of one link; raises ConfigError naming ``where`` + the field. Returns the link as
    plain floats with its axis normalised (URDF semantics: only the direction counts)."""
    if not (_finite([link.mass]) and link.mass >= 0):
        raise ConfigError(f"{where}.mass", link.mass, "a finite mass >= 0 kg")
    for field, value, unit in (
        ("com", link.com, " (m)"),
        ("joint.xyz", link.xyz, " (m)"),
        ("joint.axis", link.axis, ""),
    ):
        if not (isinstance(value, Sequence) and len(value) == 3 and _finite(value)):
            raise ConfigError(f"{where}.{field}", value, f"three finite floats{unit}")
    for field, value in (("inertia", link.inertia), ("joint.rotation", link.rotation)):
        if not (_is_matrix(value) and _finite([v for row in value for v in row])):
            raise ConfigError(f"{where}.{field}", value, "a 3x3 of finite floats")
    flat = [v for row in link.inertia for v in row]
    scale = max(1.0, max(abs(v) for v in flat))
    if any(abs(link.inertia[i][j] - link.inertia[j][i]) > 1e-12 * scale for i in range(3) for j in range(i)):
        raise ConfigError(f"{where}.inertia", link.inertia, "a symmetric 3x3 tensor")
    eig = torch.linalg.eigvalsh(torch.tensor(link.inertia, dtype=torch.float64))
    if float(eig.min()) < -1e-12 * scale:
        eigs = [round(float(e), 9) for e in eig]
        raise ConfigError(f"{where}.inertia", link.inertia, f"a positive semi-definite tensor (eigenvalues {eigs})")
    rot = torch.tensor(link.rotation, dtype=torch.float64)
    if not (torch.allclose(rot @ rot.T, torch.eye(3, dtype=rot.dtype), atol=1e-12) and torch.det(rot) > 0):
        raise ConfigError(f"{where}.joint.rotation", link.rotation, "a proper rotation matrix")
    norm = math.sqrt(sum(a * a for a in link.axis))
    if not norm > 0:
        raise ConfigError(f"{where}.joint.axis", link.axis, "a non-zero finite 3-vector")
    if link.limits is not None and not (
        isinstance(link.limits, Sequence)
        and len(link.limits) == 2
        and _finite(link.limits)
        and link.limits[0] < link.limits[1]
    ):
        raise ConfigError(f"{where}.joint.limits", link.limits, "[lower, upper] in rad with lower < upper")
    for field in ("velocity", "effort"):
        value = getattr(link, field)
        if value is not None and not (_finite([value]) and value > 0):
            raise ConfigError(f"{where}.joint.{field}", value, "a positive finite limit (null: not given)")
    floats = lambda v: tuple(float(x) for x in v)
    return replace(
        link,
        mass=float(link.mass),
        com=floats(link.com),
        xyz=floats(link.xyz),
        inertia=tuple(floats(r) for r in link.inertia),
        rotation=tuple(floats(r) for r in link.rotation),
        axis=tuple(float(a) / norm for a in link.axis),
        limits=None if link.limits is None else floats(link.limits),
        velocity=None if link.velocity is None else float(link.velocity),
        effort=None if link.effort is None else float(link.effort),
    )


# ---------------------------------------------------------------------------------------------- batched rows
def _lin(*terms: tuple) -> Any:
    """Σ c·x·y over terms (x, y[, c]); x, y are [B] tensors or float constants. Exact zeros are skipped,
    constant factors folded, tensor products fused (addcmul): the one primitive of the recursions."""
    const, acc = 0.0, None
    for term in terms:
        x, y = term[0], term[1]
        c = term[2] if len(term) > 2 else 1.0
        x_t, y_t = isinstance(x, torch.Tensor), isinstance(y, torch.Tensor)
        if not x_t:
            c *= x
        if not y_t:
            c *= y
        if c == 0.0:
            continue
        if not (x_t or y_t):
            const += c
        elif x_t and y_t:
            if acc is None:
                acc = x * y if c == 1.0 else torch.mul(x, y).mul_(c)
            else:
                acc = torch.addcmul(acc, x, y, value=c)
        else:
            t = x if x_t else y
            if acc is None:
                acc = t if c == 1.0 else t * c
            else:
                acc = acc + t if c == 1.0 else acc.add(t, alpha=c)
    if acc is None:
        return const
    return acc + const if const != 0.0 else acc


def _add(a, b):
    return tuple(_lin((x, 1.0), (y, 1.0)) for x, y in zip(a, b))


def _scale(v, s):
    return tuple(_lin((x, s)) for x in v)


def _cross(a, b):
    return (
        _lin((a[1], b[2]), (a[2], b[1], -1.0)),
        _lin((a[2], b[0]), (a[0], b[2], -1.0)),
        _lin((a[0], b[1]), (a[1], b[0], -1.0)),
    )


def _dot(a, b) -> Any:
    return _lin(*zip(a, b))


def _mv(m, v):
    """m v for a matrix given by rows."""
    return tuple(_dot(row, v) for row in m)


def _mtv(m, v):
    """mᵀ v: a parent-frame vector in the child's frame when m is the child's rotation."""
    return tuple(_lin((m[0][c], v[0]), (m[1][c], v[1]), (m[2][c], v[2])) for c in range(3))


def _mm(a, b):
    return tuple(tuple(_lin(*((a[r][k], b[k][c]) for k in range(3))) for c in range(3)) for r in range(3))


def link_rotations(parts: Sequence[tuple[Mat3, Mat3, Mat3]], trig: Sequence[torch.Tensor]) -> list:
    """Each link's rotation into its parent's frame, R0 Rot(axis, q_i) = P + cos q_i Q + sin q_i S, from
    rows [cos q_1..N, sin q_1..N] and each link's ``joint_parts`` (cos and sin computed once per call: one
    large op instead of one per chunk)."""
    n = len(parts)
    out = []
    for i, (fixed, turn, skew) in enumerate(parts):
        cos, sin = trig[i], trig[n + i]
        out.append(
            tuple(
                tuple(_lin((fixed[r][c], 1.0), (turn[r][c], cos), (skew[r][c], sin)) for c in range(3))
                for r in range(3)
            )
        )
    return out


def world(links: Sequence[Link], rotations: Sequence, end_point: Sequence[float]) -> tuple[list, list, Any]:
    """Base-frame link orientations, joint origins and the end point from the links' own rotations."""
    rots, origins = [], []
    rot, o = IDENTITY, (0.0, 0.0, 0.0)
    for lk, local in zip(links, rotations):
        o = _add(o, _mv(rot, lk.xyz))
        rot = _mm(rot, local)
        rots.append(rot)
        origins.append(o)
    return rots, origins, _add(o, _mv(rot, end_point))
