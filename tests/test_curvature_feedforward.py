"""A model fitted on straight roads, given the steering a bend needs beyond what its bearings
explain (``FilterSettings.steering_curvature_feedforward``, ``estimators.trust.
curvature_feedforward``; docs/design.md §8.28), instead of being switched off on bends."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from benchmarks.protocol.config import ProtocolConfig
from benchmarks.protocol.plan import load_frames, make_plan
from estimators import FilterSettings, GaussianMixtureEKF
from estimators.arx_state_space import road_curvature_ahead
from estimators.filterpy_ekf import FilterpyGMEKF
from estimators.offline import run_estimator
from estimators.settings import STRAIGHT_CURVATURE
from estimators.trust import (
    FEEDFORWARD_PRECISION,
    TrainingRecord,
    curvature_feedforward,
    curvature_feedforward_error,
    trusted_filter,
)
from estimators.tuning import steering_residual_std
from hasa_env.steering.arx import ARXForm
from hasa_env.steering.models import GeneralizedModel


def test_the_feedforward_is_the_kinematic_steering_less_what_the_bearings_explain() -> None:
    arx = ARXForm(a=(0.3, 0.2), b=(0.1,), c=(0.2,), d=(), near_distance=5.0, far_distance=20.0)
    # steady state centred on a bend: phi = kappa 5 / 2, Omega = kappa 20 / 2, delta = L kappa
    expected = 2.8 - (0.1 * 5.0 + 0.2 * 20.0) / (2.0 * 0.5)
    assert curvature_feedforward(arx, 2.8) == pytest.approx(expected)
    assert curvature_feedforward(arx, 2.8, steering_ratio=15.0) == pytest.approx(
        expected + 14 * 2.8
    )
    unstable = ARXForm(a=(1.0,), b=(0.1,), c=(), d=(), near_distance=5.0, far_distance=20.0)
    assert math.isnan(curvature_feedforward(unstable, 2.8))


def test_the_curvature_is_read_exactly_from_the_road_points_of_a_circle() -> None:
    kappa, near = np.array([0.005, -0.002, 0.0008]), 6.2
    points = np.column_stack([np.sin(kappa * near) / kappa, (1 - np.cos(kappa * near)) / kappa,
                              np.full(3, 20.0), np.zeros(3)])  # fmt: skip
    np.testing.assert_allclose(road_curvature_ahead(points, 3), kappa, rtol=1e-6, atol=1e-12)
    np.testing.assert_array_equal(road_curvature_ahead(None, 2), np.zeros(2))


@pytest.fixture(scope="module")
def bends():
    """The generalized model fitted as the benchmark fits it (seed 5131: "Ill" and 8 training
    drivers, 30 s straight runs each; its G pinned down), the same runs fitted with BIC's
    orders (4, 6, 3, 3; G not pinned down), and 3 drivers' runs on the curved track."""
    plan = make_plan(ProtocolConfig(seeds=(5131,), drivers=3, runs=1, ill_runs=1), 5131)
    env = plan.training_env_config or plan.env_config
    train = load_frames(plan.trainings(), "straight", env, plan.params)
    extra = {p.name: p for p in plan.training_drivers}
    train += load_frames(plan.driver_trainings(), "straight", env, extra)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = GeneralizedModel().fit(train)
        loose = GeneralizedModel(4, 6, 3, 3).fit(train)
    curved_plan = make_plan(ProtocolConfig(seeds=(5131,), drivers=3, runs=1, ill_runs=1,
                                           duration=30.0, track="curved"), 5131)  # fmt: skip
    curved = load_frames(curved_plan.main, "curved", curved_plan.env_config, curved_plan.params)
    residual = steering_residual_std(model.arx(), train, decision_lag=model.decision_lag)
    record = TrainingRecord(residual_std=residual, curvature=0.0)
    return model, record, curved, loose


def test_the_standard_error_of_g_is_the_delta_method_on_the_fits_covariance(bends):
    model = bends[0]
    result = model.fit_result
    params = np.asarray(result.parameters, dtype=np.float64)

    def g_of(values: np.ndarray) -> float:
        return curvature_feedforward(model.with_parameters(values).arx(), 2.8)

    step = 1e-7
    gradient = np.array([(g_of(params + step * e) - g_of(params - step * e)) / (2 * step)
                         for e in np.eye(params.size)])  # fmt: skip
    expected = math.sqrt(gradient @ np.asarray(result.covariance) @ gradient)
    assert curvature_feedforward_error(model) == pytest.approx(expected, rel=1e-4)
    assert math.isnan(curvature_feedforward_error(GeneralizedModel.paper()))  # no fit record


def test_the_rule_gives_it_to_straight_road_fits_that_pin_it_down(bends):
    model, record, _, loose = bends
    gain = curvature_feedforward(model.arx(), 2.8)
    assert curvature_feedforward_error(model) <= FEEDFORWARD_PRECISION * abs(gain)
    straight = trusted_filter(model, FilterSettings(), training=record)
    assert straight.settings.steering_curvature_feedforward == pytest.approx(gain)
    assert math.isinf(straight.settings.steering_curvature_limit)
    assert any(r.startswith("on bends, the steering less the bend's steady steering G kappa: "
                            f"G = {gain:.3g} (standard error ") for r in straight.reasons)  # fmt: skip
    loose_reasons = trusted_filter(loose, FilterSettings(), training=record).reasons
    assert any(r.startswith("no curvature feed-forward: its fit does not pin G down")
               for r in loose_reasons)  # fmt: skip
    no_record = GeneralizedModel.from_arx(model.arx())  # fitted elsewhere, roads unknown
    no_record.training_curvature = None
    for other, training, limit in [
        (loose, record, STRAIGHT_CURVATURE),  # G not pinned down by its fit
        (GeneralizedModel.paper(), record, STRAIGHT_CURVATURE),  # a preset: no fit record
        (no_record, TrainingRecord(curvature=0.004), 0.004 + STRAIGHT_CURVATURE),  # bends
    ]:
        settings = trusted_filter(other, FilterSettings(), training=training).settings
        assert settings.steering_curvature_feedforward == 0.0
        assert settings.steering_curvature_limit == pytest.approx(limit)
    refused = trusted_filter(
        model, FilterSettings(), training=record, overrides={"steering_curvature_feedforward": 0}
    )
    assert refused.settings.steering_curvature_limit == pytest.approx(STRAIGHT_CURVATURE)
    noise = {"speed": 0.1, "camera": 0.1, "imu": 0.1, "steering": 1e-4}
    config = {"noise": noise, "vehicle": {"wheelbase": 3.1}}
    assert FilterSettings.from_env_config(config).wheelbase == 3.1


def test_the_fast_filter_equals_filterpy_with_the_feedforward(bends):
    model, record, curved, _ = bends
    first = int(np.argmax(np.abs(curved[0]["road_curvature"].to_numpy()) > 1e-3))
    frame = curved[0].iloc[first - 100 : first + 500]
    trusted = trusted_filter(
        model, FilterSettings.from_env_config(frame.attrs["config"]), training=record
    )
    assert trusted.settings.steering_curvature_feedforward != 0
    settings, arx = trusted.settings, trusted.arx
    fast = run_estimator(GaussianMixtureEKF(arx, settings), frame, store_components=True)
    ref = run_estimator(FilterpyGMEKF(arx, settings), frame, store_components=True)
    assert np.abs(frame["road_curvature"]).max() > 1e-3  # it runs on a bend
    np.testing.assert_allclose(fast.component_means, ref.component_means, rtol=0, atol=1e-8)
    np.testing.assert_allclose(fast.weights, ref.weights, rtol=0, atol=1e-9)


def _final_true_weight(result) -> np.ndarray:
    """(R,) the weight of the true lane at each run's last step."""
    last = result.weights[np.arange(result.num_runs), result.lengths - 1]  # (R, C)
    return (last * result.true_lane_mask()).sum(axis=1)


def test_with_it_the_steering_counts_on_bends_and_finds_the_lane_there(bends):
    """Runs cut to start at their first bend: with the curvature rule the steering is off
    there and the mixture stays at the prior (0.9 m off); with the feed-forward it counts and
    the lane is found on the bend."""
    model, record, curved, _ = bends
    cut = []
    for frame in curved:
        first = int(np.argmax(np.abs(frame["road_curvature"].to_numpy()) > 1e-3))
        cut.append(frame.iloc[first:].reset_index(drop=True))
    base = FilterSettings.from_env_config(curved[0].attrs["config"])
    results = {}
    for name, overrides in {
        "feedforward": {},
        "curvature rule": {"steering_curvature_feedforward": 0.0},
    }.items():
        est = trusted_filter(model, base, training=record, overrides=overrides).estimator()
        results[name] = run_estimator(est, cut)
    ff, rule = results["feedforward"], results["curvature rule"]
    assert not ff.low_speed[ff.valid].any() and rule.low_speed[rule.valid].mean() > 0.3
    assert np.all(_final_true_weight(ff) > 0.95)
    assert np.all(ff.lateral_rmse() < 0.2) and np.all(rule.lateral_rmse() > 0.5)


def test_the_benchmark_reports_how_each_model_is_used_on_bends(bends):
    from benchmarks.protocol.models import FittedModel, describe_trust
    from benchmarks.report_sections import _bends_cell

    model, record, _, loose = bends
    refused = TrainingRecord(residual_std=record.residual_std, curvature=0.0, keeps_lane=False)
    fitted = [
        FittedModel("pinned", "builtin", model, record.residual_std, record),
        FittedModel("loose", "builtin", loose, record.residual_std, record),
        FittedModel("refused", "builtin", model, record.residual_std, refused),
    ]
    infos = [{"name": f.name} for f in fitted]
    describe_trust(fitted, infos, {})
    pinned, not_pinned, off = infos
    gain = curvature_feedforward(model.arx(), 2.8)
    assert pinned["steering_curvature_feedforward"] == pytest.approx(gain)
    assert pinned["steering_curvature_limit"] is None  # lifted by the feed-forward
    assert not_pinned["steering_curvature_feedforward"] == 0.0
    assert not_pinned["steering_curvature_limit"] == pytest.approx(STRAIGHT_CURVATURE)
    assert off["steering_curvature_feedforward"] is None  # its steering is not used at all
    cells = [
        _bends_cell((i["steering_curvature_feedforward"], i.get("steering_curvature_limit")))
        for i in infos
    ]
    assert cells == [f"feed-forward G {gain:.3g}", "off above 0.0002 1/m", "-"]
    assert _bends_cell((0.0, None)) == "counts"


def test_a_model_that_does_not_name_its_parameters_keeps_the_curvature_rule(bends):
    """A duck-typed user model (``arx()`` and a fit record, no regressors) or a fit record whose
    covariance does not match its parameters: G's precision is unknown, no feed-forward."""
    from types import SimpleNamespace

    model, record, _, _ = bends
    duck = SimpleNamespace(arx=model.arx, fit_result=model.fit_result, decision_lag=1)
    assert math.isnan(curvature_feedforward_error(duck))
    wrong = GeneralizedModel.from_arx(model.arx())
    wrong.fit_result = SimpleNamespace(parameter_names=("a1", "b1"), covariance=np.eye(3))
    assert math.isnan(curvature_feedforward_error(wrong))
    settings = trusted_filter(duck, FilterSettings(), training=record).settings
    assert settings.steering_curvature_feedforward == 0.0
    assert settings.steering_curvature_limit == pytest.approx(STRAIGHT_CURVATURE)


def test_a_saved_fit_keeps_its_covariance_and_so_its_feedforward(bends, tmp_path):
    """A model file keeps the fit's covariance: the model loaded from it gets the same G and
    the same standard error as the model that was fitted (hasa-replay --model file.json)."""
    from hasa_env.steering.base import SteeringModel

    model, record, _, loose = bends
    given = []
    for fitted in (model, loose):
        path = tmp_path / f"{fitted.name}-{len(fitted.parameter_names)}.json"
        fitted.save(path)
        loaded = SteeringModel.load(path)
        assert loaded.fit_result is None and loaded.training_curvature == 0.0
        error = curvature_feedforward_error(loaded)
        assert error == pytest.approx(curvature_feedforward_error(fitted), rel=1e-12)
        training = TrainingRecord(residual_std=record.residual_std)  # the file's own roads
        settings = trusted_filter(loaded, FilterSettings(), training=training).settings
        given.append(settings.steering_curvature_feedforward)
    assert given[0] == pytest.approx(curvature_feedforward(model.arx(), 2.8))  # pinned down
    assert given[1] == 0.0  # BIC's orders: not pinned down, as when fitted
