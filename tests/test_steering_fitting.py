"""Least squares with standard errors, BIC order search, diagnostics, identifiability, scores."""

import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from statsmodels.stats.diagnostic import acorr_ljungbox

from hasa_env.drivers import ModelDriver, run_driver
from hasa_env.steering import (
    ARXForm,
    GeneralizedModel,
    IdentifiabilityWarning,
    TwoPointModel,
    check_identifiability,
    ljung_box,
    residual_diagnostics,
    score,
    score_features,
    score_runs,
    select_order,
)
from hasa_env.steering.fitting import least_squares


def arx_data(arx: ARXForm, n: int, rng: np.random.Generator, noise: float = 1e-3) -> pd.DataFrame:
    """Open-loop data of an ARX model driven by random, coloured bearings."""

    def coloured(scale):
        return scale * np.convolve(rng.standard_normal(n + 4), np.ones(5) / np.sqrt(5), "valid")

    phi, omega, vy = coloured(0.02), coloured(0.01), coloured(0.1)
    delta = np.zeros(n)
    e = noise * rng.standard_normal(n)
    start = arx.memory_order
    for k in range(start, n):
        value = sum(c * delta[k - i] for i, c in enumerate(arx.a, start=1))
        for coefs, x in ((arx.b, phi), (arx.c, omega), (arx.d, vy)):
            value += sum(c * x[k - i] for i, c in enumerate(coefs))
        delta[k] = value + e[k]
    frame = pd.DataFrame({"delta": delta, "phi": phi, "omega": omega, "lateral_velocity": vy,
                          "speed": 15.0})  # fmt: skip
    frame.attrs = {"near_distance": 6.2, "far_distance": 20.0, "decision_lag": 1, "dt": arx.dt}
    return frame


@st.composite
def stable_arx(draw):
    na = draw(st.integers(0, 2))
    poles = [draw(st.floats(-0.9, 0.9)) for _ in range(na)]
    a = tuple(np.poly(poles)[1:] * -1.0) if na else ()
    nb, nc, nd = draw(st.integers(1, 4)), draw(st.integers(0, 2)), draw(st.integers(0, 2))
    coef = st.floats(-1.0, 1.0).filter(lambda x: abs(x) > 0.05)
    b = tuple(draw(coef) for _ in range(nb))
    c = tuple(draw(coef) for _ in range(nc))
    d = tuple(draw(coef) for _ in range(nd))
    return ARXForm(a=a, b=b, c=c, d=d)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(arx=stable_arx(), seed=st.integers(0, 2**32 - 1))
def test_fit_recovers_known_arx_coefficients_within_their_standard_errors(arx, seed):
    rng = np.random.default_rng(seed)
    runs = [arx_data(arx, 1500, rng), arx_data(arx, 1500, rng)]
    truth = GeneralizedModel.from_arx(arx)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)  # random gains may cancel
        fitted = GeneralizedModel(*truth.orders.values()).fit(runs)
    error = fitted.parameter_vector - truth.parameter_vector
    se = np.array(list(fitted.standard_errors.values()))
    assert np.all(np.abs(error) <= 4.0 * se), (error / se).round(2)
    assert np.all(se < 0.05), se  # informative, not vacuous
    result = fitted.fit_result
    assert result.n_obs == 2 * (1500 - truth.max_lag)
    assert result.residual_std == pytest.approx(1e-3, rel=0.1)
    assert set(result.summary().columns) == {"estimate", "std_error", "t"}


@settings(max_examples=20, deadline=None, derandomize=True)
@given(
    gains=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(0.5, 20)),
    seed=st.integers(0, 2**32 - 1),
)
def test_two_point_fit_recovers_its_gains(gains, seed):
    truth = TwoPointModel(*gains)
    frame = arx_data(truth.arx(), 3000, np.random.default_rng(seed))
    fitted = TwoPointModel().fit(frame)
    error = fitted.parameter_vector - truth.parameter_vector
    se = fitted._standard_errors
    assert np.all(np.abs(error) <= 4.0 * se), (error / se).round(2)


@pytest.mark.slow
def test_bic_selects_the_true_order_on_a_common_sample():
    arx = ARXForm(a=(1.1, -0.35), b=(0.6, -0.4, 0.25), c=(0.3,), d=(0.08, -0.06))
    rng = np.random.default_rng(7)
    runs = [arx_data(arx, 2500, rng), arx_data(arx, 2500, rng)]
    selection = select_order(runs, max_orders=(4, 5, 3, 3), min_orders=(0, 0, 0, 0))
    assert selection.orders == {"na": 2, "nb": 3, "nc": 1, "nd": 2}
    assert selection.criterion == "bic"
    # common sample: every candidate was fitted on the rows the largest model can use
    largest_lag = 5 - 1
    assert selection.n_common == 2 * (2500 - largest_lag)
    assert len(selection.table) == 5 * 6 * 4 * 4
    row = selection.table.query("na == 1 and nb == 2 and nc == 0 and nd == 0").iloc[0]
    stacked = [GeneralizedModel(4, 5, 3, 3).design(r) for r in runs]
    keep = [d.valid for d in stacked]
    X = np.vstack([d.matrix[v] for d, v in zip(stacked, keep, strict=True)])
    y = np.concatenate([d.target[v] for d, v in zip(stacked, keep, strict=True)])
    assert row["rss"] == pytest.approx(least_squares(X[:, [0, 4, 5]], y).rss, rel=1e-10)
    # the returned model has the selected orders, fitted on all the data
    assert selection.model.orders == selection.orders
    np.testing.assert_allclose(
        selection.model.parameter_vector, GeneralizedModel.from_arx(arx).parameter_vector, atol=0.02
    )
    with pytest.raises(ValueError, match="criterion"):
        select_order(runs, criterion="hqic")


def test_static_gain_decides_identifiability_not_any_nonzero_coefficient():
    # b non-zero, but its effect cancels at steady state: the paper's criterion says
    # "observable", the static gain says no
    cancelling = ARXForm(a=(0.5,), b=(0.3, -0.3))
    report = check_identifiability(cancelling)
    assert not report.identifiable and "not clearly non-zero" in report.message
    wrong_sign = check_identifiability(ARXForm(a=(0.5,), b=(-0.1,)))
    assert wrong_sign.identifiable and not wrong_sign.sign_consistent
    assert check_identifiability(GeneralizedModel.paper()).ok
    two_point = check_identifiability(TwoPointModel.paper())
    assert two_point.ok and two_point.memory_gain == 0.0
    assert two_point.static_lane_gain == pytest.approx(0.087 * 0.01 / 6.2)


def test_a_fit_that_loses_identifiability_warns():
    # the steering depends only on lateral velocity: no lane information
    arx = ARXForm(a=(0.8,), b=(0.0,), c=(), d=(0.2,))
    frame = arx_data(arx, 3000, np.random.default_rng(1))
    with pytest.warns(IdentifiabilityWarning, match="not clearly non-zero"):
        fitted = GeneralizedModel(1, 1, 1, 1).fit(frame)
    report = fitted.fit_result.identifiability
    assert not report.identifiable
    assert abs(report.static_lane_gain) < 3 * report.standard_error
    # with lane information the same fit does not warn
    informative = arx_data(ARXForm(a=(0.8,), b=(0.3,), d=(0.2,)), 3000, np.random.default_rng(1))
    with warnings.catch_warnings():
        warnings.simplefilter("error", IdentifiabilityWarning)
        fitted = GeneralizedModel(1, 1, 1, 1).fit(informative)
    report = fitted.fit_result.identifiability
    assert report.ok and not report.integrating
    expected_snr = abs(report.static_lane_gain) * 1.8 / fitted.fit_result.residual_std
    assert report.lane_snr == pytest.approx(expected_snr)
    assert report.steady_state_gain == pytest.approx(-report.static_lane_gain / (1 - 0.8), rel=0.05)


def test_residual_diagnostics_tell_white_from_coloured():
    rng = np.random.default_rng(0)
    white = rng.standard_normal(3000)
    coloured = np.convolve(rng.standard_normal(3003), np.ones(4), "valid")
    w = residual_diagnostics(white, lags=20)
    c = residual_diagnostics([coloured[:1500], coloured[1500:]], lags=20)
    assert w.white and w.ljung_box_p > 0.01 and w.fraction_outside < 0.2
    assert not c.white and c.ljung_box_p < 1e-10
    assert c.autocorrelation[0] == 1.0 and c.autocorrelation[1] == pytest.approx(0.75, abs=0.05)
    assert w.confidence_band == pytest.approx(1.96 / np.sqrt(3000))


def test_ljung_box_is_statsmodels_to_the_bit():
    """:func:`ljung_box` (lags 1..L only) gives statsmodels' ``acorr_ljungbox`` (every lag's
    autocovariance by ``np.correlate``) to the bit: white, random-walk and offset series of
    many lengths, levels and lag counts, up to more samples than a run has."""
    rng = np.random.default_rng(5011)
    for trial in range(300):
        n = int(rng.integers(10, 6000))
        lags = int(min(int(rng.integers(1, 40)), max(n // 5, 1)))
        series = rng.standard_normal(n) * 10 ** rng.uniform(-6, 2)
        if trial % 3 == 1:
            series = np.cumsum(series) * 1e-3
        elif trial % 3 == 2:
            series = series + 5.0
        theirs = acorr_ljungbox(series, lags=[lags], return_df=True)
        expected = (float(theirs["lb_stat"].iloc[0]), float(theirs["lb_pvalue"].iloc[0]))
        assert ljung_box(series, lags) == expected, (n, lags)


@pytest.fixture(scope="module")
def paper_driver_runs():
    """Three 30 s runs of the paper's generalized model driving at 15 m/s with noise."""
    driver = ModelDriver(GeneralizedModel.paper(), noise_std=5e-4)
    return run_driver(driver, runs=3, seed=11, options={"bias_index": 0})


def test_closed_loop_fit_of_a_model_driver_is_consistent(paper_driver_runs):
    # the applied steering is what the model produced (the measured one adds sensor noise);
    # least squares is consistent for an ARX driver even in closed loop
    truth = GeneralizedModel.paper()
    fitted = GeneralizedModel(steering_signal="applied").fit(paper_driver_runs, ridge=0)
    error = fitted.parameter_vector - truth.parameter_vector
    se = fitted._standard_errors
    assert np.all(np.abs(error) <= 3.0 * se), (error / se).round(2)
    # individual lags are collinear in closed loop at 100 Hz, but what the estimator
    # needs, the static lane-offset gain, is pinned down
    report = fitted.fit_result.identifiability
    assert report.ok
    true_gain = truth.arx().static_lane_gain
    assert abs(report.static_lane_gain - true_gain) <= 3.0 * report.standard_error
    assert report.standard_error < 0.2 * true_gain
    assert fitted.fit_result.residual_std == pytest.approx(5e-4, rel=0.05)
    # the default ridge fit trades the cancelling lag coefficients for a smaller norm at
    # no cost in prediction, and keeps the lane gain
    ridge = GeneralizedModel(steering_signal="applied").fit(paper_driver_runs)
    assert ridge.fit_result.checks.ridge_lambda > 0
    assert np.linalg.norm(ridge.parameter_vector) < np.linalg.norm(fitted.parameter_vector)
    assert ridge.fit_result.residual_std == pytest.approx(5e-4, rel=0.05)
    assert ridge.fit_result.identifiability.ok
    # at 15 m/s the bearings and v_y are nearly collinear: flagged (at other speeds the fit
    # would be an extrapolation), not hidden
    checks = ridge.fit_result.checks
    assert checks.stable and checks.flags == ("collinear_features",)
    assert checks.feature_collinearity["lateral_velocity"] < 1e-4


def test_scores_of_the_true_model_and_of_steer_as_before(paper_driver_runs):
    truth = score(GeneralizedModel.paper(steering_signal="applied"), paper_driver_runs)
    assert truth["n_runs"] == 3
    assert truth["rmse"] == pytest.approx(5e-4, rel=0.05)  # the noise it was driven with
    assert truth["r2"] > 0.9 and truth["ljung_box_p"] > 0.001
    assert 0 < truth["r2_increments"] < 1
    assert np.isfinite(truth["free_run_rmse"]) and truth["free_run_rmse"] > truth["rmse"]
    as_before = GeneralizedModel(1, 0, 0, 0, parameters=[1.0], steering_signal="applied")
    baseline = score(as_before, paper_driver_runs)
    assert baseline["r2_increments"] == pytest.approx(0.0, abs=0.01)
    assert baseline["rmse"] > truth["rmse"]
    per_run = score_runs(GeneralizedModel.paper(steering_signal="applied"), paper_driver_runs)
    assert len(per_run) == 3 and per_run["rmse"].mean() == pytest.approx(truth["rmse"])


def test_score_features_is_a_row_of_score_runs(paper_driver_runs):
    """:func:`score_features` of a run's features (with the one-step predictions given or
    not) holds :func:`score_runs`' row of that run, to the bit, with and without the free
    run; the benchmark scores each run with it."""
    model = GeneralizedModel.paper(steering_signal="applied")
    for free_run in (True, False):
        table = score_runs(model, paper_driver_runs, free_run=free_run)
        for i, run in enumerate(paper_driver_runs):
            features = model.features(run)
            given = score_features(
                model, features, free_run=free_run, one_step=model.predict_features(features)
            )
            for row in (score_features(model, features, free_run=free_run), given):
                assert list(row) == list(table.columns)
                expected = table.iloc[i].to_numpy(dtype=np.float64)
                np.testing.assert_array_equal(np.array(list(row.values()), float), expected)


def test_fit_needs_enough_varied_data():
    frame = arx_data(ARXForm(a=(0.5,), b=(0.3,)), 10, np.random.default_rng(0))
    with pytest.raises(ValueError, match="more samples"):
        GeneralizedModel(4, 5, 1, 1).fit(frame)
    flat = frame.assign(omega=0.0)
    with pytest.raises(ValueError, match="identically zero"):
        GeneralizedModel(1, 1, 1, 0).fit(flat)
    with pytest.raises(ValueError, match="no runs"):
        GeneralizedModel().fit([])


def test_aim_offsets_are_fitted_per_run_and_left_out_of_the_model():
    """A driver who holds the car off the lane centre steers toward that offset: in the ARX
    equation a constant per run. With ``aim_offset`` the fit takes one intercept per run
    and recovers the model's coefficients; without it they are biased."""
    arx = ARXForm(a=(0.6,), b=(0.5, -0.2), c=(0.3,), d=(0.1,))
    rng = np.random.default_rng(5)
    runs = []
    for constant in (0.02, -0.03):
        frame = arx_data(arx, 2000, rng)
        delta = frame["delta"].to_numpy().copy()
        for k in range(1, delta.size):  # the same ARX recursion with the run's constant
            delta[k] += 0.6 * (delta[k - 1] - frame["delta"].iloc[k - 1]) + constant
        frame["delta"] = delta
        runs.append(frame)
    truth = GeneralizedModel.from_arx(arx)
    model = GeneralizedModel(*truth.orders.values())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        with_offsets = model.fit(runs, aim_offset=True, ridge=0)
        without = model.fit(runs, ridge=0)
    se = np.array(list(with_offsets.standard_errors.values()))
    error = with_offsets.parameter_vector - truth.parameter_vector
    assert with_offsets.parameter_vector.size == truth.parameter_vector.size
    assert np.all(np.abs(error) <= 4.0 * se), (error / se).round(2)
    assert np.abs(without.parameter_vector - truth.parameter_vector).max() > 10 * se.max()
    assert with_offsets.fit_result.rss < without.fit_result.rss
