"""Wilson score interval: reference values, edge cases, bad input."""

import math

import pytest

from alphatank.stats import League, wilson_interval


def test_known_values():
    # Reference: Wilson (1927) / statsmodels proportion_confint(method="wilson").
    lo, hi = wilson_interval(50, 100)
    assert lo == pytest.approx(0.40383, abs=1e-5)
    assert hi == pytest.approx(0.59617, abs=1e-5)
    lo, hi = wilson_interval(9, 10)
    assert lo == pytest.approx(0.59585, abs=1e-5)
    assert hi == pytest.approx(0.98212, abs=1e-5)


def test_edges_stay_in_unit_interval():
    lo, hi = wilson_interval(0, 20)
    assert lo == 0.0 and 0.0 < hi < 0.2
    lo, hi = wilson_interval(20, 20)
    assert hi == 1.0 and 0.8 < lo < 1.0
    assert wilson_interval(0, 0) == (0.0, 1.0)


def test_contains_point_estimate_and_narrows_with_n():
    widths = []
    for n in (10, 100, 1000):
        lo, hi = wilson_interval(0.3 * n, n)
        assert lo < 0.3 < hi
        widths.append(hi - lo)
    assert widths[0] > widths[1] > widths[2]
    # width shrinks like 1/sqrt(n)
    assert widths[1] / widths[2] == pytest.approx(math.sqrt(10), rel=0.05)


def test_z_widens():
    a = wilson_interval(30, 100, z=1.0)
    b = wilson_interval(30, 100, z=2.576)
    assert b[0] < a[0] and b[1] > a[1]


@pytest.mark.parametrize("s,n,z", [(5, 4, 1.96), (-1, 4, 1.96), (1, -2, 1.96), (1, 4, 0.0),
                                   (5, 10, float("nan")), (5, 10, float("inf")),
                                   (5, float("inf"), 1.96), (5, float("nan"), 1.96)])
def test_bad_input(s, n, z):
    with pytest.raises(ValueError, match="wilson_interval"):
        wilson_interval(s, n, z)


def test_league_ranks_the_player_who_wins():
    league = League(["strong", "weak", "even"])
    for _ in range(10):
        league.record(0, 1, 1)
        league.record(2, 1, 0)
    rows = league.table()
    assert rows[0][0] == "strong"
    assert rows[-1][0] == "weak"
    with pytest.raises(ValueError, match="outcome must be"):
        league.record(0, 1, 2)
    for i, j in ((0, -1), (0, 3), (1, 1)):  # a negative index would rate the last player
        with pytest.raises(ValueError, match="a game needs two different players of the 3"):
            league.record(i, j, 1)
    k = league.add("late", mu=30.0, sigma=2.0)
    assert k == 3 and league.names[k] == "late" and league.ratings[k].mu == 30.0
    league.record(k, 0, -1)
    assert league.ratings[k].mu < 30.0


@pytest.mark.parametrize("n", [1, 7, 100, 200, 1000])
def test_interval_always_contains_the_observed_rate(n):
    for k in (0, n // 3, n):
        lo, hi = wilson_interval(k, n)
        assert lo <= k / n <= hi
