"""The learning curves that size the modern study (selpres_studies.modern_curve): the budget is read off by hand."""

from __future__ import annotations

import pytest

from selpres_studies import modern_curve


def point(*rms):
    return {"rms": dict(enumerate(rms)), "cost": 100, "wall": [1.0, 3.0], "lr": {0.15}}


def test_the_chosen_budget_is_the_first_whose_doubling_moves_the_median_less_than_ten_percent():
    found = {
        # medians 4.0, 2.0, 1.9, 1.8: 5 -> 10 halves it, 10 -> 20 is -5 %: N = 10. The means (a stalled seed at 9 Nm
        # in the N = 20 run only) would move +66 % there.
        ("arm", "paper"): {5: point(3.9, 4.0, 4.1), 10: point(1.9, 2.0, 2.1), 20: point(1.8, 1.9, 9.0),
                           40: point(1.7, 1.8, 1.9)},
        # never within 10 %: the largest run is marked
        ("arm", "adam"): {5: point(4.0, 4.0, 4.0), 10: point(3.0, 3.0, 3.0)},
    }  # fmt: skip
    rows = modern_curve.curve_rows(found)
    paper = [r for r in rows if r["regime"] == "paper"]
    assert [r["epochs"] for r in paper] == [5, 10, 20, 40]
    assert [r["chosen"] for r in paper] == [False, True, False, False]
    assert paper[1]["change_at_doubling"] == pytest.approx(1.9 / 2.0 - 1)
    assert paper[2]["rms_mean"] == pytest.approx((1.8 + 1.9 + 9.0) / 3) and paper[2]["rms_median"] == 1.9
    assert paper[0]["wall_s"] == 2.0 and paper[-1]["change_at_doubling"] is None
    adam = [r for r in rows if r["regime"] == "adam"]
    assert [r["chosen"] for r in adam] == [False, False] and [r["largest"] for r in adam] == [False, True]
    assert "**chosen**" in modern_curve.markdown(rows) and "largest run" in modern_curve.markdown(rows)


def test_a_gap_in_the_doublings_chooses_nothing_across_it():
    found = {("arm", "paper"): {5: point(2.0), 20: point(1.95), 40: point(1.0)}}
    rows = modern_curve.curve_rows(found)
    assert [r["chosen"] for r in rows] == [False, False, False]  # 5 -> 20 is not a doubling; 20 -> 40 halves


def test_a_sweep_is_a_learning_curve_from_three_doublings_on():
    cases = ([], [5], [5, 10], [5, 10, 20], [5, 20, 40], [5, 10, 30, 60, 120])
    assert [modern_curve._doublings(Ns) for Ns in cases] == [0, 1, 2, 3, 2, 3]


def test_each_rate_is_its_own_curve_and_the_rate_check_picks_the_lowest_median():
    def pt(*rms, stalled=()):
        p = point(*rms)
        p["stalled"] = {s: s in stalled for s in p["rms"]}
        return p

    found = {
        ("arm", "adam", 0.003): {
            10: pt(3.0, 3.1, 3.2),
            20: pt(1.0, 1.1, 9.0, stalled=(2,)),
            40: pt(1.0, 1.05, 9.1, stalled=(2,)),
        },
        ("arm", "adam", 0.01): {20: pt(1.2, 1.3, 1.4)},
        ("arm", "adam", 0.001): {20: pt(2.0, 2.1, 2.2)},
    }
    rows = [r for r in modern_curve.curve_rows(found) if r["lr"] == "0.003"]
    assert [r["chosen"] for r in rows] == [False, True, False]  # 1.1 -> 1.05: -4.5 %
    assert (rows[1]["stalls"], rows[1]["stall_seeds"]) == (1, 3)
    assert "1/3 [" in modern_curve.markdown(rows)
    rates = modern_curve.rate_rows(found)
    assert [(r["lr"], r["chosen"]) for r in rates] == [(0.001, False), (0.003, True), (0.01, False)]  # at N = 20
    assert rates[1]["rms_median"] == 1.1 and rates[1]["stalls"] == 1


def test_a_doubling_that_still_cures_stalls_is_not_settled():
    def pt(*rms, stalled=()):
        p = point(*rms)
        p["stalled"] = {s: s in stalled for s in p["rms"]}
        return p

    # 20 -> 40: the median moves 2 %, but 6 of 20 seeds that stalled at 20 did not at 40 (McNemar p = 2 / 2^6): not
    # settled; 40 -> 80 is
    rms = [1.0] * 20
    found = {
        ("arm", "adam", 0.003): {
            20: pt(*rms, stalled=range(6)),
            40: pt(*[0.98] * 20),
            80: pt(*[0.97] * 20, stalled=(19,)),  # one more stall at 80: a rise is no cure
        }
    }
    rows = modern_curve.curve_rows(found)
    assert [r["chosen"] for r in rows] == [False, True, False]
    assert modern_curve.settled(found[("arm", "adam", 0.003)][40], found[("arm", "adam", 0.003)][80])
    assert (rows[0]["stalled_only_here"], rows[0]["stalled_only_at_2n"]) == (6, 0)
    assert rows[0]["stall_p_at_2n"] == pytest.approx(2 / 2**6)
    # five cured of 20: p = 2 / 2^5 > 0.05, not detectable: settled
    five = {20: pt(*rms, stalled=range(5)), 40: pt(*[0.98] * 20)}
    assert modern_curve.settled(five[20], five[40])
