"""Median, interquartile mean and the stratified bootstrap on hand-computed cases."""

import numpy as np
import pytest

from alphatank.training.aggregate import iqm, median, stratified_bootstrap


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
