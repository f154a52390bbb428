"""The arms of a robot config: the paper's analytic two-link arm (section 4, eq. 6) and ``make_arm``.

Point masses sit at the distal ends of the links; θ1 is measured from the horizontal, θ2 relative to
link 1 (hence c12 in the gravity term); gravity acts along −y. All methods take tensors shaped
``[..., 2]`` and compute in the inputs' dtype/device, so one call can simulate the whole
1,050,625-candidate grid of section 5.1.

``make_arm(robot_cfg)`` is the one place a robot config becomes an arm: ``kind: two_link`` (this
closed form, which the Table 1 numbers depend on), ``serial`` (``selpres.arms.serial.SerialArm`` from links
or DH rows) or ``urdf`` (``selpres.arms.urdf.load_urdf(robot.path)``). Every arm has ``to_config()``, its
canonical description (a URDF's content, not its path), which data hashes use, and ``as_serial()``,
which ``selpres-export --urdf`` writes out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import torch

from selpres.arms.serial import SerialArm
from selpres.errors import ConfigError

ROBOT_KEYS = ("m1", "m2", "l1", "l2", "g")
# the fields of robot config (selpres.run.config.RobotConfig) each kind reads; the others must stay unset
KIND_KEYS = {
    "two_link": ROBOT_KEYS,
    "serial": ("name", "convention", "gravity", "end_point", "base", "tip", "links"),
    "urdf": ("path", "g", "gravity", "base", "tip", "joints", "hold"),
}


def cfg_get(cfg: Any, key: str) -> Any:
    """Read ``key`` from a dict-like or attribute-style config (DictConfig supports both)."""
    return cfg[key] if isinstance(cfg, Mapping) else getattr(cfg, key)


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
        """Build from any mapping/attribute object holding m1, m2, l1, l2, g (e.g. an OmegaConf node)."""
        return cls(**{k: float(cfg_get(cfg, k)) for k in ROBOT_KEYS})

    def to_config(self) -> dict[str, Any]:
        """The canonical description (what ``make_arm`` reads back)."""
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


def _plain(cfg: Any) -> dict[str, Any]:
    """A robot config node (DictConfig or dict; enums by value) as a plain dict."""
    if not isinstance(cfg, Mapping) and hasattr(cfg, "items"):
        cfg = dict(cfg.items())
    if not isinstance(cfg, Mapping):
        raise ConfigError("robot", cfg, "a robot config (a mapping with a 'kind')")
    try:
        from omegaconf import DictConfig, OmegaConf

        if isinstance(cfg, DictConfig):
            return OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
    except ImportError:  # pragma: no cover
        pass
    return {str(k): (v.value if isinstance(v, Enum) else v) for k, v in cfg.items()}


def make_arm(robot_cfg: Any) -> Arm:
    """The arm a robot config describes; raises ConfigError naming ``robot.<key>`` (a URDF's errors name
    the file and the element). Reads nothing but ``robot.path``."""
    c = _plain(robot_cfg)
    kind = c.get("kind", "two_link" if all(k in c for k in ROBOT_KEYS) else None)
    if kind not in KIND_KEYS:
        raise ConfigError("robot.kind", kind, f"one of {list(KIND_KEYS)}")
    used = KIND_KEYS[kind]
    for k, v in c.items():
        if k != "kind" and k not in used and v is not None:
            raise ConfigError(f"robot.{k}", v, f"unset (null) for robot.kind={kind}, which reads {list(used)}")
    if kind == "two_link":
        for k in ROBOT_KEYS:
            v = c.get(k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ConfigError(f"robot.{k}", v, "a positive number (kg, m, m/s²)")
        return TwoLinkArm.from_config(c)
    if kind == "serial":
        return SerialArm.from_config({k: c[k] for k in ("kind", *used) if c.get(k) is not None}, "robot")
    from selpres.arms.urdf import load_urdf  # the XML reader only when a URDF is asked for

    path, g = c.get("path"), c.get("g")
    if not isinstance(path, str) or not path or path == "???":
        raise ConfigError("robot.path", path, "the URDF file to load (robot=urdf robot.path=my_arm.urdf)")
    if g is not None and (isinstance(g, bool) or not isinstance(g, (int, float)) or not (math.isfinite(g) and g >= 0)):
        raise ConfigError("robot.g", g, "gravity's magnitude in m/s² (>= 0), along -z of the URDF's root")
    gravity = c.get("gravity")
    if gravity is not None and not (
        isinstance(gravity, (list, tuple))
        and len(gravity) == 3
        and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in gravity)
    ):
        raise ConfigError("robot.gravity", gravity, "[gx, gy, gz]: three finite numbers (m/s², the root link's frame)")
    joints, hold = c.get("joints"), c.get("hold") or {}
    if joints is not None and not (isinstance(joints, list) and joints and all(isinstance(j, str) for j in joints)):
        raise ConfigError("robot.joints", joints, "a list of joint names to model (null: every revolute joint)")
    if not isinstance(hold, Mapping):
        raise ConfigError("robot.hold", hold, "{joint name: position (rad or m)} for held joints")
    return load_urdf(
        Path(path).expanduser(),
        g=g,
        gravity=gravity,
        base=c.get("base"),
        tip=c.get("tip"),
        joints=joints,
        hold=dict(hold),
    )
