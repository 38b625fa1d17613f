"""The bootstrap of lanrocli.core.stats against distributions worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from lanrocli.core.stats import bootstrap, improvement, iqm, mean, paired_rate_difference, probability_of_improvement

MANY = 100_000
"""Resamples for the tests: the sample quantiles then sit well inside the steps of the exact distributions."""


def test_one_stratum_of_two_runs() -> None:
    # Resampling two runs scoring 0 and 1: the mean is 0, 1/2 or 1 with probabilities 1/4, 1/2, 1/4. So the
    # 2.5% and 97.5% quantiles are 0 and 1, and the 30% and 70% quantiles both 1/2.
    assert bootstrap([0.0, 1.0], reps=MANY).ci == (0.0, 1.0)
    estimate = bootstrap([0.0, 1.0], confidence=0.4, reps=MANY)
    assert (estimate.value, estimate.low, estimate.high, estimate.runs) == (0.5, 0.5, 0.5, 2)


def test_strata_are_resampled_apart() -> None:
    # Two strata (tasks) of two runs, scoring 0 and 1 in each. Resampled stratum by stratum, the mean of the
    # four scores is Binomial(4, 1/2) / 4: P(0) = 1/16, P(1/4) = 4/16, P(1/2) = 6/16, P(3/4) = 4/16, P(1) = 1/16,
    # so its 10% and 90% quantiles are 1/4 and 3/4. Resampling whole runs (rows) instead would give 0 and 1.
    scores = np.array([[0.0, 0.0], [1.0, 1.0]])
    assert bootstrap(scores, confidence=0.8, reps=MANY).ci == (0.25, 0.75)


def test_the_interquartile_mean_trims_a_quarter_from_each_end() -> None:
    scores = np.array([1, 2, 3, 4, 5, 6, 7, 100], dtype=float)[:, None]
    assert iqm(scores[None])[0] == pytest.approx(4.5)  # the mean of 3, 4, 5, 6
    assert mean(scores[None])[0] == pytest.approx(16.0)
    assert bootstrap(scores, iqm, reps=1000).value == pytest.approx(4.5)


def test_probability_of_improvement_counts_ties_as_half() -> None:
    # Pairs (1, 0), (1, 2), (2, 0), (2, 2): wins 1, 0, 1 and a tie, so 2.5 of 4.
    x, y = np.array([1.0, 2.0])[:, None], np.array([0.0, 2.0])[:, None]
    assert improvement(x[None], y[None])[0] == 0.625
    estimate = probability_of_improvement([1.0, 2.0], [0.0, 2.0], reps=MANY)
    assert estimate.value == 0.625 and estimate.low <= 0.625 <= estimate.high
    assert probability_of_improvement([3.0, 4.0], [1.0, 2.0]).ci == (1.0, 1.0)


def test_resampling_is_repeatable_and_refuses_gaps() -> None:
    assert bootstrap([0.2, 0.5, 0.9]) == bootstrap([0.2, 0.5, 0.9])
    with pytest.raises(ValueError, match="NaN"):
        bootstrap([0.5, float("nan")])
    with pytest.raises(ValueError, match="at least one run"):
        bootstrap([])


def test_a_paired_difference_cancels_what_both_ways_share() -> None:
    rng = np.random.default_rng(1)
    units = 500
    counted = np.ones((2, units), dtype=bool)
    counted[:, rng.random(units) < 0.6] = False  # the units where neither way counts (no correction spoken)
    shared = rng.random(units) < 0.9  # what the two ways of playing a unit share decides most outcomes
    won = np.stack([shared & (rng.random(units) < 0.95), shared])
    estimate = paired_rate_difference(counted, won)
    rates = (won & counted).sum(axis=1) / counted.sum(axis=1)
    assert estimate.value == pytest.approx(rates[0] - rates[1]) and estimate.runs == units
    # The first way loses about 5 points; paired, the interval excludes no change, which two independent
    # samples of this size could not show (their Wilson intervals would overlap).
    assert estimate.low < estimate.value < estimate.high < 0
    assert estimate.high - estimate.low < 0.07
    same = paired_rate_difference(counted, np.stack([shared, shared]))
    assert (same.value, same.low, same.high) == (0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="something counted each way"):
        paired_rate_difference(np.zeros((2, 4), dtype=bool), np.zeros((2, 4), dtype=bool))
