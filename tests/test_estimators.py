"""The Gaussian-mixture EKF and its baselines on closed-loop data.

Data: the env driven by the paper's generalized ARX model as a driver
(steering ratio 15, white equation noise), :func:`estimators._testing.drive_arx`.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from estimators._testing import drive_arx
from estimators.base import ACCELERATION_KEYS, MEASUREMENT_KEYS, LaneEstimator
from estimators.baselines import NoSteeringEKF, OracleEKF, SingleHypothesisEKF
from estimators.filterpy_ekf import FilterpyGMEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.offline import run_estimator
from estimators.settings import FilterSettings
from estimators.tuning import steering_residual_std
from hasa_env.steering.arx import ARXForm

PAPER = ARXForm(a=(1.47, -0.51), b=(-5.73, 17.32, -17.65, 6.12), c=(0.11,), d=(-0.02, 0.02))
RATIO = 15.0
HYPOTHESES = [0.0, -1.8]


def make_ekf(**kw) -> GaussianMixtureEKF:
    kw.setdefault("steering_ratio", RATIO)
    kw.setdefault("steering_residual_std", 1e-3)
    return GaussianMixtureEKF(PAPER, **kw)


@pytest.fixture(scope="module")
def runs() -> dict[int, list[pd.DataFrame]]:
    """Four 30 s runs with each hypothesis true (same seeds: same trajectories)."""
    return {b: drive_arx(PAPER, runs=4, seed=3, bias_index=b, steering_ratio=RATIO) for b in (0, 1)}


def arrays(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    z = frame[list(MEASUREMENT_KEYS)].to_numpy(dtype=np.float64).copy()
    a = frame[list(ACCELERATION_KEYS)].to_numpy(dtype=np.float64).copy()
    return z, a


def with_dropouts(frame: pd.DataFrame) -> pd.DataFrame:
    """Camera lost for 1 s, steering sensor for 0.1 s, one IMU reading, one speed reading."""
    frame = frame.copy()
    frame.loc[500:599, "sensor_camera_lateral"] = np.nan
    frame.loc[900:909, "sensor_steering"] = np.nan
    frame.loc[1200, "sensor_imu_lateral"] = np.nan
    frame.loc[1500, "sensor_speed"] = np.nan
    frame.loc[1700:1702, list(MEASUREMENT_KEYS)] = np.nan
    return frame


def filter_run(estimator, frame: pd.DataFrame, hypotheses=HYPOTHESES, steps: int | None = None):  # noqa: ANN001, ANN201
    z, a = arrays(frame)
    steps = len(z) if steps is None else steps
    est = estimator.reset(z[0], hypotheses)
    out = [est]
    for k in range(1, steps):
        out.append(estimator.step(z[k], a[k]))
    return out


def test_public_api():
    import estimators

    if estimators.__file__ is None:
        pytest.skip(
            "estimators imports as a namespace package: the editable install predates "
            "estimators/__init__.py (reinstall with pip install -e . or run python -m pytest)"
        )
    for name in estimators.__all__:
        assert hasattr(estimators, name), name
    assert estimators.GaussianMixtureEKF is GaussianMixtureEKF


def test_estimators_implement_the_protocol():
    for est in (
        make_ekf(),
        FilterpyGMEKF(PAPER),
        NoSteeringEKF(),
        SingleHypothesisEKF(),
        OracleEKF(),
    ):
        assert isinstance(est, LaneEstimator)


@pytest.mark.parametrize("lag", [0, 1])
def test_one_component_matches_filterpy_over_a_whole_run(runs, lag):
    frame = with_dropouts(runs[1][0])
    fast = filter_run(make_ekf(decision_lag=lag), frame, [-1.8])
    ref = filter_run(
        FilterpyGMEKF(PAPER, steering_ratio=RATIO, steering_residual_std=1e-3, decision_lag=lag),
        frame,
        [-1.8],
    )
    assert len(fast) == len(frame) == 3001
    for a, b in zip(fast, ref, strict=True):
        np.testing.assert_allclose(a.component_means, b.component_means, rtol=0, atol=1e-9)
        np.testing.assert_allclose(
            a.component_covariances, b.component_covariances, rtol=0, atol=1e-9
        )
    assert np.all(np.isfinite(fast[-1].mean))


@pytest.mark.parametrize("checks", [True, False])
def test_mixture_matches_filterpy_with_floor_or_pruning(runs, checks):
    # with the evidence checks the wrong lane's weight rests on the floor; without them
    # (the paper's eq. 19 as written) an explicit prune_threshold prunes it
    # (the aim cap off: it keeps the wrong lane's weight far above the floor)
    options = {
        "evidence_checks": checks,
        "prune_threshold": 0.0 if checks else 1e-10,
        "aim_offset_std": 0.0,
    }
    frame = with_dropouts(runs[0][1])
    fast = filter_run(make_ekf(**options), frame, steps=800)
    ref = filter_run(
        FilterpyGMEKF(PAPER, steering_ratio=RATIO, steering_residual_std=1e-3, **options),
        frame,
        steps=800,
    )
    for a, b in zip(fast, ref, strict=True):
        np.testing.assert_allclose(a.weights, b.weights, rtol=0, atol=1e-9)
        np.testing.assert_allclose(a.mean, b.mean, rtol=0, atol=1e-9)
        assert a.decision == b.decision
        np.testing.assert_allclose(a.model_error, b.model_error, rtol=1e-9)
    if checks:
        assert fast[-1].weights[1] == pytest.approx(1e-12, rel=1e-6)  # floored, not pruned
        assert fast[-1].decision == "decided"
    else:
        assert fast[-1].weights[1] == 0.0  # pruned


def test_vectorized_path_equals_per_run_path(runs):
    frames = [with_dropouts(runs[0][0]), runs[0][1], runs[1][2], with_dropouts(runs[1][3])]
    steps = 600
    z = np.stack([arrays(f)[0] for f in frames])
    a = np.stack([arrays(f)[1] for f in frames])
    batch = make_ekf()
    est = batch.reset(z[:, 0], HYPOTHESES)
    single = [filter_run(make_ekf(), f, steps=steps) for f in frames]
    for k in range(steps):
        if k:
            est = batch.step(z[:, k], a[:, k])
        for r in range(len(frames)):
            np.testing.assert_allclose(est.mean[r], single[r][k].mean, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(
                est.component_covariances[r],
                single[r][k].component_covariances,
                rtol=1e-12,
                atol=1e-14,
            )
            np.testing.assert_allclose(est.weights[r], single[r][k].weights, rtol=1e-12, atol=1e-12)


def test_stepping_a_subset_of_runs_leaves_the_others(runs):
    frames = runs[0][:3]
    z = np.stack([arrays(f)[0] for f in frames])
    a = np.stack([arrays(f)[1] for f in frames])
    ekf = make_ekf()
    ekf.reset(z[:, 0], HYPOTHESES)
    before = ekf.estimate()
    est = ekf.step(z[[0, 2], 1], a[[0, 2], 1], runs=np.array([0, 2]))
    np.testing.assert_array_equal(est.component_means[1], before.component_means[1])
    alone = make_ekf()
    alone.reset(z[2, 0], HYPOTHESES)
    np.testing.assert_allclose(est.mean[2], alone.step(z[2, 1], a[2, 1]).mean, rtol=1e-12)
    # restart run 1 from a new start
    est = ekf.reset(z[1:2, 5], HYPOTHESES, runs=[1])
    fresh = make_ekf().reset(z[1, 5], HYPOTHESES)
    np.testing.assert_allclose(est.mean[1], fresh.mean)
    np.testing.assert_array_equal(est.weights[1], [0.5, 0.5])


def test_covariances_stay_symmetric_positive_definite_through_dropouts(runs):
    out = filter_run(make_ekf(prune_threshold=0.0), with_dropouts(runs[1][0]))
    for est in out[::50] + out[495:610] + out[1695:1705]:
        cov = est.component_covariances
        np.testing.assert_array_equal(cov, np.swapaxes(cov, -1, -2))
        assert np.linalg.eigvalsh(cov).min() > 0
        assert math.isclose(est.weights.sum(), 1.0, rel_tol=1e-12)
    # the camera dropout widens y's uncertainty (steering and IMU still inform it); it shrinks back
    std_y = [e.lateral_offset_std for e in out]
    assert std_y[599] > std_y[499] and std_y[700] < std_y[599]


def test_mixture_picks_the_true_lane_with_a_matched_model(runs):
    for bias_index in (0, 1):
        res = run_estimator(make_ekf(), runs[bias_index])
        assert res.picked_true_lane().all()
        # (above 0.9995: the aim cap holds the log-odds to what where the car is held allows)
        assert np.all(res.true_lane_weight()[:, 20:] > 0.99)
        assert np.all(res.lateral_rmse() < 0.1)
        assert np.all(res.lateral_rmse(start=100) < 0.03)


class SharedMemoryEKF(GaussianMixtureEKF):
    """A deliberately wrong filter: every hypothesis starts with hypothesis 0's
    memory states (one shared "observed" memory), as the paper describes."""

    def __init__(self, *args, **kwargs) -> None:  # noqa: ANN002, ANN003
        super().__init__(*args, **kwargs)
        own = self.matrices.initial_state

        def shared(z: np.ndarray, hyp: np.ndarray) -> np.ndarray:
            x = own(z, hyp)
            x[..., 4:] = x[:, :1, 4:]
            return x

        self.matrices.initial_state = shared


@pytest.mark.slow
def test_swapping_the_true_hypothesis_gives_the_same_statistics(runs):
    """The memory initialisation uses each hypothesis' own bearings, never a
    shared or true lane: with the same trajectories, which hypothesis is true
    does not change the errors (the wrong one sits 1.8 m to the other side). The aim cap is
    off: it reads where the car sits from each centre, which the swap does change."""
    res = {b: run_estimator(make_ekf(aim_offset_std=0.0), runs[b]) for b in (0, 1)}
    rmse = {b: r.lateral_rmse() for b, r in res.items()}
    assert abs(rmse[0].mean() - rmse[1].mean()) < 0.003
    np.testing.assert_allclose(rmse[0], rmse[1], rtol=0.15)  # the first 2-3 steps differ
    late = {b: r.lateral_rmse(start=20) for b, r in res.items()}
    np.testing.assert_allclose(late[0], late[1], rtol=1e-6)
    # the test has teeth: a shared memory start favours hypothesis 0 whichever is true
    leaky = {
        b: run_estimator(
            SharedMemoryEKF(PAPER, steering_ratio=RATIO, steering_residual_std=1e-3), runs[b]
        )
        for b in (0, 1)
    }
    assert leaky[0].lateral_rmse().mean() < 0.05 and leaky[1].lateral_rmse().mean() > 0.5


def test_initial_memory_uses_each_hypothesis_own_bearings():
    ekf = make_ekf()
    z0 = np.array([15.0, -0.4, 0.02 / RATIO])
    est = ekf.reset(z0, [0.0, -1.8, 1.8])
    model = ekf.model
    for i, b in enumerate([0.0, -1.8, 1.8]):
        x = est.component_means[i]
        assert x[1] == pytest.approx(-0.4 - b) and x[3] == b
        np.testing.assert_allclose(x[4:], model.steady_memory(np.array(0.02), x), rtol=1e-14)
    # a hypothesis' start does not depend on which others are present or true
    alone = make_ekf().reset(z0, [1.8])
    np.testing.assert_array_equal(alone.component_means[0], est.component_means[2])
    swapped = make_ekf().reset(z0, [1.8, 0.0, -1.8])
    np.testing.assert_array_equal(swapped.component_means[[1, 2, 0]], est.component_means)


def test_no_steering_baseline_confuses_lanes_1_8_m_apart(runs):
    res = run_estimator(NoSteeringEKF(), runs[0] + runs[1])
    rmse = res.lateral_rmse()
    assert np.all(np.abs(rmse - 0.9) < 0.03), rmse
    np.testing.assert_allclose(res.weights[:, -1], 0.5, atol=0.05)


def test_single_hypothesis_and_oracle_baselines(runs):
    single_res = run_estimator(SingleHypothesisEKF(), runs[0] + runs[1])
    single = single_res.lateral_rmse()
    assert np.all(single[:4] < 0.05) and np.all(np.abs(single[4:] - 1.8) < 0.05)
    np.testing.assert_array_equal(single_res.picked_true_lane(), [True] * 4 + [False] * 4)
    oracle = run_estimator(OracleEKF(), runs[0] + runs[1])
    assert np.all(oracle.lateral_rmse() < 0.05) and oracle.picked_true_lane().all()
    np.testing.assert_array_equal(oracle.true_lane_weight(), 1.0)
    np.testing.assert_array_equal(oracle.hypotheses[:, 0], [0.0] * 4 + [-1.8] * 4)
    with pytest.raises(ValueError, match="true_bias"):
        OracleEKF().reset(np.array([15.0, 0.0, 0.0]), HYPOTHESES)


@pytest.mark.slow
def test_any_number_of_hypotheses_floored_or_pruned(runs):
    hyps = [3.6, 1.8, 0.0, -1.8, -3.6]
    # the aim cap off: it keeps the neighbours' weights near 1e-4, far above the floor
    no_cap = {"aim_offset_std": 0.0}
    res = run_estimator(make_ekf(**no_cap), runs[1], hypotheses=hyps)
    assert res.weights.shape[-1] == 5
    assert np.all(res.most_likely[:, -1] == 3)  # b = -1.8 is true
    others = np.delete(res.weights[:, -1], 3, axis=1)
    assert np.all(others < 1e-12)  # never pruned: their filters run on, log weights finite
    assert np.all(np.isfinite(res.weights)) and np.all(res.final_decision() == "decided")
    floored = run_estimator(make_ekf(weight_floor=1e-12, **no_cap), runs[1], hypotheses=hyps)
    np.testing.assert_allclose(np.delete(floored.weights[:, -1], 3, axis=1), 1e-12, rtol=1e-6)
    pruned = run_estimator(make_ekf(prune_threshold=1e-10, **no_cap), runs[1], hypotheses=hyps)
    assert np.count_nonzero(pruned.weights[:, -1]) == 4  # the others are pruned to exactly 0
    np.testing.assert_allclose(pruned.lateral_rmse(), res.lateral_rmse(), rtol=1e-3)
    # log-space weights: evidence far beyond float range stays finite and ordered
    # (the paper's eq. 19 without the floor and forgetting of the evidence checks)
    out = filter_run(make_ekf(evidence_checks=False), runs[1][0], hyps, steps=400)
    log_w = out[-1].log_weights
    assert np.all(np.isfinite(log_w)) and log_w.min() < -1000 and np.argmax(log_w) == 3


def test_run_estimator_pads_runs_of_different_lengths(runs):
    frames = [runs[0][0], runs[0][1].iloc[:1200]]
    res = run_estimator(make_ekf(), frames, store_components=True)
    assert res.mean.shape == (2, 3001, 8) and res.component_means.shape == (2, 3001, 2, 8)
    np.testing.assert_array_equal(res.lengths, [3001, 1200])
    assert res.valid[1, 1199] and not res.valid[1, 1200]
    assert np.isnan(res.lateral_error()[1, 1200:]).all()
    short = run_estimator(make_ekf(), frames[1])
    np.testing.assert_allclose(short.mean[0], res.mean[1, :1200], rtol=1e-12, atol=1e-12)
    out = res.to_frames()
    assert len(out[1]) == 1200
    assert {
        "estimate_lateral_offset",
        "std_lateral_offset",
        "weight_0",
        "weight_1",
        "lateral_offset",
    } <= set(out[0].columns)


def test_steering_residual_std_from_recordings(runs):
    sigma = steering_residual_std(PAPER, runs[0], steering_ratio=RATIO)
    # the driver's equation noise is 1e-3 rad (model units), plus rounding at the wheel limit
    assert sigma == pytest.approx(1e-3, rel=0.1)


def test_settings_validation_and_env_config():
    with pytest.raises(ValueError, match="speed_noise_std"):
        FilterSettings(speed_noise_std=0.0)
    with pytest.raises(ValueError, match="camera_noise_std"):
        FilterSettings(camera_noise_std=float("nan"))
    with pytest.raises(ValueError, match="prune_threshold"):
        FilterSettings(prune_threshold=1.0)
    from hasa_env import make_config

    s = FilterSettings.from_env_config(
        make_config({"noise": {"camera": 0.2}}), steering_residual_std=5e-3
    )
    assert (
        s.camera_noise_std == 0.2 and s.steering_residual_std == 5e-3 and s.speed_noise_std == 0.05
    )


def test_reset_and_step_errors():
    ekf = make_ekf()
    with pytest.raises(RuntimeError, match="reset"):
        ekf.step(np.zeros(3), np.zeros(2))
    with pytest.raises(ValueError, match="shape"):
        ekf.reset(np.zeros(4), HYPOTHESES)
    with pytest.raises(ValueError, match="finite speed and camera"):
        ekf.reset(np.array([np.nan, 0.0, 0.0]), HYPOTHESES)
    ekf.reset(np.array([[15.0, 0.0, 0.0]] * 2), HYPOTHESES)
    with pytest.raises(ValueError, match="expected measurement"):
        ekf.step(np.zeros(3), np.zeros(2))
    with pytest.raises(ValueError, match="prior"):
        ekf.reset(np.array([15.0, 0.0, 0.0]), HYPOTHESES, prior=[0.7, 0.7])


def test_all_measurements_missing_only_predicts():
    ekf = make_ekf()
    ekf.reset(np.array([15.0, -0.5, 0.0]), HYPOTHESES)
    before = ekf.estimate()
    est = ekf.step(np.full(3, np.nan), np.array([0.0, 0.0]))
    np.testing.assert_array_equal(est.weights, before.weights)
    assert est.lateral_offset_std > before.lateral_offset_std - 1e-12
    est = ekf.step(np.full(3, np.nan), np.full(2, np.nan))
    assert np.all(np.isfinite(est.component_means))
