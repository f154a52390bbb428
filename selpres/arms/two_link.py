"""The paper's analytic two-link arm (section 4, eq. 6).

Point masses sit at the distal ends of the links; θ1 is measured from the horizontal, θ2 relative to
link 1 (hence c12 in the gravity term); gravity acts along −y. All methods take tensors shaped
``[..., 2]`` and compute in the inputs' dtype/device, so one call can simulate the whole
1,050,625-candidate grid of section 5.1.

A robot node becomes an arm through its source (``selpres.arms.sources``: ``two_link`` is this closed form, which
the Table 1 numbers depend on). Every arm has ``to_config()``, its canonical description (a URDF's content, not
its path), which data hashes use, and ``as_serial()``, which ``selpres-export --urdf`` writes out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch

from selpres.arms.serial import SerialArm

ROBOT_KEYS = ("m1", "m2", "l1", "l2", "g")


@dataclass(frozen=True)
class TwoLinkArm:
    """Masses m1, m2 (kg), link lengths l1, l2 (m), gravity g (m/s²)."""

    m1: float
    m2: float
    l1: float
    l2: float
    g: float = 9.81

    @classmethod
    def from_config(cls, cfg: Any) -> TwoLinkArm:
        """Build from any mapping holding m1, m2, l1, l2, g (a dict, an OmegaConf node)."""
        return cls(**{k: float(cfg[k]) for k in ROBOT_KEYS})

    def to_config(self) -> dict[str, Any]:
        """The canonical description (what ``selpres.arms.sources.make_arm`` reads back)."""
        return {"kind": "two_link", **{k: getattr(self, k) for k in ROBOT_KEYS}}

    def as_serial(self) -> SerialArm:
        """The same arm in the general code (agrees with eq. 6 to rounding): what a URDF export writes."""
        return SerialArm.two_link(self.m1, self.m2, self.l1, self.l2, self.g)

    @property
    def name(self) -> str:
        return "two_link"

    @property
    def dof(self) -> int:
        return 2

    def joint_limits(self, dtype: torch.dtype = torch.float64) -> torch.Tensor:
        """``[2, 2]``: the paper's joints have no limits (±inf)."""
        return torch.tensor([[-math.inf, math.inf]] * 2, dtype=dtype)

    def rate_limits(self, kind: str = "velocity", dtype: torch.dtype = torch.float64) -> torch.Tensor:
        """``[2]``: no velocity or effort limits (inf)."""
        return torch.full((2,), math.inf, dtype=dtype)

    def _terms(self, q: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The entries of H(q) that eq. 6 shares between H, C and the solve."""
        c2 = torch.cos(q[..., 1])
        a = self.m2 * self.l2**2
        b = self.m2 * self.l1 * self.l2
        h11 = a + 2.0 * b * c2 + (self.m1 + self.m2) * self.l1**2
        h12 = a + b * c2
        h22 = torch.full_like(c2, a)
        return h11, h12, h22

    def mass_matrix(self, q: torch.Tensor) -> torch.Tensor:
        """H(q) ``[..., 2, 2]``: symmetric positive definite inertia matrix."""
        h11, h12, h22 = self._terms(q)
        return torch.stack((torch.stack((h11, h12), -1), torch.stack((h12, h22), -1)), -2)

    def coriolis(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        """C(q, q̇) ``[..., 2]`` as the paper writes it: a vector, already multiplied by the velocities."""
        k = self.m2 * self.l1 * self.l2 * torch.sin(q[..., 1])
        w1, w2 = qd[..., 0], qd[..., 1]
        return torch.stack((-k * (w2 * w2 + 2.0 * w1 * w2), k * w1 * w1), -1)

    def gravity(self, q: torch.Tensor) -> torch.Tensor:
        """G(q) ``[..., 2]``: torques holding the arm against gravity."""
        c1 = torch.cos(q[..., 0])
        c12 = torch.cos(q[..., 0] + q[..., 1])
        g2 = self.m2 * self.l2 * self.g * c12
        return torch.stack((g2 + (self.m1 + self.m2) * self.l1 * self.g * c1, g2), -1)

    def bias(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        """Bias torque b = C + G (eq. 5): the torque giving zero acceleration."""
        return self.coriolis(q, qd) + self.gravity(q)

    def det_mass_matrix(self, q: torch.Tensor) -> torch.Tensor:
        """det H(q) ``[...]``: the Jacobian of θ̈ → τ, needed for exact sampling in selpres.data.paper."""
        h11, h12, h22 = self._terms(q)
        return h11 * h22 - h12 * h12

    def inverse_dynamics(self, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor) -> torch.Tensor:
        """τ = H q̈ + C + G (eq. 6): what the network learns."""
        h11, h12, h22 = self._terms(q)
        a1, a2 = qdd[..., 0], qdd[..., 1]
        return torch.stack((h11 * a1 + h12 * a2, h12 * a1 + h22 * a2), -1) + self.bias(q, qd)

    def forward_dynamics(self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
        """q̈ = H⁻¹(τ − b) (eq. 5), closed-form 2×2 solve: the paper's simulator."""
        h11, h12, h22 = self._terms(q)
        r = tau - self.bias(q, qd)
        r1, r2 = r[..., 0], r[..., 1]
        det = h11 * h22 - h12 * h12
        return torch.stack(((h22 * r1 - h12 * r2) / det, (h11 * r2 - h12 * r1) / det), -1)


Arm = TwoLinkArm | SerialArm
