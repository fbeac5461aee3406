"""Median, interquartile mean, the stratified bootstrap and pooled runs on hand-computed
cases."""

import math

import numpy as np
import pytest

from alphatank.training.aggregate import iqm, median, pool_runs, stratified_bootstrap


def test_iqm_cuts_a_quarter_from_each_end():
    assert iqm(np.array([1.0, 2.0, 3.0, 4.0])) == 2.5  # mean of 2, 3
    assert iqm(np.array([0.0, 10.0, 1.0, 2.0, 3.0, 4.0, 100.0, 5.0])) == 3.5  # 2, 3, 4, 5
    assert iqm(np.array([0.2, 0.9, 0.4])) == pytest.approx(0.5)  # 3 values: nothing cut
    assert iqm(np.array([[1.0, 9.0], [3.0, 5.0]])) == 4.0  # a matrix: all scores together
    assert median(np.array([0.1, 0.7, 0.3, 0.5])) == pytest.approx(0.4)
    with pytest.raises(ValueError):
        iqm(np.array([]))


def test_bootstrap_of_two_runs_covers_both():
    # runs {0, 1}: a resample's mean is 0 (1/4), 0.5 (1/2) or 1 (1/4): the 95% interval
    # is [0, 1]; identical runs give a point
    assert stratified_bootstrap(np.array([0.0, 1.0]), reps=4000) == (0.0, 1.0)
    assert stratified_bootstrap(np.array([0.3, 0.3, 0.3])) == (0.3, 0.3)


def test_bootstrap_resamples_each_task_on_its_own():
    # task 0 always scores 0, task 1 always 1: every stratified resample keeps one of each
    # per run, so the mean is exactly 0.5 (an unstratified resample of all 4 scores is not)
    scores = np.array([[0.0, 1.0], [0.0, 1.0]])
    lo, hi = stratified_bootstrap(scores, stat=lambda m: float(np.mean(m)), reps=500)
    assert lo == hi == 0.5
    # the interval of a spread-out task contains its IQM and is reproducible
    spread = np.array([0.1, 0.35, 0.4, 0.45, 0.9])
    ci = stratified_bootstrap(spread, seed=3)
    assert ci[0] <= iqm(spread) <= ci[1] and ci == stratified_bootstrap(spread, seed=3)


def test_pooled_runs_alike_and_apart():
    same = pool_runs([50, 50, 50], [100, 100, 100])
    assert (same.wins, same.games, same.spread, same.p_value) == (150, 300, 0.0, 1.0)
    assert same.noise == pytest.approx(0.05)  # sqrt(0.5 * 0.5 / 100)
    assert same.rate == 0.5 and same.interval[0] < 0.5 < same.interval[1]
    apart = pool_runs([10, 90], [100, 100])
    assert apart.p_value < 0.01 and apart.spread == pytest.approx(0.8 / math.sqrt(2))
    assert apart.p_text == "< 0.001" and same.p_text == "1"
    # the shuffles come from the seeded generator alone
    assert pool_runs([40, 55], [100, 100], seed=3) != pool_runs([40, 55], [100, 100], seed=4)
    assert pool_runs([40, 55], [100, 100], seed=3) == pool_runs([40, 55], [100, 100], seed=3)


def test_pooled_p_value_matches_the_exact_hypergeometric_test():
    # two runs of 10 games, 10 wins in all: run 0's wins K are hypergeometric, and the
    # statistic grows with |K - 5|, so p = P(|K - 5| >= 2) for wins (3, 7)
    exact = sum(math.comb(10, k) * math.comb(10, 10 - k) for k in range(11)
                if abs(k - 5) >= 2) / math.comb(20, 10)
    got = pool_runs([3, 7], [10, 10], reps=40000, seed=1).p_value
    assert got == pytest.approx(exact, abs=0.01)  # Monte Carlo error ~0.0025
    # unequal sizes: the last run takes what the others leave
    assert 0.0 < pool_runs([1, 2, 30], [5, 10, 40]).p_value < 0.01


@pytest.mark.parametrize("wins, games, words", [
    ([3], [10], "two or more runs"),
    ([3, 4], [10], "two or more runs"),
    ([11, 4], [10, 10], "0 <= wins <= games"),
    ([1, 0], [10, 0], "games > 0"),
])
def test_pooled_runs_refuse_bad_counts(wins, games, words):
    with pytest.raises(ValueError, match=words):
        pool_runs(wins, games)
