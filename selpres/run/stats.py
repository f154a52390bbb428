"""Seed statistics: mean, standard deviation, median, Student-t intervals, paired t-tests, the equivalence
test (TOST), Holm's correction for a family of tests, the trimmed mean's test, and the exact tests of a yes/no
outcome (Clopper–Pearson's interval, McNemar's paired test).

The Student-t distribution is scipy's (``scipy.special.stdtr`` / ``stdtrit``, the functions ``scipy.stats.t``'s
``cdf`` and ``ppf`` call): ``scipy.stats`` itself would cost ~0.3 s of import at every job's end (measured with
``python -X importtime``), ``scipy.special`` a tenth of that, and it is imported only when a statistic is asked
for. The tests check these functions against values printed in tables and against ``scipy.stats.ttest_1samp``.
Holm's step-down is a few lines scipy does not have.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence


def t_cdf(t: float, df: int) -> float:
    """P(T ≤ t) for Student's t with ``df`` degrees of freedom."""
    from scipy.special import stdtr

    return float(stdtr(df, t))


@functools.lru_cache(maxsize=1024)  # asked for the same (p, df) for every metric of a job
def t_quantile(p: float, df: int) -> float:
    """The ``p`` quantile of Student's t with ``df`` degrees of freedom."""
    if not 0 < p < 1 or df < 1:
        raise ValueError(f"t_quantile needs 0 < p < 1 and df >= 1, got p={p}, df={df}")
    from scipy.special import stdtrit

    return float(stdtrit(df, p))


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


def median(values: Iterable[float | None]) -> float | None:
    """The middle value (the mean of the two middle ones for an even count) over the values that are not
    None or NaN; ±inf are kept, so a setting that never got there (inf) still counts in the middle."""
    vals = sorted(float(v) for v in values if v is not None and not math.isnan(v))
    n = len(vals)
    if n == 0:
        return None
    return vals[n // 2] if n % 2 else 0.5 * (vals[n // 2 - 1] + vals[n // 2])


def _mean_se(values: Iterable[float | None]) -> tuple[int, float | None, float | None]:
    """(n, mean, standard error of the mean) over the finite values, via :func:`summarize`."""
    st = summarize(values)
    se = st["std"] / math.sqrt(st["n"]) if st["std"] is not None else None
    return st["n"], st["mean"], se


def _upper_tail(diff: float, se: float, df: int) -> float:
    """P(T ≥ diff / se) for T ~ t(df); a zero standard error (all values equal) makes the test exact."""
    if se == 0:
        return 0.0 if diff > 0 else (1.0 if diff < 0 else 0.5)
    return t_cdf(-diff / se, df)


def t_test(values: Iterable[float | None], mu: float = 0.0) -> dict:
    """Two-sided one-sample t-test of mean = ``mu`` (on paired differences: the paired t-test).
    {"n", "mean", "t", "p"}; t and p are None below two values."""
    n, mean, se = _mean_se(values)
    if se is None:
        return {"n": n, "mean": mean, "t": None, "p": None}
    diff = mean - mu
    t = diff / se if se > 0 else (math.copysign(math.inf, diff) if diff else 0.0)
    p = 1.0 if diff == 0 else min(1.0, 2 * _upper_tail(abs(diff), se, n - 1))
    return {"n": n, "mean": mean, "t": t, "p": p}


def tost(values: Iterable[float | None], margin: float, alpha: float = 0.05) -> dict:
    """Two one-sided tests (Schuirmann 1987) of equivalence within ±``margin``: H0 mean ≤ −margin and H0
    mean ≥ +margin, each at level ``alpha``. {"n", "mean", "p_lower", "p_upper", "p" (the larger),
    "ci" (the 1 − 2α interval: inside ±margin exactly when p < alpha), "equivalent"}."""
    if not margin > 0:
        raise ValueError(f"tost needs a margin > 0, got {margin!r}")
    if not 0 < alpha < 0.5:
        raise ValueError(f"tost needs 0 < alpha < 0.5, got {alpha!r}")
    n, mean, se = _mean_se(values)
    out = {"n": n, "mean": mean, "p_lower": None, "p_upper": None, "p": None, "ci": [None, None], "equivalent": None}
    if se is None:
        return out
    p_lower = _upper_tail(mean + margin, se, n - 1)  # evidence against mean ≤ −margin
    p_upper = _upper_tail(margin - mean, se, n - 1)  # evidence against mean ≥ +margin
    half = t_quantile(1 - alpha, n - 1) * se
    p = max(p_lower, p_upper)
    out.update(p_lower=p_lower, p_upper=p_upper, p=p, ci=[mean - half, mean + half], equivalent=p < alpha)
    return out


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm's (1979) step-down adjusted p-values, in the input order: the i-th smallest p is multiplied by
    k − i + 1 (i from 1), made non-decreasing along that order and capped at 1. Rejecting where the
    adjusted p < α controls the family-wise error rate at α for any dependence between the tests."""
    k = len(pvalues)
    for i, p in enumerate(pvalues):
        if p is None or not 0 <= p <= 1:
            raise ValueError(f"holm needs p-values in [0, 1], got {p!r} at position {i}")
    adjusted = [0.0] * k
    running = 0.0
    for rank, i in enumerate(sorted(range(k), key=lambda j: pvalues[j])):
        running = max(running, min(1.0, (k - rank) * pvalues[i]))
        adjusted[i] = running
    return adjusted


def trimmed(values: Iterable[float | None], trim: float = 0.2, margin: float | None = None, alpha: float = 0.05):
    """The ``trim`` trimmed mean of the finite values (g = ⌊trim n⌋ cut from each end) with the Tukey–McLaughlin
    test (Wilcox's ``trimci``): standard error s_w / ((1 − 2 trim) √n), s_w the winsorized values' standard
    deviation, Student's t with n − 2g − 1 degrees of freedom. {"n", "trim", "mean", "se", "df", "ci95", "p"
    (two-sided, mean = 0), and with ``margin`` the two one-sided tests as :func:`tost`: "p_lower" (against mean
    ≤ −margin), "p_upper" (against mean ≥ +margin), "p_tost" (the larger), "ci90"}.
    Robust to a tail of outliers (a run that stalled, half-converged) where the plain mean is not."""
    if not 0 <= trim < 0.5:
        raise ValueError(f"trimmed needs 0 <= trim < 0.5, got {trim!r}")
    x = sorted(float(v) for v in values if v is not None and math.isfinite(v))
    n = len(x)
    g = math.floor(trim * n)
    out = {"n": n, "trim": trim, "mean": None, "se": None, "df": None, "ci95": [None, None], "p": None}
    out.update(p_tost=None, ci90=[None, None])
    if n == 0:
        return out
    kept = x[g : n - g]
    out["mean"] = mean = sum(kept) / len(kept)
    df = n - 2 * g - 1
    if df < 1:
        return out
    w = [x[g]] * g + kept + [x[n - g - 1]] * g  # winsorized
    wm = sum(w) / n
    se = math.sqrt(sum((v - wm) ** 2 for v in w) / (n - 1)) / ((1 - 2 * trim) * math.sqrt(n))
    half = t_quantile(0.975, df) * se
    p = 1.0 if mean == 0 else min(1.0, 2 * _upper_tail(abs(mean), se, df))
    out.update(se=se, df=df, ci95=[mean - half, mean + half], p=p)
    if margin is not None and margin > 0:
        p_lower, p_upper = _upper_tail(mean + margin, se, df), _upper_tail(margin - mean, se, df)
        half90 = t_quantile(1 - alpha, df) * se
        out.update(p_lower=p_lower, p_upper=p_upper, p_tost=max(p_lower, p_upper), ci90=[mean - half90, mean + half90])
    return out


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float | None, float | None]:
    """The exact (Clopper–Pearson 1934) interval of a binomial proportion from k successes in n trials: the
    α/2 quantile of Beta(k, n − k + 1) and the 1 − α/2 quantile of Beta(k + 1, n − k) (0 at k = 0, 1 at k = n).
    (None, None) for n = 0."""
    if not 0 <= k <= n:
        raise ValueError(f"clopper_pearson needs 0 <= k <= n, got k={k}, n={n}")
    if n == 0:
        return None, None
    from scipy.special import betaincinv

    a = (1 - level) / 2
    lo = 0.0 if k == 0 else float(betaincinv(k, n - k + 1, a))
    hi = 1.0 if k == n else float(betaincinv(k + 1, n - k, 1 - a))
    return lo, hi


def mcnemar_exact(a: Iterable[bool], b: Iterable[bool]) -> dict:
    """McNemar's exact test on paired yes/no outcomes (a[i], b[i]): only the discordant pairs count, a-only and
    b-only, and under H0 (P(a) = P(b)) each discordant pair is a-only with probability ½. {"n" (pairs),
    "a_only", "b_only", "p" (two-sided: twice the smaller binomial tail, capped at 1; 1 with no discordant
    pair)}."""
    pairs = list(zip(a, b, strict=True))
    a_only = sum(1 for x, y in pairs if x and not y)
    b_only = sum(1 for x, y in pairs if y and not x)
    d, k = a_only + b_only, min(a_only, b_only)
    p = 1.0 if d == 0 else min(1.0, 2 * sum(math.comb(d, i) for i in range(k + 1)) / 2**d)
    return {"n": len(pairs), "a_only": a_only, "b_only": b_only, "p": p}
