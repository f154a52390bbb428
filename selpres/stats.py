"""Seed statistics: mean, standard deviation and Student-t 95 % intervals, without scipy.

The t quantile is found by bisection on the exact Student-t CDF for whole degrees of freedom
(closed-form finite series in θ = atan(t/√ν)), so intervals over a handful of seeds are honest.
"""

from __future__ import annotations

import math
from typing import Iterable


def t_cdf(t: float, df: int) -> float:
    """Exact CDF of Student's t with whole df (Abramowitz & Stegun 26.7.3/26.7.4)."""
    theta = math.atan(t / math.sqrt(df))
    s, c = math.sin(theta), math.cos(theta)
    if df % 2 == 1:
        total, term = 0.0, c
        if df > 1:
            total = term
            for k in range(3, df - 1, 2):
                term *= c * c * (k - 1) / k
                total += term
        a = (2 / math.pi) * (theta + s * total) if df > 1 else (2 / math.pi) * theta
    else:
        total, term = 1.0, 1.0
        for k in range(2, df - 1, 2):
            term *= c * c * (k - 1) / k
            total += term
        a = s * total
    return 0.5 + 0.5 * a


def t_quantile(p: float, df: int) -> float:
    if not 0 < p < 1 or df < 1:
        raise ValueError(f"t_quantile needs 0 < p < 1 and df >= 1, got p={p}, df={df}")
    lo, hi = -1e3, 1e3
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if t_cdf(mid, df) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def summarize(values: Iterable[float | None]) -> dict:
    """mean, sample std, 95 % t-interval of the mean over the finite values; counts what was left out."""
    vals = [float(v) for v in values if v is not None and math.isfinite(v)]
    n = len(vals)
    out = {"n": n, "mean": None, "std": None, "ci95": [None, None], "min": None, "max": None}
    if n == 0:
        return out
    mean = sum(vals) / n
    out.update(mean=mean, min=min(vals), max=max(vals))
    if n >= 2:
        std = math.sqrt(sum((v - mean) ** 2 for v in vals) / (n - 1))
        half = t_quantile(0.975, n - 1) * std / math.sqrt(n)
        out.update(std=std, ci95=[mean - half, mean + half])
    return out
