"""General serial arm of N revolute joints: the simulator of the paper's section 4, batched in torch.

Eq. (4) τ = H(q)q̈ + C(q, q̇)q̇ + G(q) + K(q)ᵀk is evaluated by recursive Newton–Euler in link
coordinates (Luh, Walker & Paul 1980); H(q) by composite rigid bodies (Walker & Orin 1982, the paper's
ref. [7]); the simulator of eq. (5) solves H(q)q̈ = τ − b, b = τ at q̈ = 0, by an LDLᵀ factorisation that
also gives det H. All methods take tensors shaped ``[..., N]`` (``[..., 6]`` for the wrench k), broadcast
their leading shapes and compute in the inputs' dtype/device (float64 expected), in chunks: 10⁶ PUMA 560
states take about a second for τ and for q̈ on this 2-core machine.

The wrench k = (force, moment), first three components force, last three moment (the paper's order),
is expressed in the base frame and acts at the end point of the last link. It enters with eq. (4)'s
sign: +Kᵀk is the torque the joints spend to *exert* k on the surroundings (a load pushing on the arm
with force f is k = −f).

Geometry follows URDF 1:1: link i is moved by revolute joint i, whose frame sits at a fixed origin
(xyz + rpy) in link i−1's frame (the base frame for i = 1) and turns about a unit ``axis`` of that
frame; the link's mass, centre of mass and inertia tensor (about the centre of mass) are given in link
i's frame. Point masses are the zero-inertia case. ``from_dh`` builds the same from standard
Denavit–Hartenberg rows.

Config spec read by ``from_config`` (YAML/dict; ``kind: serial``)::

    kind: serial
    name: planar3                    # optional, default "arm"
    gravity: [0.0, -9.81, 0.0]       # m/s², free-fall acceleration in the base frame
    end_point: [0.1, 0.0, 0.0]       # optional: the wrench's point in the last link's frame (default 0)
    base: base                       # optional frame names for URDF export (defaults "base", "tip")
    tip: tip
    convention: urdf                 # optional: urdf (default) or dh
    links:                           # from the base outwards
      - name: link1
        joint: {name: joint1, xyz: [0, 0, 0], rpy: [0, 0, 0], axis: [0, 0, 1], limits: [-3.1, 3.1]}
        mass: 0.42                   # kg
        com: [0.2, 0.0, 0.0]         # m, link frame
        inertia: {ixx: 0, iyy: 0, izz: 0, ixy: 0, ixz: 0, iyz: 0}   # kg m², about the com; or a 3x3 list;
                                                                     # omitted: a point mass
With ``convention: dh`` a link has ``dh: {a, alpha, d, offset}`` instead of joint xyz/rpy/axis (joint
angle θ = q + offset, transform Rz(θ) Tz(d) Tx(a) Rx(α)); its com, inertia and the end point are then
given in DH frame i (as in Corke's Robotics Toolbox), ``limits`` and joint ``name`` stay under ``joint``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import torch

from selpres.errors import ConfigError

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]
IDENTITY: Mat3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
ZERO3: Vec3 = (0.0, 0.0, 0.0)
ZERO33: Mat3 = (ZERO3, ZERO3, ZERO3)
CHUNK = 1 << 14  # states per pass: [B] rows of 128 kB stay in cache (measured best of 2^11..2^16)
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

    @property
    def rpy(self) -> Vec3:
        return matrix_rpy(self.rotation)


def _joint_parts(link: Link) -> tuple[Mat3, Mat3, Mat3]:
    """R0 a aᵀ, R0 (I − a aᵀ), R0 [a]×: the joint's rotation R0 Rot(a, q) = sum of these weighted 1, cos q,
    sin q (Rodrigues)."""
    a = link.axis
    outer = tuple(tuple(a[i] * a[j] for j in range(3)) for i in range(3))
    rest = tuple(tuple(IDENTITY[i][j] - outer[i][j] for j in range(3)) for i in range(3))
    skew = ((0.0, -a[2], a[1]), (a[2], 0.0, -a[0]), (-a[1], a[0], 0.0))
    return tuple(_mat_mul(link.rotation, m) for m in (outer, rest, skew))  # type: ignore[return-value]


def _about_origin(link: Link) -> Mat3:
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
    )


# ------------------------------------------------------------------------------------------------- the arm
class SerialArm:
    """N revolute joints in a chain; eq. (4)/(5) batched over any leading shape."""

    def __init__(
        self,
        links: Sequence[Link],
        gravity: Sequence[float],
        end_point: Sequence[float] = ZERO3,
        *,
        name: str = "arm",
        base: str = "base",
        tip: str = "tip",
    ):
        if len(links) < 1:
            raise ConfigError("links", list(links), "at least one link")
        checked = (check_link(lk, f"links[{i}]") for i, lk in enumerate(links))
        self.links = tuple(lk if lk.joint else replace(lk, joint=f"joint{i + 1}") for i, lk in enumerate(checked))
        if not (len(gravity) == 3 and _finite(gravity)):
            raise ConfigError("gravity", gravity, "three finite numbers (m/s^2, base frame)")
        if not (len(end_point) == 3 and _finite(end_point)):
            raise ConfigError("end_point", end_point, "three finite numbers (m, last link's frame)")
        self.gravity_vector = tuple(float(g) for g in gravity)
        self.end_point = tuple(float(e) for e in end_point)
        self.name, self.base, self.tip = name, base, tip
        names = [lk.name for lk in self.links] + [base]
        for kind, seq in (("link", names), ("joint", [lk.joint for lk in self.links])):
            dup = sorted({x for x in seq if seq.count(x) > 1})
            if dup:
                raise ConfigError(f"{kind} names", dup[0], f"unique {kind} names (the base counts as a link)")
        self._parts = [_joint_parts(lk) for lk in self.links]
        self._about_origin = [_about_origin(lk) for lk in self.links]

    # -- construction -------------------------------------------------------------------------------------
    @classmethod
    def two_link(cls, m1: float, m2: float, l1: float, l2: float, g: float = 9.81) -> SerialArm:
        """The paper's arm (eq. 6): point masses at the distal link ends, planar in x–y, axes along z,
        θ1 from the horizontal x axis, θ2 relative to link 1, gravity along −y."""
        return cls(
            [
                Link("link1", m1, (l1, 0.0, 0.0), joint="joint1"),
                Link("link2", m2, (l2, 0.0, 0.0), joint="joint2", xyz=(l1, 0.0, 0.0)),
            ],
            gravity=(0.0, -g, 0.0),
            end_point=(l2, 0.0, 0.0),
            name="two_link",
        )

    @classmethod
    def from_dh(
        cls, rows: Sequence[Mapping[str, Any]], gravity: Sequence[float], end_point: Sequence[float] = ZERO3, **kw: Any
    ) -> SerialArm:
        """Standard Denavit–Hartenberg rows {a, alpha, d, offset, mass, com, inertia, name, joint, limits}
        (com, inertia and ``end_point`` in DH frame i, as Corke's toolbox) mapped onto URDF-style links.

        Link i's URDF frame is DH frame i−1 turned by θ_i about its z axis, so DH frame i sits at the
        fixed transform D_i = Tz(d_i) Tx(a_i) Rx(α_i) in it; joint i+1's origin is D_i Rz(offset_{i+1}).
        """
        links, prev_xyz, prev_rot = [], ZERO3, IDENTITY
        for i, row in enumerate(rows):
            a, alpha, d = float(row["a"]), float(row["alpha"]), float(row["d"])
            rx = rot_x(alpha)
            inertia = row.get("inertia", ZERO33)
            links.append(
                Link(
                    name=row.get("name", f"link{i + 1}"),
                    mass=float(row["mass"]),
                    com=tuple(x + y for x, y in zip((a, 0.0, d), _mat_vec(rx, row["com"]))),
                    inertia=_mat_mul(rx, _mat_mul(inertia, _transpose(rx))),
                    joint=row.get("joint", f"joint{i + 1}"),
                    xyz=prev_xyz,
                    rotation=_mat_mul(prev_rot, rot_z(float(row.get("offset", 0.0)))),
                    axis=(0.0, 0.0, 1.0),
                    limits=row.get("limits"),
                )
            )
            prev_xyz, prev_rot = (a, 0.0, d), rx
        end = tuple(x + y for x, y in zip(prev_xyz, _mat_vec(prev_rot, end_point)))
        return cls(links, gravity, end, **kw)

    @classmethod
    def from_config(cls, cfg: Any, prefix: str = "robot") -> SerialArm:
        """Build from the YAML/dict spec in the module docstring; errors name ``prefix.key`` and the value."""
        return _parse_config(_plain(cfg), prefix)

    def to_config(self) -> dict[str, Any]:
        """The URDF-style spec that ``from_config`` reads back (rotations as rpy)."""
        links = []
        for lk in self.links:
            joint = {"name": lk.joint, "xyz": list(lk.xyz), "rpy": list(lk.rpy), "axis": list(lk.axis)}
            if lk.limits is not None:
                joint["limits"] = list(lk.limits)
            links.append(
                {
                    "name": lk.name,
                    "joint": joint,
                    "mass": lk.mass,
                    "com": list(lk.com),
                    "inertia": [list(r) for r in lk.inertia],
                }
            )
        return {
            "kind": "serial",
            "name": self.name,
            "gravity": list(self.gravity_vector),
            "end_point": list(self.end_point),
            "base": self.base,
            "tip": self.tip,
            "links": links,
        }

    def __repr__(self) -> str:
        return f"SerialArm(name={self.name!r}, dof={self.dof}, links={[lk.name for lk in self.links]})"

    # -- properties ---------------------------------------------------------------------------------------
    @property
    def dof(self) -> int:
        """N, the number of joints."""
        return len(self.links)

    def joint_limits(self, dtype: torch.dtype = torch.float64) -> torch.Tensor:
        """``[N, 2]`` (lower, upper) in rad; ±inf for a joint without limits."""
        inf = math.inf
        return torch.tensor([lk.limits if lk.limits is not None else (-inf, inf) for lk in self.links], dtype=dtype)

    # -- batched evaluation -------------------------------------------------------------------------------
    # Inside, a vector is a tuple of three entries and a matrix a tuple of three rows, each entry a [B]
    # tensor or a float constant: eager torch then streams every product over contiguous rows, products
    # with an exact-zero constant (most of a planar or DH arm's geometry) are skipped, and sums of products
    # are fused (addcmul). Recursions run in link coordinates (Luh, Walker & Paul), where each link's
    # rotation from its parent, R0 Rot(axis, q), is sparse and its inertia constant.
    def _batched(self, fn, width: int, q: torch.Tensor, *args: torch.Tensor | None) -> torch.Tensor:
        """Broadcast q and ``args`` (``[..., n]`` each, None allowed) over their leading shapes, run ``fn`` on
        chunks of CHUNK states given as lists of [B] rows (q as its rows cos q_1..N, sin q_1..N), and return
        ``[..., width]`` (``[...]`` if width is 0)."""
        shape = torch.broadcast_shapes(q.shape[:-1], *(a.shape[:-1] for a in args if a is not None))
        flat = [None if a is None else a.expand(*shape, a.shape[-1]).reshape(-1, a.shape[-1]) for a in (q, *args)]
        flat[0] = torch.cat((torch.cos(flat[0]), torch.sin(flat[0])), -1)  # once: torch threads these
        total = math.prod(shape)
        out = torch.empty(total, max(width, 1), dtype=q.dtype, device=q.device)
        for s in range(0, total, CHUNK):  # column by column: every op stays below torch's parallel grain
            rows = [None if x is None else [c.contiguous() for c in x[s : s + CHUNK].unbind(1)] for x in flat]
            try:
                res = fn(*rows)
            except _Singular as e:
                state = q.expand(*shape, q.shape[-1]).reshape(-1, q.shape[-1])[s + e.index]
                raise ValueError(
                    f"H(q) is not positive definite at q={state.tolist()} (joint {e.joint} "
                    "moves no mass or inertia there): the forward dynamics of eq. (5) are "
                    "undefined"
                ) from None
            for j, r in enumerate(res):
                out[s : s + CHUNK, j] = r
        return out.reshape(*shape, width) if width else out.reshape(shape)

    def _check(self, **named: torch.Tensor | None) -> None:
        for name, x in named.items():
            n = 6 if name == "k" else self.dof
            if x is not None and (not isinstance(x, torch.Tensor) or x.ndim < 1 or x.shape[-1] != n):
                shape = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
                raise ValueError(
                    f"{name} has shape {shape}: expected a tensor [..., {n}] for {self.name} ({self.dof} joints)"
                )

    def _rotations(self, trig: Sequence[torch.Tensor]) -> list:
        """Each link's rotation into its parent's frame, R0 Rot(axis, q_i) = P + cos q_i Q + sin q_i S, from
        rows [cos q_1..N, sin q_1..N] (computed once per call: one large op instead of one per chunk)."""
        out = []
        for i, (fixed, turn, skew) in enumerate(self._parts):
            cos, sin = trig[i], trig[self.dof + i]
            out.append(
                tuple(
                    tuple(_lin((fixed[r][c], 1.0), (turn[r][c], cos), (skew[r][c], sin)) for c in range(3))
                    for r in range(3)
                )
            )
        return out

    def _rnea(self, rots: list, qd, qdd, k, with_gravity: bool) -> list:
        """Newton–Euler in link coordinates: τ for rates given as [B] rows (None = 0) and the base-frame
        wrench k (None = 0)."""
        zero = (0.0, 0.0, 0.0)
        w = dw = zero  # angular velocity and acceleration of the parent link, in its frame
        # acceleration of the parent's origin; gravity enters as the base accelerating upwards
        acc = tuple(-g for g in self.gravity_vector) if with_gravity else zero
        loads = []
        for i, (lk, rot) in enumerate(zip(self.links, rots)):
            p = lk.xyz
            acc = _mtv(rot, _add(acc, _add(_cross(dw, p), _cross(w, _cross(w, p)))))
            w_in = _mtv(rot, w)
            dw = _mtv(rot, dw)
            if qdd is not None:
                dw = _add(dw, _scale(lk.axis, qdd[i]))
            if qd is not None:
                wz = _scale(lk.axis, qd[i])
                dw = _add(dw, _cross(w_in, wz))
                w = _add(w_in, wz)
            else:
                w = w_in
            acc_c = _add(acc, _add(_cross(dw, lk.com), _cross(w, _cross(w, lk.com))))
            force = _scale(acc_c, lk.mass)
            moment = _add(_mv(lk.inertia, dw), _cross(w, _mv(lk.inertia, w)))
            loads.append((force, moment))
        if k is not None:  # the wrench into the last link's frame, then about its origin
            f_end, n_end = tuple(k[:3]), tuple(k[3:])
            for rot in rots:
                f_end, n_end = _mtv(rot, f_end), _mtv(rot, n_end)
            f, n = f_end, _add(n_end, _cross(self.end_point, f_end))
        else:
            f = n = zero
        tau: list = [0.0] * self.dof
        for i in range(self.dof - 1, -1, -1):
            lk, (force, moment) = self.links[i], loads[i]
            n = _add(_add(n, moment), _cross(lk.com, force))
            f = _add(f, force)
            tau[i] = _dot(lk.axis, n)
            if i:  # into the parent's frame, about its origin
                f = _mv(rots[i], f)
                n = _add(_mv(rots[i], n), _cross(lk.xyz, f))
        return tau

    def _mass_matrix(self, rots: list) -> list[list]:
        """Composite rigid bodies in link coordinates: links i..N carry mass M, first moment h and inertia J
        about joint i's origin; turning joint i at unit acceleration demands the force a_i × h and moment
        J a_i there, which are carried to each joint j < i to give H_ji."""
        n = self.dof
        h_rows: list[list] = [[0.0] * n for _ in range(n)]
        mass, first, second = 0.0, (0.0, 0.0, 0.0), None
        for i in range(n - 1, -1, -1):
            lk = self.links[i]
            if i < n - 1:  # links i+1..N, from frame i+1 into frame i
                first, second = _carry_composite(rots[i + 1], self.links[i + 1].xyz, mass, first, second)
            own = self._about_origin[i]
            mass = mass + lk.mass
            first = _add(first, _scale(lk.com, lk.mass))
            second = own if second is None else _sym(lambda r, c, s=second, o=own: _lin((s[r][c], 1.0), (o[r][c], 1.0)))
            force, moment = _cross(lk.axis, first), _mv(second, lk.axis)
            h_rows[i][i] = _dot(lk.axis, moment)
            for j in range(i - 1, -1, -1):  # carry the column's wrench to joint j
                child = self.links[j + 1]
                force = _mv(rots[j + 1], force)
                moment = _add(_mv(rots[j + 1], moment), _cross(child.xyz, force))
                h_rows[j][i] = h_rows[i][j] = _dot(self.links[j].axis, moment)
        return h_rows

    def _world(self, trig: Sequence[torch.Tensor]) -> tuple[list, list, Any]:
        """Base-frame link orientations, joint origins and the end point (kinematics only)."""
        rots, origins = [], []
        rot, o = IDENTITY, (0.0, 0.0, 0.0)
        for lk, local in zip(self.links, self._rotations(trig)):
            o = _add(o, _mv(rot, lk.xyz))
            rot = _mm(rot, local)
            rots.append(rot)
            origins.append(o)
        return rots, origins, _add(o, _mv(rot, self.end_point))

    # -- the paper's quantities ---------------------------------------------------------------------------
    def inverse_dynamics(
        self, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor, k: torch.Tensor | None = None
    ) -> torch.Tensor:
        """τ = H q̈ + C q̇ + G + Kᵀk (eq. 4): what the network learns. ``[..., N]``."""
        self._check(q=q, qd=qd, qdd=qdd, k=k)
        return self._batched(
            lambda q_, qd_, qdd_, k_: self._rnea(self._rotations(q_), qd_, qdd_, k_, True), self.dof, q, qd, qdd, k
        )

    def bias(self, q: torch.Tensor, qd: torch.Tensor, k: torch.Tensor | None = None) -> torch.Tensor:
        """b = C q̇ + G + Kᵀk, τ at q̈ = 0 (the paper's "bias torque", eq. 5)."""
        self._check(q=q, qd=qd, k=k)
        return self._batched(
            lambda q_, qd_, k_: self._rnea(self._rotations(q_), qd_, None, k_, True), self.dof, q, qd, k
        )

    def gravity(self, q: torch.Tensor) -> torch.Tensor:
        """G(q): the torques holding the arm still against gravity."""
        self._check(q=q)
        return self._batched(lambda q_: self._rnea(self._rotations(q_), None, None, None, True), self.dof, q)

    def coriolis(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        """C(q, q̇) q̇ as a vector (centrifugal and Coriolis torques), as ``TwoLinkArm.coriolis``."""
        self._check(q=q, qd=qd)
        return self._batched(lambda q_, qd_: self._rnea(self._rotations(q_), qd_, None, None, False), self.dof, q, qd)

    def wrench_torque(self, q: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
        """K(q)ᵀk: the joint torques that exert the wrench k (base frame) at the end point."""
        self._check(q=q, k=k)
        return self._batched(lambda q_, k_: self._rnea(self._rotations(q_), None, None, k_, False), self.dof, q, k)

    def mass_matrix(self, q: torch.Tensor) -> torch.Tensor:
        """H(q) ``[..., N, N]``: symmetric positive definite."""
        self._check(q=q)
        n = self.dof
        return self._batched(
            lambda q_: [x for row in self._mass_matrix(self._rotations(q_)) for x in row], n * n, q
        ).unflatten(-1, (n, n))

    def det_mass_matrix(self, q: torch.Tensor) -> torch.Tensor:
        """det H(q) ``[...]``: the Jacobian of q̈ → τ, for exact sampling in selpres.data.paper."""
        self._check(q=q)
        return self._batched(lambda q_: [math.prod(_ldl(self._mass_matrix(self._rotations(q_)))[1])], 0, q)

    def forward_dynamics(
        self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor, k: torch.Tensor | None = None
    ) -> torch.Tensor:
        """q̈ = H⁻¹(τ − b) (eq. 5): the paper's simulator, an LDLᵀ solve per state."""
        self._check(q=q, qd=qd, tau=tau, k=k)
        n = self.dof

        def fn(q_, qd_, tau_, k_):
            rots = self._rotations(q_)
            bias = self._rnea(rots, qd_, None, k_, True)
            low, _, inv = _ldl(self._mass_matrix(rots))
            y: list = []
            for i in range(n):  # L y = τ − b
                y.append(_lin((tau_[i], 1.0), (bias[i], -1.0), *((low[i][m], y[m], -1.0) for m in range(i))))
            x: list = [0.0] * n
            for i in range(n - 1, -1, -1):  # Lᵀ q̈ = D⁻¹ y
                x[i] = _lin((y[i], inv[i]), *((low[m][i], x[m], -1.0) for m in range(i + 1, n)))
            return x

        return self._batched(fn, n, q, qd, tau, k)

    def forward_kinematics(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(link orientations ``[..., N, 3, 3]``, joint origins ``[..., N, 3]``, end point ``[..., 3]``),
        base frame."""
        self._check(q=q)
        n = self.dof

        def fn(q_):
            rots, origins, end = self._world(q_)
            return [x for r in rots for row in r for x in row] + [x for o in origins for x in o] + list(end)

        out = self._batched(fn, n * 12 + 3, q)
        return (
            out[..., : 9 * n].unflatten(-1, (n, 3, 3)),
            out[..., 9 * n : 12 * n].unflatten(-1, (n, 3)),
            out[..., 12 * n :],
        )

    def jacobian(self, q: torch.Tensor) -> torch.Tensor:
        """K(q) ``[..., 6, N]``: end-point velocity (rows 0–2) and angular velocity (rows 3–5) per q̇_i."""
        self._check(q=q)
        n = self.dof

        def fn(q_):
            rots, origins, end = self._world(q_)
            axes = [_mv(r, lk.axis) for r, lk in zip(rots, self.links)]
            cols = [(*_cross(z, _add(end, _scale(o, -1.0))), *z) for z, o in zip(axes, origins)]
            return [cols[i][r] for r in range(6) for i in range(n)]

        return self._batched(fn, 6 * n, q).unflatten(-1, (6, n))


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


def _carry_composite(rot, p, mass: float, first, second) -> tuple:
    """A composite body's (M, h, J) moved from a child frame into its parent (child rotation ``rot``, child
    origin ``p``): h' = M p + R h, J' = R J Rᵀ + M(|p|² 1 − p pᵀ) + 2(p·R h) 1 − p (R h)ᵀ − (R h) pᵀ
    (parallel axes). Returns (h', J')."""
    h_rot, rj = _mv(rot, first), _mm(rot, second)
    pp, ph = _dot(p, p), _dot(p, h_rot)

    def entry(r: int, c: int) -> Any:
        diag = 1.0 if r == c else 0.0
        return _lin(
            *zip(rj[r], rot[c]),
            (mass * (pp * diag - p[r] * p[c]), 1.0),
            (2.0 * diag, ph),
            (p[r], h_rot[c], -1.0),
            (h_rot[r], p[c], -1.0),
        )

    return _add(_scale(p, mass), h_rot), _sym(entry)


def _sym(entry) -> tuple:
    """A symmetric 3x3 from ``entry(r, c)`` evaluated for r <= c only."""
    upper = {(r, c): entry(r, c) for r in range(3) for c in range(r, 3)}
    return tuple(tuple(upper[min(r, c), max(r, c)] for c in range(3)) for r in range(3))


class _Singular(Exception):
    """H(q) has a non-positive pivot at chunk row ``index`` (joint ``joint``, 1-based)."""

    def __init__(self, index: int, joint: int):
        super().__init__(index, joint)
        self.index, self.joint = index, joint


def _ldl(h: list[list]) -> tuple[list[list], list, list]:
    """H = L D Lᵀ (unit lower L, diagonal D), unrolled over [B] rows; returns (L, D, 1/D). Square-root free:
    torch runs sqrt multi-threaded even on small rows, which stalls on a busy machine. Raises _Singular at
    the first state whose H is not positive definite (a joint that moves no mass or inertia)."""
    n = len(h)
    low: list[list] = [[0.0] * n for _ in range(n)]
    scaled: list[list] = [[0.0] * n for _ in range(n)]  # L_ij D_j
    diag: list = [0.0] * n
    inv: list = [0.0] * n
    for j in range(n):
        diag[j] = _lin((h[j][j], 1.0), *((low[j][m], scaled[j][m], -1.0) for m in range(j)))
        bad = torch.as_tensor(diag[j]) <= 0
        if bool(bad.any()):
            raise _Singular(int(torch.nonzero(bad.reshape(-1))[0, 0]) if bad.ndim else 0, j + 1)
        inv[j] = 1.0 / diag[j]
        for i in range(j + 1, n):
            scaled[i][j] = _lin((h[i][j], 1.0), *((low[i][m], scaled[j][m], -1.0) for m in range(j)))
            low[i][j] = _lin((scaled[i][j], inv[j]))
    return low, diag, inv


# ------------------------------------------------------------------------------------------ config parsing
def _plain(cfg: Any) -> Any:
    """Mappings/sequences (OmegaConf nodes included) to dicts/lists of plain Python values."""
    if isinstance(cfg, Mapping):
        return {str(k): _plain(v) for k, v in cfg.items()}
    if isinstance(cfg, Sequence) and not isinstance(cfg, (str, bytes)):
        return [_plain(v) for v in cfg]
    if not isinstance(cfg, (int, float, str, bool, type(None))) and hasattr(cfg, "items"):
        return {str(k): _plain(v) for k, v in cfg.items()}
    return cfg


def _keys(node: Any, key: str, allowed: Sequence[str], required: Sequence[str] = ()) -> dict[str, Any]:
    if not isinstance(node, dict):
        raise ConfigError(key, node, f"a mapping with keys {list(allowed)}")
    for k in node:
        if k not in allowed:
            raise ConfigError(f"{key}.{k}", node[k], f"one of the keys {list(allowed)}")
    for k in required:
        if k not in node:
            raise ConfigError(f"{key}.{k}", None, "a value (the key is required)")
    return node


def _number(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(key, value, "a finite number")
    return float(value)


def _vector(value: Any, key: str, n: int = 3) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n:
        raise ConfigError(key, value, f"a list of {n} finite numbers")
    return tuple(_number(v, f"{key}[{i}]") for i, v in enumerate(value))


def _inertia(value: Any, key: str) -> Mat3:
    if isinstance(value, dict):
        node = _keys(value, key, INERTIA_KEYS, ("ixx", "iyy", "izz"))
        v = {k: _number(node.get(k, 0.0), f"{key}.{k}") for k in INERTIA_KEYS}
        return ((v["ixx"], v["ixy"], v["ixz"]), (v["ixy"], v["iyy"], v["iyz"]), (v["ixz"], v["iyz"], v["izz"]))
    if isinstance(value, list) and len(value) == 3:
        return tuple(_vector(row, f"{key}[{i}]") for i, row in enumerate(value))  # type: ignore[return-value]
    raise ConfigError(key, value, "{ixx, iyy, izz[, ixy, ixz, iyz]} or a 3x3 list (kg m^2, about the com)")


def _parse_config(node: Any, prefix: str) -> SerialArm:
    top = _keys(
        node,
        prefix,
        ("kind", "name", "gravity", "end_point", "base", "tip", "convention", "links"),
        ("gravity", "links"),
    )
    if top.get("kind", "serial") != "serial":
        raise ConfigError(f"{prefix}.kind", top["kind"], "'serial' for selpres.arms.serial.SerialArm")
    convention = top.get("convention", "urdf")
    if convention not in ("urdf", "dh"):
        raise ConfigError(f"{prefix}.convention", convention, "'urdf' (joint xyz/rpy/axis) or 'dh'")
    links = top["links"]
    if not isinstance(links, list) or not links:
        raise ConfigError(f"{prefix}.links", links, "a non-empty list of links, from the base outwards")
    kw = {k: str(top[k]) for k in ("name", "base", "tip") if k in top}
    gravity = _vector(top["gravity"], f"{prefix}.gravity")
    end = _vector(top["end_point"], f"{prefix}.end_point") if "end_point" in top else ZERO3
    joint_keys = ("name", "limits") if convention == "dh" else ("name", "xyz", "rpy", "axis", "limits")
    parsed = []
    for i, raw in enumerate(links):
        key = f"{prefix}.links[{i}]"
        geometry = "dh" if convention == "dh" else "joint"
        lk = _keys(
            raw,
            key,
            ("name", "joint", "dh", "mass", "com", "inertia")
            if convention == "dh"
            else ("name", "joint", "mass", "com", "inertia"),
            ("mass", "com", geometry),
        )
        joint = _keys(lk.get("joint", {}), f"{key}.joint", joint_keys, () if convention == "dh" else ("axis",))
        row = {
            "name": str(lk.get("name", f"link{i + 1}")),
            "mass": _number(lk["mass"], f"{key}.mass"),
            "com": _vector(lk["com"], f"{key}.com"),
            "inertia": _inertia(lk["inertia"], f"{key}.inertia") if "inertia" in lk else ZERO33,
            "joint": str(joint.get("name", f"joint{i + 1}")),
            "limits": _vector(joint["limits"], f"{key}.joint.limits", 2) if "limits" in joint else None,
        }
        if convention == "dh":
            dh = _keys(lk["dh"], f"{key}.dh", ("a", "alpha", "d", "offset"), ("a", "alpha", "d"))
            row.update({k: _number(v, f"{key}.dh.{k}") for k, v in dh.items()})
        else:
            row.update(
                xyz=_vector(joint.get("xyz", [0.0, 0.0, 0.0]), f"{key}.joint.xyz"),
                rotation=rpy_matrix(_vector(joint.get("rpy", [0.0, 0.0, 0.0]), f"{key}.joint.rpy")),
                axis=_vector(joint["axis"], f"{key}.joint.axis"),
            )
        # physical checks with this config's key names (the arm re-checks with its own)
        check = Link(
            **{k: row[k] for k in ("name", "mass", "com", "inertia", "joint", "limits")},
            **({"xyz": row["xyz"], "rotation": row["rotation"], "axis": row["axis"]} if convention == "urdf" else {}),
        )
        check_link(check, key)
        parsed.append(row)
    if convention == "dh":
        return SerialArm.from_dh(parsed, gravity, end, **kw)
    return SerialArm([Link(**r) for r in parsed], gravity, end, **kw)
