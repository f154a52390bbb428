"""The data every room shares: patterns, the exemplar and test sets made of them, their scaling into the sigmoid's
range, and the paper's error criterion.

A data route (``selpres.data``) makes these, the engines and the loop (``selpres.run``) train and score on them, the
export writes them out and the cache keeps them: so they live here, at the bottom of the flow, beside ``errors`` and
``storage``, and import no room. Tensors are float64 (:data:`DTYPE`), inputs ``X [n, inputs]`` and targets
``Y [n, outputs]`` in raw units (Nm for an arm); nothing here reads a config.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import torch

DTYPE = torch.float64


@dataclass(frozen=True)
class Patterns:
    """Input rows ``X [n, inputs]`` and targets ``Y [n, outputs]`` (Nm for an arm), float64."""

    X: torch.Tensor
    Y: torch.Tensor

    def __iter__(self):  # allows ``X, Y = patterns``
        return iter((self.X, self.Y))

    def __len__(self) -> int:
        return int(self.X.shape[0])


@dataclass(frozen=True)
class ExemplarSet(Patterns):
    """The exemplar set U (the paper's 1002 patterns with the default robot) and how many candidates (grid
    points, draws or file rows) it came from."""

    n_candidates: int = 0


@dataclass(frozen=True)
class TestSets:
    """``test10``: the paper's 10 random test patterns (``test10_from_exemplar`` marks the rows taken from
    the exemplar set); ``heldout``: many outside patterns, for a metric that is not dominated by noise."""

    test10: Patterns
    test10_from_exemplar: torch.Tensor
    heldout: Patterns


@dataclass(frozen=True)
class Scaler:
    """Per-column affine map of [min − margin·range, max + margin·range] onto [lo, hi] ⊂ (0, 1).

    The BPN's output units are sigmoids, so targets must lie inside (0, 1) and away from its flat ends. Mode
    ``exemplar`` uses the exemplar set's own min/max, ``commanded`` the boxes the data was drawn from (why the
    paper's task uses ``exemplar``: docs/reproducibility.md, "Scaling").
    """

    x_min: torch.Tensor  # data-side bounds (margin already applied), [inputs]
    x_max: torch.Tensor
    y_min: torch.Tensor  # [outputs]
    y_max: torch.Tensor
    lo: float = 0.1
    hi: float = 0.9

    @classmethod
    def fit(
        cls, exemplar: Patterns, scaling: Mapping[str, Any], commanded: tuple[torch.Tensor, ...] | None = None
    ) -> Scaler:
        """The scaler ``scaling`` = {mode, margin, lo, hi} asks for: bounds from the exemplar set (mode
        ``exemplar``) or from ``commanded`` = (x lo, x hi, y lo, y hi), the boxes (mode ``commanded``)."""
        mode = str(getattr(scaling["mode"], "value", scaling["mode"]))  # a typed config holds an enum
        margin = float(scaling["margin"])
        if mode == "exemplar":
            x0, x1 = exemplar.X.min(0).values, exemplar.X.max(0).values
            y0, y1 = exemplar.Y.min(0).values, exemplar.Y.max(0).values
        elif mode == "commanded":
            if commanded is None:
                raise ValueError("scaling.mode: 'commanded' needs the commanded boxes, and none were given")
            x0, x1, y0, y1 = commanded
        else:
            raise ValueError(f"scaling.mode: expected 'exemplar' or 'commanded', got {mode!r}")

        def widen(v0: torch.Tensor, v1: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            span = v1 - v0
            span = torch.where(span > 0, span, torch.ones_like(span))  # constant column: any invertible map
            return (v0 - margin * span).to(DTYPE), (v1 + margin * span).to(DTYPE)

        lo, hi = float(scaling["lo"]), float(scaling["hi"])
        if not lo < hi:
            raise ValueError(f"scaling: lo ({lo}) must be < hi ({hi})")
        return cls(*widen(x0, x1), *widen(y0, y1), lo=lo, hi=hi)

    def _fwd(self, v: torch.Tensor, v0: torch.Tensor, v1: torch.Tensor) -> torch.Tensor:
        v0, v1 = v0.to(v), v1.to(v)
        return self.lo + (v - v0) * ((self.hi - self.lo) / (v1 - v0))

    def _inv(self, s: torch.Tensor, v0: torch.Tensor, v1: torch.Tensor) -> torch.Tensor:
        v0, v1 = v0.to(s), v1.to(s)
        return v0 + (s - self.lo) * ((v1 - v0) / (self.hi - self.lo))

    def transform_x(self, X: torch.Tensor) -> torch.Tensor:
        return self._fwd(X, self.x_min, self.x_max)

    def inverse_x(self, Xs: torch.Tensor) -> torch.Tensor:
        return self._inv(Xs, self.x_min, self.x_max)

    def transform_y(self, Y: torch.Tensor) -> torch.Tensor:
        return self._fwd(Y, self.y_min, self.y_max)

    def inverse_y(self, Ys: torch.Tensor) -> torch.Tensor:
        return self._inv(Ys, self.y_min, self.y_max)


def metric_names(n_outputs: int) -> tuple[str, ...]:
    """``overall, tau1..tauK``: the per-output keys of ``rms_errors`` (output k is "tau<k>" whatever its
    column is called, so results.json reads alike for every arm and data file)."""
    return ("overall", *(f"tau{k}" for k in range(1, n_outputs + 1)))


def rms_errors(pred_scaled: torch.Tensor, Y_true_Nm: torch.Tensor, scaler: Scaler) -> dict[str, torch.Tensor]:
    """The paper's criterion, RMS of (network output − actual output), in Nm and in scaled units.

    ``pred_scaled`` is ``[..., N, K]`` (e.g. a leading replica dim R); every value has the leading shape
    ``[...]``. Keys ``<name>_Nm`` and ``<name>_scaled`` for every name of ``metric_names(K)`` (tau1_Nm, …,
    overall_Nm, …); overall = sqrt of the mean squared error over all outputs and all patterns.
    """
    Y_true_Nm = Y_true_Nm.to(pred_scaled)
    out: dict[str, torch.Tensor] = {}
    for unit, err in (
        ("Nm", scaler.inverse_y(pred_scaled) - Y_true_Nm),
        ("scaled", pred_scaled - scaler.transform_y(Y_true_Nm)),
    ):
        sq = err.square()
        per_joint = sq.mean(-2).sqrt()  # [..., K]
        for k, name in enumerate(metric_names(per_joint.shape[-1])[1:]):
            out[f"{name}_{unit}"] = per_joint[..., k]
        out[f"overall_{unit}"] = sq.mean((-2, -1)).sqrt()
    return out
