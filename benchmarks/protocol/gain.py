"""A model's gain over the best steering-free baseline, with its bootstrap interval.

On each seed s, the steering-free baseline
(:data:`~benchmarks.protocol.config.STEERING_FREE_BASELINES`) with the smallest lateral RMSE
L_b(s) (the seed's mean over drivers), and per model m::

    gain_m = (1/S) sum_s (L_b(s) - L_m(s))

with the 95 % interval of the verdict's hierarchical bootstrap
(:func:`~benchmarks.protocol.intervals.hierarchical_bootstrap`: seeds, then drivers within
seeds) over the per-driver differences ``L_b(s, d) - L_m(s, d)``, the best baseline of a seed
held fixed in the replicates. Positive: the model estimates the lane better than every
estimator without a steering model.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from benchmarks.protocol.config import STEERING_FREE_BASELINES
from benchmarks.protocol.intervals import hierarchical_bootstrap, percentile_interval

__all__ = ["steering_free_gain"]


def steering_free_gain(groups: Sequence[np.ndarray], names: Sequence[str]) -> dict[str, np.ndarray]:
    """``gain_over_steering_free`` and its ``_ci_low`` and ``_ci_high`` per model (module
    docstring), in ``names`` order, from the per-seed ``(drivers, models)`` lateral RMSEs
    ``groups`` (columns in ``names`` order); NaN without a steering-free baseline, and no
    interval with fewer than two values to resample."""
    free = [list(names).index(n) for n in STEERING_FREE_BASELINES if n in names]
    gains = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a model without rows: NaN
        for values in groups:
            means = np.nanmean(values[:, free], axis=0) if free else np.array([])
            if not np.isfinite(means).any():
                gains.append(np.full(values.shape, np.nan))
                continue
            best = free[int(np.nanargmin(means))]
            gains.append(values[:, [best]] - values)
        point = np.nanmean(np.array([np.nanmean(g, axis=0) for g in gains]), axis=0)
    low, high = percentile_interval(hierarchical_bootstrap(gains))
    enough = sum(np.isfinite(g).sum(axis=0) for g in gains) >= 2
    return {
        "gain_over_steering_free": point,
        "gain_over_steering_free_ci_low": np.where(enough, low, np.nan),
        "gain_over_steering_free_ci_high": np.where(enough, high, np.nan),
    }
