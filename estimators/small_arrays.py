"""Tests on the filter's small arrays without numpy's per-call overhead of a reduction.

One car's filter step (:class:`estimators.gm_ekf.GaussianMixtureEKF` on one run) asks a dozen
questions a step of arrays of one to six numbers: is any channel off, is any reading missing,
is the favourite's distance inside the gate. A numpy reduction (``any``, ``sum``, ``max``)
costs about 1 us whatever the size, a Python loop over ``tolist()`` a tenth of it on such
arrays; on a batch the reduction is the faster. Each function here answers its question with
the one or the other by size, the same answer either way: they decide branches, they never
compute a number the filter stores.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "SMALL_SIZE",
    "all_finite",
    "all_true",
    "all_within",
    "any_equal",
    "any_nan",
    "any_true",
    "min_below",
]

SMALL_SIZE = 16
"""Arrays of at most this many entries are tested in Python (one run's arrays: C <= 8)."""


def any_true(mask: np.ndarray) -> bool:
    """``mask.any()`` of a boolean array."""
    if mask.size > SMALL_SIZE:
        return bool(mask.any())
    return True in mask.ravel().tolist()


def any_equal(values: np.ndarray, value: float) -> bool:
    """``(values == value).any()`` (``value`` not NaN)."""
    if values.size > SMALL_SIZE:
        return bool((values == value).any())
    return value in values.ravel().tolist()


def all_true(mask: np.ndarray) -> bool:
    """``mask.all()`` of a boolean array."""
    if mask.size > SMALL_SIZE:
        return bool(mask.all())
    return False not in mask.ravel().tolist()


def all_finite(values: np.ndarray) -> bool:
    """No entry of ``values`` is NaN or +-inf. A large array is tested by its sum
    (``math.isfinite(values.sum())``, one reduction), which also fails when finite entries
    overflow it (beyond 1.8e308): where the filter asks, it then takes its path for
    non-finite entries, which gives the same numbers on finite ones."""
    if values.size > SMALL_SIZE:
        return math.isfinite(values.sum())
    return all(map(math.isfinite, values.ravel().tolist()))


def any_nan(values: np.ndarray) -> bool:
    """Some entry of ``values`` is NaN, for arrays without +-inf (the filter's, whose
    non-finite entries are NaN). A large array is tested by its sum
    (``math.isnan(values.sum())``, one reduction)."""
    if values.size > SMALL_SIZE:
        return math.isnan(values.sum())
    return any(map(math.isnan, values.ravel().tolist()))


def all_within(values: np.ndarray, limit: float) -> bool:
    """Every entry of ``values`` has ``|v| <= limit`` (False with a NaN)."""
    if values.size > SMALL_SIZE:
        return bool(np.abs(values).max() <= limit)
    for value in values.ravel().tolist():
        if not abs(value) <= limit:
            return False
    return True


def min_below(values: np.ndarray, bound: float) -> bool:
    """``values.min() < bound``: some entry is below ``bound`` and none is NaN."""
    if values.size > SMALL_SIZE:
        return bool(values.min() < bound)
    below = False
    for value in values.ravel().tolist():
        if value != value:  # NaN
            return False
        below = below or value < bound
    return below
