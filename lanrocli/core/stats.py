"""Interval estimates over a handful of runs, as Agarwal et al. (NeurIPS 2021, "Deep reinforcement learning at
the edge of the statistical precipice") recommend for results of deep RL, where three to ten seeds are usual.

Scores come as an array of runs by strata (a stratum is one task, or one task's stage). A *stratified
bootstrap* resamples the runs of each stratum with replacement, independently of the other strata, and
computes the statistic on every resample; the interval is the percentile interval of those statistics. With
one stratum it is the ordinary percentile bootstrap over runs. Statistics: the mean, the interquartile mean
(the mean of the middle half of all scores, robust to one outlying run yet less noisy than the median), and
the probability of improvement P(X > Y) that a run of one setting beats a run of another.

Pure numpy, so that ``lanro report`` and ``lanro plot`` load no more than they need.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

CONFIDENCE = 0.95
REPS = 10_000
"""Bootstrap resamples: enough that the ends of a 95% interval move by well under a percentage point
between seeds of the resampling."""
IQM_RUNS = 5
"""Fewest runs for which the interquartile mean is reported: with fewer, it trims next to nothing away."""

Statistic = Callable[[np.ndarray], np.ndarray]
"""Maps resampled scores, shaped (resamples, runs, strata), to one value per resample."""


@dataclass(frozen=True)
class Estimate:
    """A statistic of the observed scores and its bootstrap interval."""

    value: float
    low: float
    high: float
    runs: int

    @property
    def ci(self) -> tuple[float, float]:
        return (self.low, self.high)


def mean(scores: np.ndarray) -> np.ndarray:
    """The mean over runs and strata, per resample."""
    return scores.mean(axis=(-2, -1))


def iqm(scores: np.ndarray) -> np.ndarray:
    """The interquartile mean over runs and strata, per resample: a quarter of the scores cut from each end
    (rounded down), the rest averaged."""
    flat = np.sort(scores.reshape(*scores.shape[:-2], -1), axis=-1)
    cut = flat.shape[-1] // 4
    return flat[..., cut : flat.shape[-1] - cut].mean(axis=-1)


def _as_matrix(scores: np.ndarray | list[float]) -> np.ndarray:
    matrix = np.asarray(scores, dtype=float)
    if matrix.ndim == 1:
        matrix = matrix[:, None]
    if matrix.ndim != 2 or matrix.shape[0] == 0:
        raise ValueError(f"scores must be runs by strata with at least one run, not of shape {matrix.shape}")
    if np.isnan(matrix).any():
        raise ValueError("scores must not be NaN: leave out the runs that have no such score")
    return matrix


def _resample(matrix: np.ndarray, reps: int, rng: np.random.Generator) -> np.ndarray:
    """``reps`` stratified resamples of ``matrix``: each stratum's runs drawn with replacement on their own."""
    runs, strata = matrix.shape
    picks = rng.integers(0, runs, size=(reps, runs, strata))
    return matrix[picks, np.arange(strata)]


def _percentiles(values: np.ndarray, confidence: float) -> tuple[float, float]:
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(values, [tail, 100 - tail])
    return float(low), float(high)


def bootstrap(
    scores: np.ndarray | list[float],
    statistic: Statistic = mean,
    confidence: float = CONFIDENCE,
    reps: int = REPS,
    seed: int = 0,
) -> Estimate:
    """``statistic`` of ``scores`` (runs, or runs by strata) with its stratified bootstrap interval. The
    resampling has its own seed, so a report is the same every time it is made."""
    matrix = _as_matrix(scores)
    resampled = _resample(matrix, reps, np.random.default_rng(seed))
    low, high = _percentiles(statistic(resampled), confidence)
    return Estimate(float(statistic(matrix[None])[0]), low, high, matrix.shape[0])


def improvement(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """P(X > Y) per resample: over every pair of a run of ``x`` and a run of ``y`` within a stratum, 1 where
    x's is higher, 1/2 on a tie, averaged over the pairs and then over the strata (the Mann-Whitney
    statistic, normalised). ``x`` and ``y`` are shaped (resamples, runs, strata), their runs' counts may differ."""
    xs, ys = x[..., :, None, :], y[..., None, :, :]
    wins = (xs > ys) + 0.5 * (xs == ys)
    return wins.mean(axis=(-3, -2)).mean(axis=-1)


def probability_of_improvement(
    x: np.ndarray | list[float],
    y: np.ndarray | list[float],
    confidence: float = CONFIDENCE,
    reps: int = REPS,
    seed: int = 0,
) -> Estimate:
    """The probability that a run with the scores of ``x`` beats one of ``y``, with its interval: the runs of
    both resampled, each setting's and each stratum's on their own. ``runs`` counts ``x``'s."""
    a, b = _as_matrix(x), _as_matrix(y)
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"x and y must have the same strata, not {a.shape[1]} and {b.shape[1]}")
    rng = np.random.default_rng(seed)
    values = improvement(_resample(a, reps, rng), _resample(b, reps, rng))
    low, high = _percentiles(values, confidence)
    return Estimate(float(improvement(a[None], b[None])[0]), low, high, a.shape[0])


def paired_rate_difference(
    counted: np.ndarray,
    won: np.ndarray,
    confidence: float = CONFIDENCE,
    reps: int = REPS,
    seed: int = 0,
) -> Estimate:
    """Rate of the first way minus rate of the second, on units measured both ways (the same episodes played
    twice), each rate over the units it counts: ``counted`` and ``won`` are booleans shaped (2, units). The
    bootstrap draws units, not ways, so that what the two share (a scene, a goal, a mistake) cancels in
    every resample; resamples where either way counts no unit are left out."""
    counted, won = np.asarray(counted, dtype=bool), np.asarray(won, dtype=bool) & np.asarray(counted, dtype=bool)
    if counted.ndim != 2 or counted.shape[0] != 2 or counted.shape != won.shape or not counted.any(axis=1).all():
        raise ValueError(f"counted and won must be (2, units) with something counted each way, not {counted.shape}")
    units = counted.shape[1]
    rng, differences = np.random.default_rng(seed), []
    for chunk in np.array_split(np.arange(reps), max(1, reps * units // 1_000_000)):
        weights = rng.multinomial(units, np.full(units, 1 / units), size=len(chunk))
        totals, wins = weights @ counted.T.astype(float), weights @ won.T.astype(float)
        kept = (totals > 0).all(axis=1)
        differences.append(wins[kept, 0] / totals[kept, 0] - wins[kept, 1] / totals[kept, 1])
    value = won[0].sum() / counted[0].sum() - won[1].sum() / counted[1].sum()
    low, high = _percentiles(np.concatenate(differences), confidence)
    return Estimate(float(value), low, high, units)
