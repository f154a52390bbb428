"""Dynamics of a serial chain in link coordinates, on batched rows (``selpres.arms.kinematics``).

Eq. (4) τ = H(q)q̈ + C(q, q̇)q̇ + G(q) + K(q)ᵀk by recursive Newton–Euler (Luh, Walker & Paul 1980); H(q) by
composite rigid bodies (Walker & Orin 1982, the paper's ref. [7]); H = L D Lᵀ for the simulator of eq. (5)
and det H. Each link's rotation from its parent, R0 Rot(axis, q), is sparse and its inertia constant.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch

from selpres.arms.kinematics import Link, Mat3, _add, _cross, _dot, _lin, _mm, _mtv, _mv, _scale


def rnea(
    links: Sequence[Link],
    gravity: Sequence[float],
    end_point: Sequence[float],
    rots: list,
    qd,
    qdd,
    k,
    with_gravity: bool,
) -> list:
    """Newton–Euler in link coordinates: τ for rates given as [B] rows (None = 0) and the base-frame
    wrench k (None = 0)."""
    zero = (0.0, 0.0, 0.0)
    w = dw = zero  # angular velocity and acceleration of the parent link, in its frame
    # acceleration of the parent's origin; gravity enters as the base accelerating upwards
    acc = tuple(-g for g in gravity) if with_gravity else zero
    loads = []
    for i, (lk, rot) in enumerate(zip(links, rots)):
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
        f, n = f_end, _add(n_end, _cross(end_point, f_end))
    else:
        f = n = zero
    tau: list = [0.0] * len(links)
    for i in range(len(links) - 1, -1, -1):
        lk, (force, moment) = links[i], loads[i]
        n = _add(_add(n, moment), _cross(lk.com, force))
        f = _add(f, force)
        tau[i] = _dot(lk.axis, n)
        if i:  # into the parent's frame, about its origin
            f = _mv(rots[i], f)
            n = _add(_mv(rots[i], n), _cross(lk.xyz, f))
    return tau


def mass_matrix(links: Sequence[Link], about_origin: Sequence[Mat3], rots: list) -> list[list]:
    """Composite rigid bodies in link coordinates: links i..N carry mass M, first moment h and inertia J
    about joint i's origin; turning joint i at unit acceleration demands the force a_i × h and moment
    J a_i there, which are carried to each joint j < i to give H_ji."""
    n = len(links)
    h_rows: list[list] = [[0.0] * n for _ in range(n)]
    mass, first, second = 0.0, (0.0, 0.0, 0.0), None
    for i in range(n - 1, -1, -1):
        lk = links[i]
        if i < n - 1:  # links i+1..N, from frame i+1 into frame i
            first, second = _carry_composite(rots[i + 1], links[i + 1].xyz, mass, first, second)
        own = about_origin[i]
        mass = mass + lk.mass
        first = _add(first, _scale(lk.com, lk.mass))
        second = own if second is None else _sym(lambda r, c, s=second, o=own: _lin((s[r][c], 1.0), (o[r][c], 1.0)))
        force, moment = _cross(lk.axis, first), _mv(second, lk.axis)
        h_rows[i][i] = _dot(lk.axis, moment)
        for j in range(i - 1, -1, -1):  # carry the column's wrench to joint j
            child = links[j + 1]
            force = _mv(rots[j + 1], force)
            moment = _add(_mv(rots[j + 1], moment), _cross(child.xyz, force))
            h_rows[j][i] = h_rows[i][j] = _dot(links[j].axis, moment)
    return h_rows


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


class Singular(Exception):
    """H(q) has a non-positive pivot at chunk row ``index`` (joint ``joint``, 1-based)."""

    def __init__(self, index: int, joint: int):
        super().__init__(index, joint)
        self.index, self.joint = index, joint


def ldl(h: list[list]) -> tuple[list[list], list, list]:
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
            raise Singular(int(torch.nonzero(bad.reshape(-1))[0, 0]) if bad.ndim else 0, j + 1)
        inv[j] = 1.0 / diag[j]
        for i in range(j + 1, n):
            scaled[i][j] = _lin((h[i][j], 1.0), *((low[i][m], scaled[j][m], -1.0) for m in range(j)))
            low[i][j] = _lin((scaled[i][j], inv[j]))
    return low, diag, inv
