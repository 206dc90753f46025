"""Properties of the mixture filter under corrupted measurement streams (hypothesis).

A realistic run (the paper's ARX model driving the env, 4 s) with NaN, +-inf,
huge values and outliers injected anywhere, in any channel: the weights stay
finite and sum to 1, every component covariance stays symmetric positive
definite, the estimate stays finite; and the fast filter equals the filterpy
reference on such streams.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators._testing import drive_arx
from estimators.base import ACCELERATION_KEYS, MEASUREMENT_KEYS
from estimators.filterpy_ekf import FilterpyGMEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.settings import FilterSettings
from hasa_env.steering.arx import ARXForm

PAPER = ARXForm(a=(1.47, -0.51), b=(-5.73, 17.32, -17.65, 6.12), c=(0.11,), d=(-0.02, 0.02))
STEPS = 400
SETTINGS = FilterSettings(steering_ratio=15.0, steering_residual_std=1e-3)


@functools.cache
def clean_stream() -> tuple[np.ndarray, np.ndarray]:
    """Measurements (T, 3) and IMU (T, 2) of a 4 s closed-loop run."""
    frame = drive_arx(PAPER, runs=1, seed=11, duration=STEPS / 100, bias_index=1)[0]
    z = frame[list(MEASUREMENT_KEYS)].to_numpy(dtype=np.float64)
    a = frame[list(ACCELERATION_KEYS)].to_numpy(dtype=np.float64)
    return z, a


BAD_VALUES = st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 1e6, -1e6])
corruption = st.tuples(
    st.integers(1, STEPS - 1),  # row (row 0 resets the filter: finite speed and camera)
    st.integers(0, 4),  # channel: speed, camera, steering, IMU x, IMU y
    st.one_of(
        BAD_VALUES.map(lambda v: ("set", v)),
        st.floats(-100.0, 100.0).map(lambda v: ("add", v)),
    ),
    st.integers(1, 40),  # how many rows from there
)


def corrupted(corruptions: list) -> tuple[np.ndarray, np.ndarray]:
    z, a = (arr.copy() for arr in clean_stream())
    data = np.concatenate([z, a], axis=1)
    for row, channel, (kind, value), length in corruptions:
        rows = slice(row, min(row + length, STEPS))
        if kind == "set":
            data[rows, channel] = value
        else:
            data[rows, channel] += value
    return data[:, :3], data[:, 3:]


@pytest.mark.slow
@given(corruptions=st.lists(corruption, max_size=12), hypotheses=st.sampled_from([2, 3]))
@settings(max_examples=25, deadline=None)
def test_corrupted_streams_keep_the_filter_sound(corruptions, hypotheses):
    z, a = corrupted(corruptions)
    ekf = GaussianMixtureEKF(PAPER, SETTINGS)
    est = ekf.reset(z[0], [0.0, -1.8, 1.8][:hypotheses])
    for k in range(1, STEPS):
        est = ekf.step(z[k], a[k])
        w = est.weights
        assert np.all(np.isfinite(w)) and math.isclose(w.sum(), 1.0, rel_tol=1e-9), k
        assert np.all(np.isfinite(est.mean)), k
        cov = est.component_covariances
        np.testing.assert_array_equal(cov, np.swapaxes(cov, -1, -2))
        np.linalg.cholesky(cov)  # raises unless every covariance is positive definite
    assert np.all(ekf.gated_counts >= 0)


@given(corruptions=st.lists(corruption, min_size=1, max_size=6))
@settings(max_examples=8, deadline=None)
def test_fast_filter_equals_filterpy_on_corrupted_streams(corruptions):
    z, a = corrupted(corruptions)
    steps = 150
    fast, ref = GaussianMixtureEKF(PAPER, SETTINGS), FilterpyGMEKF(PAPER, SETTINGS)
    fast.reset(z[0], [0.0, -1.8])
    ref.reset(z[0], [0.0, -1.8])
    for k in range(1, steps):
        ours, theirs = fast.step(z[k], a[k]), ref.step(z[k], a[k])
        np.testing.assert_allclose(ours.component_means, theirs.component_means, atol=1e-8)
        np.testing.assert_allclose(ours.weights, theirs.weights, atol=1e-9)
        np.testing.assert_array_equal(fast.last_gated, ref.last_gated)
