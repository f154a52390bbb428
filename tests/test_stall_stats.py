"""The exact tests of the stall outcome and the trimmed mean of the converged error (selpres.run.stats), against
scipy.stats and numbers worked out by hand."""

from __future__ import annotations

import math

import pytest
from scipy import stats as sps
from scipy.stats import mstats

from selpres.run.stats import clopper_pearson, mcnemar_exact, trimmed


@pytest.mark.parametrize("k,n", [(0, 10), (1, 10), (5, 48), (10, 96), (47, 48), (48, 48), (3, 7)])
def test_clopper_pearson_is_scipys_exact_interval(k, n):
    ci = sps.binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
    lo, hi = clopper_pearson(k, n)
    assert lo == pytest.approx(ci.low, abs=1e-12) and hi == pytest.approx(ci.high, abs=1e-12)


def test_clopper_pearson_by_hand():
    # k = 0: the upper end solves (1 - p)^n = 0.025; k = n: the lower end solves p^n = 0.025
    assert clopper_pearson(0, 10) == (0.0, pytest.approx(1 - 0.025 ** (1 / 10)))
    assert clopper_pearson(48, 48) == (pytest.approx(0.025 ** (1 / 48)), 1.0)
    assert clopper_pearson(0, 0) == (None, None)
    with pytest.raises(ValueError, match="0 <= k <= n"):
        clopper_pearson(5, 4)


def test_mcnemar_by_hand():
    # 0 vs 5 discordant: 2 * (1/2)^5; 1 vs 6: 2 * (1 + 7) / 2^7; no discordant pair: 1
    a = [False] * 5 + [True] * 3 + [False] * 10
    b = [True] * 5 + [True] * 3 + [False] * 10
    assert mcnemar_exact(a, b) == {"n": 18, "a_only": 0, "b_only": 5, "p": pytest.approx(2 / 32)}
    a = [True] + [False] * 6 + [False] * 4
    b = [False] + [True] * 6 + [False] * 4
    assert mcnemar_exact(a, b)["p"] == pytest.approx(2 * 8 / 128)
    assert mcnemar_exact([True, False], [True, False])["p"] == 1.0
    assert mcnemar_exact([True] * 4, [False] * 4)["p"] == pytest.approx(2 / 16)
    with pytest.raises(ValueError):
        mcnemar_exact([True], [True, False])


@pytest.mark.parametrize("a_only,b_only", [(0, 1), (2, 9), (7, 7), (12, 3), (30, 18)])
def test_mcnemar_is_scipys_binomial_test_on_the_discordant_pairs(a_only, b_only):
    a = [True] * a_only + [False] * b_only + [True, False] * 5
    b = [False] * a_only + [True] * b_only + [True, False] * 5
    want = sps.binomtest(a_only, a_only + b_only, 0.5).pvalue
    assert mcnemar_exact(a, b)["p"] == pytest.approx(want, rel=1e-12)


def test_trimmed_mean_by_hand():
    # 1..10, 20 %: g = 2; kept 3..8 (mean 5.5); winsorized 3,3,3,4,5,6,7,8,8,8: variance 42.5 / 9
    t = trimmed(range(1, 11), 0.2, margin=1.0)
    se = math.sqrt(42.5 / 9) / (0.6 * math.sqrt(10))
    assert t["mean"] == 5.5 and t["df"] == 5 and t["se"] == pytest.approx(se)
    assert t["p"] == pytest.approx(2 * sps.t.sf(5.5 / se, 5))
    assert t["ci95"] == pytest.approx([5.5 - sps.t.ppf(0.975, 5) * se, 5.5 + sps.t.ppf(0.975, 5) * se])
    # TOST against ±1 around a mean of 5.5: the upper hypothesis (mean >= 1) is not rejected
    assert t["p_tost"] == pytest.approx(sps.t.sf((1 - 5.5) / se, 5))  # = P(T >= (m - mean) / se): near 1


@pytest.mark.parametrize("seed", range(5))
def test_trimmed_is_scipys_trimmed_mean_and_its_standard_error(seed):
    import numpy as np

    rng = np.random.default_rng(seed)
    x = np.concatenate([rng.normal(0.1, 1, 40), rng.normal(3, 0.2, 5)])  # a tail of outliers (stalls)
    t = trimmed(x.tolist(), 0.2, margin=0.5)
    assert t["mean"] == pytest.approx(float(mstats.trimmed_mean(x, limits=(0.2, 0.2))), rel=1e-12)
    assert t["se"] == pytest.approx(float(mstats.trimmed_stde(x, limits=(0.2, 0.2))), rel=1e-12)
    df = len(x) - 2 * math.floor(0.2 * len(x)) - 1
    assert t["df"] == df
    assert t["p"] == pytest.approx(2 * sps.t.sf(abs(t["mean"]) / t["se"], df), rel=1e-9)
    # TOST: the larger of the two one-sided p-values; inside ±m exactly when the 90 % interval is
    lower, upper = sps.t.sf((t["mean"] + 0.5) / t["se"], df), sps.t.sf((0.5 - t["mean"]) / t["se"], df)
    assert (t["p_lower"], t["p_upper"]) == (pytest.approx(lower, rel=1e-9), pytest.approx(upper, rel=1e-9))
    assert t["p_tost"] == max(t["p_lower"], t["p_upper"])
    inside = -0.5 < t["ci90"][0] and t["ci90"][1] < 0.5
    assert inside == (t["p_tost"] < 0.05)


def test_trimmed_without_trimming_is_the_t_test():
    x = [0.3, -0.1, 0.8, 0.2, 0.5, -0.4, 0.9]
    t = trimmed(x, 0.0)
    ref = sps.ttest_1samp(x, 0.0)
    assert t["mean"] == pytest.approx(sum(x) / len(x)) and t["p"] == pytest.approx(ref.pvalue, rel=1e-9)


def test_trimmed_edge_cases():
    assert trimmed([], 0.2)["mean"] is None
    assert trimmed([1.0, None, math.nan], 0.2) == trimmed([1.0], 0.2)
    assert trimmed([1.0], 0.2)["p"] is None  # df 0
    with pytest.raises(ValueError, match="trim"):
        trimmed([1.0, 2.0], 0.5)
