"""Intervals of the benchmark's verdict: a hierarchical percentile bootstrap and exact binomial bounds.

**Hierarchical percentile bootstrap** (:func:`hierarchical_bootstrap`,
:func:`percentile_interval`). The verdict's value of a model is the mean over
population seeds of a per-seed statistic over that seed's drivers (the mean,
or the median for ``ours/paper``)::

    theta = (1/S) sum_s  stat_{d in drivers(s)} x_{s,d}

Each of ``B`` bootstrap replicates draws S seeds with replacement and, for
every drawn seed, as many of its drivers as it has, with replacement, then
computes ``theta*_b`` the same way. The 95 % interval is the 2.5 and 97.5
percentiles of ``theta*_1..B``. Both levels are resampled because both are
random draws of the protocol: the seed draws the population and its runs,
the driver is one person of it. With one seed (recordings, a study) only the
drivers (participants) are resampled. Every model is computed on the same
resampled seeds and drivers of a replicate (paired), so ranks can be compared
within a replicate (:func:`replicate_ranks`). The generator's seed is fixed
(:data:`BOOTSTRAP_SEED`): the same rows give the same interval.

A percentile interval lies between the smallest and the largest replicate,
and every replicate is a mean (or median) of observed values, so the interval
stays inside the range of the quantity (an RMSE >= 0, NEES >= 0,
R^2 <= 1, a share in [0, 1]); a Student-t interval over five values does not.
With few seeds the percentile bootstrap is narrower than it should be (it
cannot see variation the S seeds did not show): read it as a description of
the spread over seeds and drivers, not as an exact 95 % coverage.

**Clopper-Pearson** (:func:`clopper_pearson`): the exact binomial interval of
a share ``k / n`` (e.g. runs ending confidently in a wrong lane)::

    low  = Beta^-1(alpha/2;  k, n - k + 1)      (0 when k = 0)
    high = Beta^-1(1 - alpha/2; k + 1, n - k)  (1 when k = n)

It treats the n runs as independent trials; runs of one driver are not quite
independent, so the bound is a lower limit on the uncertainty.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence

import numpy as np
from scipy import stats

__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "BOOTSTRAP_SEED",
    "clopper_pearson",
    "hierarchical_bootstrap",
    "percentile_interval",
    "replicate_ranks",
]

BOOTSTRAP_SEED = 24
"""Seed of the bootstrap's random generator (fixed: results are reproducible)."""
BOOTSTRAP_RESAMPLES = 2000
"""Bootstrap replicates per quantity."""


def _quiet(function: Callable[..., np.ndarray], values: np.ndarray, axis: int) -> np.ndarray:
    """``function(values, axis=axis)`` without numpy's warning on all-NaN slices (-> NaN)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.asarray(function(values, axis=axis), dtype=np.float64)


def hierarchical_bootstrap(
    groups: Sequence[np.ndarray],
    *,
    median: bool = False,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> np.ndarray:
    """Bootstrap replicates of ``theta = mean over seeds of stat over drivers`` (module docstring).

    Args:
        groups: one ``(drivers, models)`` array per seed (NaN: no value, left out of the
            statistics like the point estimate leaves it out).
        median: the per-seed statistic is the median over drivers (default: the mean).
        resamples: the number of replicates B; seed: the generator's seed.

    Returns:
        ``(B, models)`` replicates (NaN where a replicate drew no value of a model).
    """
    if not groups:
        raise ValueError("hierarchical_bootstrap needs at least one group (seed)")
    rng = np.random.default_rng(seed)
    n_models = groups[0].shape[1]
    drawn = rng.integers(len(groups), size=(resamples, len(groups)))
    per_seed = np.full((resamples, len(groups), n_models), np.nan)
    reduce = np.nanmedian if median else np.nanmean
    for s, values in enumerate(groups):
        where = np.nonzero(drawn == s)
        if not len(where[0]) or not values.shape[0]:
            continue
        drivers = rng.integers(values.shape[0], size=(len(where[0]), values.shape[0]))
        per_seed[where] = _quiet(reduce, values[drivers], axis=1)
    return _quiet(np.nanmean, per_seed, axis=1)


def percentile_interval(
    replicates: np.ndarray, level: float = 0.95
) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) per column: the ``(1 - level)/2`` and ``(1 + level)/2`` percentiles of the
    finite replicates (NaN for a column without any)."""
    q = 100.0 * np.array([(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    bounds = _quiet(lambda v, axis: np.nanpercentile(v, q, axis=axis), replicates, axis=0)
    return bounds[0], bounds[1]


def replicate_ranks(replicates: np.ndarray) -> np.ndarray:
    """Per replicate (row), each column's rank among the columns, smallest value first, ties
    sharing the lowest rank (``1 + #{j: x_j < x_i}``); 0 where the value is NaN."""
    values = np.asarray(replicates, dtype=np.float64)
    below = (values[:, None, :] < values[:, :, None]).sum(axis=2)
    return np.where(np.isfinite(values), below + 1, 0)


def clopper_pearson(successes: int, trials: int, level: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper-Pearson) ``level`` interval of the share ``successes / trials``
    (module docstring); (NaN, NaN) without trials."""
    if trials <= 0:
        return float("nan"), float("nan")
    ci = stats.binomtest(int(successes), int(trials)).proportion_ci(
        confidence_level=level, method="exact"
    )
    return float(ci.low), float(ci.high)
