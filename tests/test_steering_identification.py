"""Identification that cannot fail silently: ridge with a cross-validated penalty, the
fit's checks (condition number, AR poles, stability, identifiability), warnings a user
can filter, and free runs that diverge reported as findings (docs/design.md §6.5)."""

import json
import math
import warnings

import numpy as np
import pytest

from hasa_env.drivers import ModelDriver, SpeedProfile, SyntheticDriver, TwoPointParams, run_driver
from hasa_env.steering import (
    ARXForm,
    GeneralizedModel,
    IdentifiabilityWarning,
    StabilityWarning,
    SteeringFitWarning,
    TwoPointModel,
    ar_poles,
    score,
)
from hasa_env.steering.fitting import choose_ridge_lambda, design_blocks, ridge_regression


@pytest.fixture(scope="module")
def constant_speed_run():
    """A closed-loop run at a constant 15 m/s: the collinear case of docs/design.md §6.5."""
    driver = SyntheticDriver(
        TwoPointParams.from_loop(1.0, 0.7, 0.3, noise_std=8e-4, speed=SpeedProfile.hold())
    )
    return run_driver(driver, runs=1, seed=3, options={"bias_index": 0})[0]


def test_a_constant_speed_run_is_ill_conditioned_for_least_squares(constant_speed_run):
    model = GeneralizedModel(steering_signal="applied")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SteeringFitWarning)
        plain = model.fit(constant_speed_run, ridge=0)
    checks = plain.fit_result.checks
    assert checks.ridge_lambda == 0.0
    assert checks.condition_number > 1e6 and "ill_conditioned" in checks.flags
    assert not checks.ok


def test_a_constant_speed_run_flags_collinear_features_and_a_ramp_does_not(constant_speed_run):
    model = GeneralizedModel(steering_signal="applied")
    with pytest.warns(IdentifiabilityWarning, match="do not tell .*lateral_velocity"):
        held = model.fit(constant_speed_run)
    checks = held.fit_result.checks
    assert "collinear_features" in checks.flags
    assert checks.feature_collinearity["lateral_velocity"] < 1e-4
    assert set(checks.feature_collinearity) == {"delta", "phi", "omega", "lateral_velocity"}
    ramp = SpeedProfile(target_speed=40.0, ramp_rate=2.0, start_time=2.0)
    driver = SyntheticDriver(TwoPointParams.from_loop(1.0, 0.7, 0.3, noise_std=8e-4, speed=ramp))
    run = run_driver(driver, runs=1, seed=3, options={"bias_index": 0})[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SteeringFitWarning)
        ramped = model.fit(run).fit_result.checks
    assert "collinear_features" not in ramped.flags
    assert min(ramped.feature_collinearity.values()) > 1e-3


def test_a_constant_speed_run_gives_a_stable_regularized_fit(constant_speed_run):
    model = GeneralizedModel(steering_signal="applied")
    with warnings.catch_warnings():
        warnings.simplefilter("error", StabilityWarning)  # the default fit must not warn
        fitted = model.fit(constant_speed_run)
    checks = fitted.fit_result.checks
    assert checks.ridge_lambda > 0 and checks.ridge_lambda >= checks.cross_validated_lambda
    assert checks.stable and checks.ar_poles_max_abs <= 1.0
    assert "ill_conditioned" not in checks.flags  # regularized: the conditioning is handled
    poles = ar_poles(fitted.arx())
    assert np.max(np.abs(poles)) == pytest.approx(checks.ar_poles_max_abs)
    document = json.loads(json.dumps(checks.to_dict()))
    assert {
        "condition_number",
        "ar_poles_max_abs",
        "stable",
        "identifiable",
        "ridge_lambda",
    } <= set(document)


def test_the_penalty_comes_from_the_training_data_alone(constant_speed_run):
    model = GeneralizedModel(steering_signal="applied")
    fitted = model.fit(constant_speed_run, stable=False)
    cv = fitted.fit_result.cross_validation
    blocks = design_blocks(model, [constant_speed_run], None)
    again = choose_ridge_lambda([(b["matrix"], b["target"]) for b in blocks], gap=model.max_lag)
    assert cv.ridge_lambda == again.ridge_lambda == fitted.fit_result.checks.ridge_lambda
    assert cv.folds == 5 and len(cv.table()) == len(cv.lambdas)
    assert cv.mean_error[cv.chosen] == np.min(cv.mean_error)
    # the chosen penalty is the training data's: a different training run chooses again
    other = run_driver(
        SyntheticDriver(TwoPointParams.from_loop(1.1, 0.6, 0.3, noise_std=2e-3)),
        runs=1,
        seed=8,
    )[0]
    refit = model.fit(other, stable=False)
    assert refit.fit_result.cross_validation.mean_error.shape == cv.mean_error.shape
    assert not np.array_equal(refit.fit_result.cross_validation.mean_error, cv.mean_error)


def test_ridge_resolves_an_exactly_collinear_pair_the_minimum_norm_way():
    rng = np.random.default_rng(0)
    x = rng.standard_normal(500)
    X = np.column_stack([x, x, rng.standard_normal(500)])  # columns 0 and 1 identical
    y = 2.0 * x + 0.5 * X[:, 2] + 0.01 * rng.standard_normal(500)
    with pytest.raises(ValueError, match="linearly dependent"):
        ridge_regression(X, y, 0.0, ["x1", "x2", "z"])
    solution = ridge_regression(X, y, 1e-6)
    np.testing.assert_allclose(solution.parameters, [1.0, 1.0, 0.5], atol=0.01)
    assert solution.effective_parameters == pytest.approx(2.0, abs=0.01)


def test_an_unstable_fit_is_flagged_and_warns_with_a_filterable_category():
    # open-loop data of an unstable AR model
    arx = ARXForm(a=(1.02,), b=(0.2,))
    rng = np.random.default_rng(1)
    n = 400
    phi = 0.01 * rng.standard_normal(n)
    delta = np.zeros(n)
    for k in range(1, n):
        delta[k] = 1.02 * delta[k - 1] + 0.2 * phi[k] + 1e-4 * rng.standard_normal()
    import pandas as pd

    frame = pd.DataFrame(
        {"delta": delta, "phi": phi, "omega": 0.0, "lateral_velocity": 0.0, "speed": 15.0}
    )
    frame.attrs = {"near_distance": 6.2, "far_distance": 20.0, "decision_lag": 1, "dt": arx.dt}
    with pytest.warns(StabilityWarning, match="outside the unit circle"):
        fitted = GeneralizedModel(1, 1, 0, 0).fit(frame, stable=False)
    assert issubclass(StabilityWarning, SteeringFitWarning)
    checks = fitted.fit_result.checks
    assert checks.stable is False and "unstable" in checks.flags
    assert checks.ar_poles_max_abs > 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", category=SteeringFitWarning)
        GeneralizedModel(1, 1, 0, 0).fit(frame, stable=False)  # filtered: no error
    # by default the penalty is raised until the AR part is stable, and the checks say so
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SteeringFitWarning)
        stabilized = GeneralizedModel(1, 1, 0, 0).fit(frame).fit_result.checks
    assert stabilized.stable and stabilized.ridge_lambda > stabilized.cross_validated_lambda


def test_a_diverging_free_run_is_a_finding_not_an_infinite_mean():
    runs = run_driver(ModelDriver(GeneralizedModel.paper(), noise_std=5e-4), runs=2, seed=4)
    unstable = GeneralizedModel.from_coefficients(
        (1.2, 0.1), (-5.73, 17.32, -17.65, 6.12), (0.11,), (-0.02, 0.02)
    )
    result = score(unstable, runs)
    assert result["free_run_diverged"] == 2
    assert math.isnan(result["free_run_rmse"])
    assert math.isfinite(result["rmse"])  # one-step prediction still has a score
    stable = score(GeneralizedModel.paper(), runs)
    assert stable["free_run_diverged"] == 0 and math.isfinite(stable["free_run_rmse"])


def test_two_point_fits_are_integrating_and_count_as_stable(constant_speed_run):
    fitted = TwoPointModel().fit(constant_speed_run)
    checks = fitted.fit_result.checks
    assert checks.ar_poles_max_abs == pytest.approx(1.0)
    assert checks.stable
