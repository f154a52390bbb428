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
        joint: {name: joint1, xyz: [0, 0, 0], rpy: [0, 0, 0], axis: [0, 0, 1], limits: [-3.1, 3.1],
                velocity: 2.0, effort: 50.0}  # optional |q̇| (rad/s), |τ| (Nm) limits: the default boxes
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
from dataclasses import replace
from typing import Any

import torch

from selpres.arms import dynamics as dyn
from selpres.arms import spec
from selpres.arms.kinematics import (
    IDENTITY,
    ZERO3,
    ZERO33,
    Link,
    _add,
    _cross,
    _finite,
    _lin,
    _mat_mul,
    _mat_vec,
    _mv,
    _scale,
    _transpose,
    about_origin,
    check_link,
    joint_parts,
    link_rotations,
    rot_x,
    rot_z,
    world,
)
from selpres.errors import ConfigError

CHUNK = 1 << 14  # states per pass: [B] rows of 128 kB stay in cache (measured best of 2^11..2^16)


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
        source: dict | None = None,
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
        self.source = dict(source or {})  # where the arm came from (a URDF's file, modelled and held joints)
        names = [lk.name for lk in self.links] + [base]
        for kind, seq in (("link", names), ("joint", [lk.joint for lk in self.links])):
            dup = sorted({x for x in seq if seq.count(x) > 1})
            if dup:
                raise ConfigError(f"{kind} names", dup[0], f"unique {kind} names (the base counts as a link)")
        self._parts = [joint_parts(lk) for lk in self.links]
        self._about_origin = [about_origin(lk) for lk in self.links]

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
                    velocity=row.get("velocity"),
                    effort=row.get("effort"),
                )
            )
            prev_xyz, prev_rot = (a, 0.0, d), rx
        end = tuple(x + y for x, y in zip(prev_xyz, _mat_vec(prev_rot, end_point)))
        return cls(links, gravity, end, **kw)

    @classmethod
    def from_config(cls, cfg: Any, prefix: str = "robot") -> SerialArm:
        """Build from the YAML/dict spec in the module docstring (plain dicts and lists, as ``yaml.safe_load`` or
        ``selpres.run.specs.plain`` give them); errors name ``prefix.key`` and the value."""
        return spec.parse_spec(cfg, prefix, cls)

    def to_config(self) -> dict[str, Any]:
        """The URDF-style spec that ``from_config`` reads back (rotations as rpy)."""
        links = []
        for lk in self.links:
            joint = {"name": lk.joint, "xyz": list(lk.xyz), "rpy": list(lk.rpy), "axis": list(lk.axis)}
            if lk.limits is not None:
                joint["limits"] = list(lk.limits)
            joint.update({k: getattr(lk, k) for k in ("velocity", "effort") if getattr(lk, k) is not None})
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

    def rate_limits(self, kind: str = "velocity", dtype: torch.dtype = torch.float64) -> torch.Tensor:
        """``[N]`` the joints' |q̇| (``velocity``, rad/s) or |τ| (``effort``, Nm) limits; inf where not given."""
        values = [getattr(lk, kind) for lk in self.links]
        return torch.tensor([math.inf if v is None else v for v in values], dtype=dtype)

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
            except dyn.Singular as e:
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
        return link_rotations(self._parts, trig)

    def _rnea(self, rots: list, qd, qdd, k, with_gravity: bool) -> list:
        return dyn.rnea(self.links, self.gravity_vector, self.end_point, rots, qd, qdd, k, with_gravity)

    def _mass_matrix(self, rots: list) -> list[list]:
        return dyn.mass_matrix(self.links, self._about_origin, rots)

    def _world(self, trig: Sequence[torch.Tensor]) -> tuple[list, list, Any]:
        """Base-frame link orientations, joint origins and the end point (kinematics only)."""
        return world(self.links, self._rotations(trig), self.end_point)

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
        return self._batched(lambda q_: [math.prod(dyn.ldl(self._mass_matrix(self._rotations(q_)))[1])], 0, q)

    def forward_dynamics(
        self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor, k: torch.Tensor | None = None
    ) -> torch.Tensor:
        """q̈ = H⁻¹(τ − b) (eq. 5): the paper's simulator, an LDLᵀ solve per state."""
        self._check(q=q, qd=qd, tau=tau, k=k)
        n = self.dof

        def fn(q_, qd_, tau_, k_):
            rots = self._rotations(q_)
            bias = self._rnea(rots, qd_, None, k_, True)
            low, _, inv = dyn.ldl(self._mass_matrix(rots))
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
