"""Interval estimates over seeds, as in rliable (Agarwal et al., NeurIPS 2021), knowing nothing
of runs, curves or claims: the interquartile mean (IQM, the mean of the middle 50% of runs) of
a number over seeds, the probability of
improvement P(a better than b) = P(X_a > X_b) + P(X_a = X_b) / 2 for one run drawn from
each curve (the Mann-Whitney U statistic over n_a n_b), and 95% percentile bootstrap
confidence intervals in which every curve's runs are resampled on their own (the stratified
bootstrap with one stratum per curve). With one seed there is no interval (NaN).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

CONFIDENCE = 0.95
N_RESAMPLES = 10_000
SEED = 0  # every bootstrap starts from this seed, so a result does not depend on call order


@dataclass(frozen=True)
class Interval:
    """A point estimate and its bootstrap confidence interval (NaN bounds: no interval)."""

    point: float
    low: float
    high: float

    def fmt(self, spec: str = ".3f") -> str:
        if np.isnan(self.low):
            return f"{self.point:{spec}} [no interval: 1 seed]"
        return f"{self.point:{spec}} [{self.low:{spec}}, {self.high:{spec}}]"


def iqm(x, axis: int = -1):
    """Interquartile mean: the mean after cutting 25% of the values at each end (rliable's IQM).

    ``scipy.stats.trim_mean`` cuts ``int(0.25 n)`` values per side, so with 5 seeds it is the
    mean of the middle three.
    """
    return stats.trim_mean(x, 0.25, axis=axis)


def probability_of_improvement(x, y, axis: int = -1):
    """P(X > Y) + P(X = Y) / 2 for X drawn from ``x`` and Y from ``y``: the Mann-Whitney U
    statistic of x over y divided by n_x n_y (rliable's probability of improvement, one task)."""
    x = np.moveaxis(np.asarray(x, dtype=float), axis, -1)[..., :, None]
    y = np.moveaxis(np.asarray(y, dtype=float), axis, -1)[..., None, :]
    p = ((x > y) + 0.5 * (x == y)).mean(axis=(-2, -1))
    # a NaN ranks nowhere: counted as a loss it would bias P towards 0, so P is NaN instead
    p = np.where(np.isnan(x).any(axis=(-2, -1)) | np.isnan(y).any(axis=(-2, -1)), np.nan, p)
    return float(p) if p.ndim == 0 else p


def bootstrap_interval(statistic, *samples, confidence: float = CONFIDENCE,
                       n_resamples: int = N_RESAMPLES, seed: int = SEED) -> Interval:
    """``statistic(*samples)`` with its percentile bootstrap interval.

    Each sample is one stratum, resampled with replacement on its own (a curve's runs are
    never mixed with another curve's): rliable's stratified bootstrap with one task.
    ``statistic`` must take an ``axis`` keyword (it is evaluated on all resamples at once).
    """
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    samples = [np.asarray(s, dtype=float) for s in samples]
    point = float(statistic(*samples, axis=-1))
    if min(len(s) for s in samples) < 2:
        return Interval(point, np.nan, np.nan)
    ci = stats.bootstrap(samples, statistic, n_resamples=n_resamples, confidence_level=confidence,
                         method="percentile", vectorized=True, rng=np.random.default_rng(seed)).confidence_interval
    return Interval(point, float(ci.low), float(ci.high))
