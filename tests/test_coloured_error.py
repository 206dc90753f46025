"""The coloured, speed-scaled equation error carried as a filter state (docs/design.md §8.34)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from estimators._testing import drive_arx
from estimators.arx_state_space import ARXStateSpace
from estimators.filterpy_ekf import FilterpyGMEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.offline import run_estimator
from hasa_env.steering.arx import ARXForm
from hasa_env.steering.equation_error import speed_scale

PAPER = ARXForm(a=(1.47, -0.51), b=(-5.73, 17.32, -17.65, 6.12), c=(0.11,), d=(-0.02, 0.02))
RATIO = 15.0
HYPOTHESES = [0.0, -1.8]
COLOURED = {
    "steering_ratio": RATIO,
    "steering_residual_std": 5e-4,
    "steering_coloured_error_std": 1e-3,
    "steering_coloured_error_correlation": 0.6,
    "steering_coloured_error_speed": 15.0,
}


@pytest.fixture(scope="module")
def runs() -> list[pd.DataFrame]:
    return drive_arx(PAPER, runs=2, seed=5, bias_index=1, steering_ratio=RATIO)


def _filter(estimator, frame: pd.DataFrame, steps: int):  # noqa: ANN001, ANN202
    from estimators.base import ACCELERATION_KEYS, MEASUREMENT_KEYS

    z = frame[list(MEASUREMENT_KEYS)].to_numpy(dtype=np.float64)
    a = frame[list(ACCELERATION_KEYS)].to_numpy(dtype=np.float64)
    out = [estimator.reset(z[0], HYPOTHESES)]
    for k in range(1, steps):
        out.append(estimator.step(z[k], a[k]))
    return out


def test_the_state_enters_the_steering_and_the_memory():
    model = ARXStateSpace(PAPER, 0.01, 1, coloured_error_correlation=0.5)
    eps = model.coloured_error_index
    assert model.state_names[eps] == "coloured_error"
    assert model.n_states == ARXStateSpace(PAPER, 0.01, 1).n_states + 1
    x = np.zeros(model.n_states)
    x[0] = 20.0
    x[eps] = 1e-3
    plain = x.copy()
    plain[eps] = 0.0
    assert model.predicted_steering(x) - model.predicted_steering(plain) == pytest.approx(1e-3)
    moved = model.transition(x, np.zeros(2)) - model.transition(plain, np.zeros(2))
    assert moved[eps] == pytest.approx(0.5e-3)
    np.testing.assert_allclose(moved[model.memory_slice], model.feedback * 1e-3, atol=1e-15)
    jac = model.transition_jacobian(x)
    np.testing.assert_allclose(jac[:, eps], moved / 1e-3, atol=1e-12)
    assert model.measurement_jacobian(x)[2, eps] == 1.0


@pytest.mark.parametrize("rho", [-0.1, 1.0])
def test_a_correlation_outside_0_1_is_named(rho):
    with pytest.raises(ValueError, match="coloured_error_correlation"):
        ARXStateSpace(PAPER, 0.01, 1, coloured_error_correlation=rho)


def test_the_scale_follows_the_speed_squared_with_a_floor():
    np.testing.assert_allclose(speed_scale(np.array([15.0, 30.0, 1.0]), 15.0), [1.0, 0.25, 9.0])


def test_the_fast_filter_equals_filterpy(runs):
    frame = runs[0]
    fast = _filter(GaussianMixtureEKF(PAPER, **COLOURED), frame, 600)
    ref = _filter(FilterpyGMEKF(PAPER, **COLOURED), frame, 600)
    for a, b in zip(fast, ref, strict=True):
        np.testing.assert_allclose(a.weights, b.weights, rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.component_means, b.component_means, rtol=0, atol=1e-9)
        np.testing.assert_allclose(
            a.component_covariances, b.component_covariances, rtol=0, atol=1e-9
        )


def test_the_batched_filter_equals_one_run_at_a_time(runs):
    estimator = GaussianMixtureEKF(PAPER, **COLOURED)
    both = run_estimator(estimator, runs, hypotheses=HYPOTHESES)
    for i, frame in enumerate(runs):
        one = run_estimator(GaussianMixtureEKF(PAPER, **COLOURED), frame, hypotheses=HYPOTHESES)
        np.testing.assert_allclose(both.weights[i], one.weights[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(both.mean[i], one.mean[0], rtol=0, atol=1e-9)


def test_the_process_noise_grows_as_the_speed_falls():
    estimator = GaussianMixtureEKF(PAPER, **COLOURED)
    mats = estimator.matrices
    var = mats.coloured_error_process_var(np.array([15.0, 30.0]))
    assert var[0] == pytest.approx(1e-6 * (1 - 0.36))
    assert var[1] == pytest.approx(var[0] / 16)
