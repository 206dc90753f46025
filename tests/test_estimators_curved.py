"""Curved roads: the road geometry as a known input of the estimator.

Bearings from the lane-centre points ahead (:mod:`estimators.road_geometry`),
the model's exact Jacobians with them, the fast filter against filterpy, the
offline runner and the wrappers on the curved track, and the straight-road
results unchanged.
"""

from __future__ import annotations

import math
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hasa_env  # noqa: F401  (registers the env ids)
from estimators._testing import drive_arx
from estimators.arx_state_space import ARXStateSpace
from estimators.filterpy_ekf import FilterpyGMEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.offline import run_estimator
from estimators.road_geometry import (
    lane_centre_bearing_error,
    lane_points_ahead,
    road_point_bearings,
    straight_road_points,
)
from estimators.settings import FilterSettings
from estimators.wrappers import EstimatorInfoWrapper
from hasa_env.drivers import ModelDriver, population, run_driver, run_population
from hasa_env.sim.road import curved_road, lane_centre_bearing, straight_road
from hasa_env.sim.setup import RECORDING_COLUMNS, recording_row
from hasa_env.steering import GeneralizedModel
from hasa_env.steering.arx import ARXForm

CURVED = "hasa_env/LaneKeepingCurved-v0"
PAPER = ARXForm(a=(1.47, -0.51), b=(-5.73, 17.32, -17.65, 6.12), c=(0.11,), d=(-0.02, 0.02))
ROAD = curved_road()


# --------------------------------------------------------------------- road points
def test_lane_points_ahead_on_a_straight_road():
    points = lane_points_ahead(straight_road(), np.array([0.0, 250.0, 4990.0, 6000.0]), 6.2, 20.0)
    assert points.shape == (4, 4)
    np.testing.assert_allclose(points, np.tile(straight_road_points(6.2, 20.0), (4, 1)), atol=1e-9)
    assert lane_points_ahead(straight_road(), 10.0, 6.2, 20.0).shape == (4,)
    with pytest.raises(ValueError, match="positive"):
        lane_points_ahead(ROAD, 0.0, 0.0, 20.0)
    with pytest.raises(ValueError, match="finite"):
        lane_points_ahead(ROAD, np.nan, 6.2, 20.0)


def test_bearings_from_road_points_are_the_exact_lane_centre_bearings():
    rng = np.random.default_rng(0)
    s = rng.uniform(0.0, 3200.0, 2000)  # through every bend, and beyond the table
    y = rng.uniform(-1.5, 1.5, s.size)
    theta = rng.uniform(-0.1, 0.1, s.size)
    phi, omega = road_point_bearings(lane_points_ahead(ROAD, s, 6.2, 20.0), y, theta)
    np.testing.assert_allclose(phi, lane_centre_bearing(ROAD, s, y, theta, 6.2), atol=1e-12)
    np.testing.assert_allclose(omega, lane_centre_bearing(ROAD, s, y, theta, 20.0), atol=1e-12)
    # the straight-road formula is badly off in the bends (the geometry matters)
    assert np.max(np.abs(phi + theta + np.arctan(y / 6.2))) > 0.02


def test_the_other_lanes_approximation_is_as_documented():
    """Hypotheses 1.8 m to either side: bearing error under 2.5 mrad (near) and 0.8 mrad
    (far) for |y| <= 1 m on the curved track (the module docstring's numbers)."""
    s = np.linspace(0.0, 3000.0, 6001)
    for lane in (1.8, -1.8):
        for y in (-1.0, 0.0, 1.0):
            near, far = lane_centre_bearing_error(ROAD, s, y, 0.0, 6.2, 20.0, lane)
            assert np.abs(near).max() < 2.5e-3 and np.abs(far).max() < 0.8e-3
            if y == 0.0:
                assert np.abs(near).max() < 1e-4 and np.abs(far).max() < 1e-4
    exact = lane_centre_bearing_error(ROAD, s, 0.7, 0.02, 6.2, 20.0, 0.0)
    assert np.abs(exact[0]).max() < 1e-12 and np.abs(exact[1]).max() < 1e-12


# ----------------------------------------------------------------- model with points
points_strategy = st.tuples(
    st.floats(4.0, 10.0), st.floats(-1.0, 1.0), st.floats(12.0, 30.0), st.floats(-4.0, 4.0)
)


@given(
    points=points_strategy,
    seed=st.integers(0, 2**31 - 1),
    lag=st.integers(0, 1),
    offset=st.booleans(),
)
@settings(max_examples=40, deadline=None)
def test_jacobians_with_road_points_match_finite_differences(points, seed, lag, offset):
    model = ARXStateSpace(PAPER, decision_lag=lag, preferred_offset=offset)
    rng = np.random.default_rng(seed)
    x = rng.normal(size=model.n_states) * 0.3
    x[:3] = rng.uniform(5.0, 40.0), rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0)
    p = np.array(points)
    acc = rng.normal(size=2)

    def numeric(f):  # noqa: ANN001, ANN202
        cols = []
        for j in range(x.size):
            step = 1e-6 * max(1.0, abs(x[j]))
            hi, lo = x.copy(), x.copy()
            hi[j] += step
            lo[j] -= step
            cols.append((f(hi) - f(lo)) / (2 * step))
        return np.stack(cols, axis=-1)

    jac = model.transition_jacobian(x, p)
    np.testing.assert_allclose(
        jac, numeric(lambda s: model.transition(s, acc, p)), rtol=1e-5, atol=1e-6
    )
    hjac = model.measurement_jacobian(x, p)
    np.testing.assert_allclose(
        hjac, numeric(lambda s: model.measurement(s, p)), rtol=1e-5, atol=1e-6
    )
    # d phi / d y = -dx_near / (dx_near^2 + (dy_near - y)^2), y read as y - p with the offset
    _, du = model.bearings(x, True, p)
    aim = x[1] - (x[4] if offset else 0.0)
    assert du[0, 1] == pytest.approx(-p[0] / (p[0] ** 2 + (p[1] - aim) ** 2), rel=1e-12)


def test_straight_road_points_reproduce_the_straight_formula():
    model = ARXStateSpace(PAPER, decision_lag=1)
    rng = np.random.default_rng(1)
    x = rng.normal(size=(50, model.n_states))
    x[:, 0] = rng.uniform(5.0, 40.0, 50)
    straight = straight_road_points(6.2, 20.0)
    np.testing.assert_allclose(
        model.bearings(x, road_points=straight), model.bearings(x), atol=1e-15
    )
    np.testing.assert_allclose(
        model.transition_jacobian(x, straight), model.transition_jacobian(x), atol=1e-13
    )
    with pytest.raises(ValueError, match="dx_near > 0"):
        model.bearings(x, road_points=np.array([0.0, 0.0, 20.0, 0.0]))
    with pytest.raises(ValueError, match="last axis of 4"):
        model.bearings(x, road_points=np.zeros(3))


# ------------------------------------------------------------------------ filters
@pytest.fixture(scope="module")
def curved_runs() -> dict[int, list[pd.DataFrame]]:
    """Four 30 s runs per true lane of the paper model driving the curved track
    (steering ratio 15, equation noise 1e-3 rad in model units)."""
    driver = ModelDriver(GeneralizedModel.paper(), noise_std=1e-3, steering_ratio=15.0)
    return {
        b: run_driver(driver, CURVED, runs=4, seed=0, options={"bias_index": b}) for b in (0, 1)
    }


def make_ekf(**kw) -> GaussianMixtureEKF:
    return GaussianMixtureEKF(PAPER, steering_ratio=15.0, steering_residual_std=1e-3, **kw)


def test_the_road_geometry_makes_the_curved_track_work(curved_runs):
    """Measured: lateral RMSE 0.025 m with the geometry, 0.144 m with the straight formula."""
    for bias_index, frames in curved_runs.items():
        assert frames[0].attrs["track"] == "curved"
        with_geometry = run_estimator(make_ekf(), frames)
        straight = run_estimator(make_ekf(), frames, road_geometry=False)
        assert with_geometry.picked_true_lane().all(), bias_index
        # (0.996-0.9997: the aim cap holds the log-odds to what where the car is held allows)
        assert np.all(with_geometry.true_lane_weight()[:, 20:] > 0.99), bias_index
        assert np.all(with_geometry.lateral_rmse() < 0.04), bias_index
        assert np.all(straight.lateral_rmse() > 3 * with_geometry.lateral_rmse()), bias_index
        # the same recordings with their road given explicitly
        explicit = run_estimator(make_ekf(), [f.copy() for f in frames], roads=ROAD)
        np.testing.assert_array_equal(explicit.mean, with_geometry.mean)


@pytest.mark.slow
def test_synthetic_population_on_the_curved_track():
    """Synthetic drivers (not the model) with the paper's generalized model, ratio 15:
    mean lateral RMSE 0.060 m with the geometry, 0.075 m without; every lane picked."""
    runs = run_population(
        population("paper-pi", seed=0), runs=1, seed=0, env_id=CURVED, options={"bias_index": 1}
    )
    frames = [f for fs in runs.values() for f in fs]
    arx = GeneralizedModel.paper().arx()
    with_geometry = run_estimator(GaussianMixtureEKF(arx, steering_ratio=15.0), frames)
    straight = run_estimator(
        GaussianMixtureEKF(arx, steering_ratio=15.0), frames, road_geometry=False
    )
    assert with_geometry.picked_true_lane().all()
    assert with_geometry.lateral_rmse().mean() < 0.9 * straight.lateral_rmse().mean()
    # the straight formula leaves the steering unexplained far more often in the bends
    assert with_geometry.gated[..., 2].sum() < 0.5 * straight.gated[..., 2].sum()


@pytest.mark.parametrize(("offset_std", "aim_std"), [(0.0, 0.0), (0.3, 0.0), (0.0, 0.3)])
def test_fast_filter_equals_filterpy_on_the_curved_track(curved_runs, offset_std, aim_std):
    frame = curved_runs[1][0].iloc[:600].copy()
    frame.loc[100:150, "sensor_camera_lateral"] = np.nan
    frame.loc[300, "sensor_steering"] += 0.2
    settings = FilterSettings(
        steering_ratio=15.0,
        steering_residual_std=1e-3,
        preferred_offset_std=offset_std,
        preferred_offset_drift_std=1e-3,
        aim_offset_std=aim_std,
    )
    fast = run_estimator(GaussianMixtureEKF(PAPER, settings), frame, store_components=True)
    ref = run_estimator(FilterpyGMEKF(PAPER, settings), frame, store_components=True)
    np.testing.assert_allclose(fast.component_means, ref.component_means, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.weights, ref.weights, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fast.gated, ref.gated)


def test_batched_curved_runs_equal_single_runs_and_subsets(curved_runs):
    frames = curved_runs[0][:2] + curved_runs[1][:1]
    batch = run_estimator(make_ekf(), frames)
    for r, frame in enumerate(frames):
        alone = run_estimator(make_ekf(), frame)
        np.testing.assert_allclose(batch.mean[r], alone.mean[0], rtol=1e-12, atol=1e-12)
    # stepping a subset with its own road points
    ekf = make_ekf()
    z = np.stack(
        [f[["sensor_speed", "sensor_camera_lateral", "sensor_steering"]].to_numpy() for f in frames]
    )
    a = np.stack([f[["sensor_imu_longitudinal", "sensor_imu_lateral"]].to_numpy() for f in frames])
    pts = np.stack([lane_points_ahead(ROAD, f["station"].to_numpy(), 6.2, 20.0) for f in frames])
    ekf.reset(z[:, 0], [0.0, -1.8], road_points=pts[:, 0])
    for k in range(1, 200):
        ekf.step(z[[0, 2], k], a[[0, 2], k], runs=np.array([0, 2]), road_points=pts[[0, 2], k])
        est = ekf.step(z[[1], k], a[[1], k], runs=np.array([1]), road_points=pts[1, k])
    np.testing.assert_allclose(est.mean, batch.mean[:, 199], rtol=1e-12, atol=1e-12)


@pytest.mark.slow
def test_straight_roads_are_unchanged():
    """On the straight track the filter gets no road points; explicit straight points
    (the generalized formula) give the same estimates within 1e-12."""
    frames = drive_arx(PAPER, runs=2, seed=5, bias_index=1)
    for f in frames:
        f.attrs = {"track": "straight"}
    auto = run_estimator(make_ekf(), frames)
    none = run_estimator(make_ekf(), frames, road_geometry=False)
    np.testing.assert_array_equal(auto.mean, none.mean)
    np.testing.assert_array_equal(auto.std, none.std)
    ekf = make_ekf()
    z = np.stack(
        [f[["sensor_speed", "sensor_camera_lateral", "sensor_steering"]].to_numpy() for f in frames]
    )
    a = np.stack([f[["sensor_imu_longitudinal", "sensor_imu_lateral"]].to_numpy() for f in frames])
    straight = straight_road_points(6.2, 20.0)
    est = ekf.reset(z[:, 0], [0.0, -1.8], road_points=straight)
    for k in range(1, z.shape[1]):
        est = ekf.step(z[:, k], a[:, k], road_points=straight)
        np.testing.assert_allclose(est.mean, auto.mean[:, k], rtol=0, atol=1e-12)


def test_run_estimator_needs_station_and_warns_without_a_track(curved_runs):
    frame = curved_runs[0][0]
    with pytest.raises(ValueError, match="station"):
        run_estimator(make_ekf(), frame.drop(columns=["station"]))
    bare = frame.copy()
    bare.attrs = {}
    with pytest.warns(UserWarning, match="names no track"):
        res = run_estimator(make_ekf(), bare)
    np.testing.assert_array_equal(
        res.mean, run_estimator(make_ekf(), frame, road_geometry=False).mean
    )
    with pytest.raises(ValueError, match="2 roads for 1 recordings"):
        run_estimator(make_ekf(), frame, roads=[ROAD, ROAD])


def test_wrappers_give_the_estimator_the_road_ahead():
    config = {"action": {"type": "physical"}, "time_limit": 4.0}
    driver = ModelDriver(GeneralizedModel.paper(), noise_std=1e-3, steering_ratio=15.0)
    env = EstimatorInfoWrapper(gym.make(CURVED, config=config), make_ekf())
    _, info = env.reset(seed=2, options={"bias_index": 1})
    driver.reset(0, dt=0.01)
    road = env.unwrapped.setup.road
    rows, estimates = [recording_row(0, info, 0.0, False, False)], [info["estimate_lateral_offset"]]
    step = 0
    while True:
        action = np.array(driver.act(info, road))
        _, reward, terminated, truncated, info = env.step(action)
        step += 1
        rows.append(recording_row(step, info, reward, terminated, truncated))
        estimates.append(info["estimate_lateral_offset"])
        if terminated or truncated:
            break
    frame = pd.DataFrame(rows, columns=list(RECORDING_COLUMNS))
    offline = run_estimator(make_ekf(), frame, roads=road)
    np.testing.assert_allclose(offline.mean[0, :, 1], estimates, rtol=0, atol=1e-12)
    # and the vector wrapper: the same as the single one, car by car
    venv = gym.make_vec(CURVED, num_envs=2, vectorization_mode="vector_entry_point", config=config)
    wrapped = EstimatorInfoWrapper(venv, make_ekf())
    _, infos = wrapped.reset(seed=[2, 3])
    singles = [EstimatorInfoWrapper(gym.make(CURVED, config=config), make_ekf()) for _ in range(2)]
    single_infos = [e.reset(seed=s)[1] for e, s in zip(singles, (2, 3), strict=True)]
    for _ in range(50):
        actions = np.array([[0.01, 0.0], [0.012, 0.0]])
        *_, infos = wrapped.step(actions)
        single_infos = [e.step(act)[-1] for e, act in zip(singles, actions, strict=True)]
    for car in range(2):
        assert infos["estimate_lateral_offset"][car] == pytest.approx(
            single_infos[car]["estimate_lateral_offset"], abs=1e-9
        )


# ---------------------------------------------------------------- outside the model's road
def test_the_curvature_limit_comes_from_the_training_data():
    from estimators.settings import STRAIGHT_CURVATURE, steering_curvature_limit

    assert steering_curvature_limit(np.zeros(300)) == STRAIGHT_CURVATURE
    assert steering_curvature_limit(np.array([0.0, -1 / 120, np.nan])) == pytest.approx(
        1 / 120 + STRAIGHT_CURVATURE
    )
    assert steering_curvature_limit(None) == math.inf
    assert steering_curvature_limit(np.array([np.nan])) == math.inf
    with pytest.raises(ValueError, match="steering_curvature_limit"):
        FilterSettings(steering_curvature_limit=-1.0)


@pytest.mark.slow
def test_a_straight_road_model_leaves_the_lane_alone_on_bends():
    """The benchmark's case: the generalized model fitted on a straight run of a driver who
    later drives the curved track. With the limit the steering channel is off on the bends
    (and only there), and the run never ends confidently in a wrong lane."""
    from benchmarks.protocol import ProtocolConfig
    from benchmarks.protocol.plan import load_frames, synthetic_plan
    from estimators.settings import steering_curvature_limit
    from estimators.tuning import steering_residual_std
    from hasa_env.steering import GeneralizedModel

    plan = synthetic_plan(ProtocolConfig(seeds=(0,)), 0)
    train_ref = next(r for r in plan.main if r.driver == plan.illustrative and r.index == 0)
    train = load_frames([train_ref], "straight", plan.env_config, plan.params)[0]
    model = GeneralizedModel().fit(train)
    curved = load_frames(plan.curved[:2], "curved", plan.env_config, plan.params)
    limit = steering_curvature_limit(train["road_curvature"].to_numpy())
    residual = steering_residual_std(model.arx(), train, decision_lag=model.decision_lag)
    settings = FilterSettings.from_env_config(
        curved[0].attrs["config"], steering_residual_std=residual
    )
    ekf = GaussianMixtureEKF(
        model.arx(), replace(settings, steering_curvature_limit=limit),
        decision_lag=model.decision_lag,
    )  # fmt: skip
    result = run_estimator(ekf, curved)
    on_bends = np.abs(np.stack([f["road_curvature"].to_numpy() for f in curved])) > 0.002
    assert result.low_speed[on_bends].mean() > 0.95  # off where the road bends
    lead_in = np.stack([f["station"].to_numpy() for f in curved]) < 150.0 - 25.0
    assert result.low_speed[lead_in].mean() < 0.05  # on along the 150 m lead-in straight
    assert not result.wrong_lane_confident(0.95).any()
