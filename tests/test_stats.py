"""selpres.run.stats against numbers worked out independently: textbook t quantiles, the closed-form t CDF
for small df, a TOST and a paired t-test done by hand, and a Holm correction done by hand."""

from __future__ import annotations

import math

import pytest

from selpres.run.stats import holm, median, summarize, t_cdf, t_quantile, t_test, tost


@pytest.mark.parametrize(
    "p, df, q",
    [
        (0.975, 9, 2.262157),
        (0.95, 29, 1.699127),
        (0.975, 29, 2.045230),
        (0.975, 4, 2.776445),
        (0.95, 9, 1.833113),
        (0.95, 2, 2.919986),
        (0.995, 1, 63.656741),
        (0.975, 100, 1.983972),
    ],
)
def test_t_quantile_matches_printed_tables(p, df, q):
    assert t_quantile(p, df) == pytest.approx(q, abs=1e-6)
    assert t_quantile(1 - p, df) == pytest.approx(-q, abs=1e-6)


@pytest.mark.parametrize("t", [-7.5, -2.0, -0.3, 0.0, 0.7, 1.9, 12.0])
def test_t_cdf_matches_the_closed_forms_for_df_1_to_4(t):
    """df 1: Cauchy; df 2: 1/2 + t/(2√(t²+2)); df 3 and 4 from the textbook closed forms."""
    assert t_cdf(t, 1) == pytest.approx(0.5 + math.atan(t) / math.pi, abs=1e-14)
    assert t_cdf(t, 2) == pytest.approx(0.5 + t / (2 * math.sqrt(t * t + 2)), abs=1e-14)
    x = t / math.sqrt(3)
    assert t_cdf(t, 3) == pytest.approx(0.5 + (x / (1 + x * x) + math.atan(x)) / math.pi, abs=1e-14)
    u = 1 + t * t / 4
    assert t_cdf(t, 4) == pytest.approx(0.5 + 3 / 8 * t / math.sqrt(u) * (1 - t * t / (12 * u)), abs=1e-14)
    assert t_cdf(math.inf, 5) == 1.0 and t_cdf(-math.inf, 6) == 0.0


def test_interval_of_ten_values_by_hand():
    vals = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]  # mean 4.5, sample sd √(82.5/9)
    sd = math.sqrt(82.5 / 9)
    st = summarize(vals + [None, math.nan])  # missing and non-finite values are left out
    assert st["n"] == 10 and st["mean"] == pytest.approx(4.5) and st["std"] == pytest.approx(sd)
    half = 2.262157 * sd / math.sqrt(10)
    assert st["ci95"] == pytest.approx([4.5 - half, 4.5 + half], abs=1e-5)


# Differences 0, 0.1, 0.2: n = 3, mean 0.1, sd 0.1, se = 0.1/√3, df = 2, where the t CDF is
# F(t) = 1/2 + t / (2√(t² + 2)), so every p below is a square root worked out by hand.
D = [0.0, 0.1, 0.2]


def test_paired_t_test_by_hand():
    r = t_test(D)  # t = 0.1 / (0.1/√3) = √3;  p = 2(1 − F(√3)) = 1 − √(3/5)
    assert r["t"] == pytest.approx(math.sqrt(3))
    assert r["p"] == pytest.approx(1 - math.sqrt(3 / 5), abs=1e-12)
    assert r["p"] == pytest.approx(0.2254033, abs=1e-7)
    assert t_test(D, mu=0.1)["p"] == pytest.approx(1.0)
    assert t_test([0.2])["p"] is None  # one value: no test
    assert t_test([0.2, 0.2, 0.2])["p"] < 1e-30  # no spread (but rounding), mean ≠ 0: the difference is certain


def test_tost_by_hand():
    # margin 0.3: t_lower = (0.1 + 0.3)/se = 4√3, p_lower = 1/2 − √(12/50) = 0.0101021
    #             t_upper = (0.1 − 0.3)/se = −2√3, p_upper = 1/2 − √(3/14) = 0.0370900
    r = tost(D, 0.3)
    assert r["p_lower"] == pytest.approx(0.5 - math.sqrt(12 / 50), abs=1e-12)
    assert r["p_upper"] == pytest.approx(0.5 - math.sqrt(3 / 14), abs=1e-12)
    assert r["p"] == pytest.approx(0.0370900, abs=1e-7) and r["equivalent"] is True
    # 90 % interval 0.1 ± t(0.95, 2)·se = 0.1 ± 2.919986·0.0577350 = [−0.068585, 0.268585], inside ±0.3
    assert r["ci"] == pytest.approx([-0.068585, 0.268585], abs=1e-6)
    # margin 0.25: the interval pokes out (0.268585 > 0.25): p_upper = 1/2 − 1.5√3/(2√8.75) = 0.0608450
    r = tost(D, 0.25)
    assert r["p"] == pytest.approx(0.5 - 1.5 * math.sqrt(3) / (2 * math.sqrt(8.75)), abs=1e-12)
    assert r["p"] == pytest.approx(0.0608450, abs=1e-7) and r["equivalent"] is False


def test_tost_equivalent_exactly_when_the_90_percent_interval_lies_inside_the_margin():
    vals = [0.013, -0.004, 0.008, 0.021, -0.011, 0.002, 0.017, 0.005, -0.002, 0.009]
    for margin in (0.005, 0.010, 0.012, 0.014, 0.016, 0.020, 0.030):
        r = tost(vals, margin)
        lo, hi = r["ci"]
        assert r["equivalent"] == (-margin < lo and hi < margin), margin


def test_tost_refuses_a_bad_margin():
    with pytest.raises(ValueError, match="margin > 0"):
        tost(D, 0.0)
    with pytest.raises(ValueError, match="alpha"):
        tost(D, 0.1, alpha=0.6)


def test_holm_by_hand():
    # sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1 = 0.02, 0.03, 0.06, 0.04;
    # made non-decreasing: the last becomes 0.06
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm([0.5, 0.6]) == pytest.approx([1.0, 1.0])  # capped at 1, still non-decreasing
    assert holm([0.2]) == [0.2] and holm([]) == []
    with pytest.raises(ValueError, match="position 1"):
        holm([0.1, None])


def test_median_odd_even_none_nan_and_inf():
    """Middle values by hand: the odd count's middle, the even count's two middles averaged, None/NaN
    dropped, and inf kept (a setting that never reached a target sorts last, not away)."""
    assert median([0.3, 0.1, 0.2]) == 0.2
    assert median([0.4, 0.1, 0.3, 0.2]) == pytest.approx(0.25)
    assert median([None, math.nan, 5.0, 1.0]) == 3.0
    assert median([1.0, math.inf, math.inf]) == math.inf
    assert median([1.0, 2.0, math.inf]) == 2.0
    assert median([]) is None and median([None]) is None


def test_t_test_and_tost_equal_scipy_stats_ttest_1samp():
    """The paired t-test is scipy's one-sample test on the differences; TOST is two of its one-sided tests."""
    from scipy import stats as ss

    rng = [0.013, -0.004, 0.021, 0.008, 0.0, 0.017, -0.011, 0.009, 0.026, 0.003, 0.012, -0.002]
    mine, ref = t_test(rng), ss.ttest_1samp(rng, 0.0)
    assert mine["t"] == pytest.approx(ref.statistic, rel=1e-12) and mine["p"] == pytest.approx(ref.pvalue, rel=1e-10)
    m = 0.02
    eq = tost(rng, m)
    lower = ss.ttest_1samp(rng, -m, alternative="greater").pvalue
    upper = ss.ttest_1samp(rng, m, alternative="less").pvalue
    assert eq["p_lower"] == pytest.approx(lower, rel=1e-10) and eq["p_upper"] == pytest.approx(upper, rel=1e-10)
    ci = ss.t.interval(0.90, len(rng) - 1, loc=sum(rng) / len(rng), scale=ss.sem(rng))
    assert eq["ci"] == pytest.approx(list(ci), rel=1e-12)
