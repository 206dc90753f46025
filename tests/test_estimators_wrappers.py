"""Gymnasium wrappers: estimates in info / as observations, single and vector envs."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import hasa_env  # noqa: F401  (registers the env ids)
from estimators.baselines import NoSteeringEKF, OracleEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.offline import run_estimator
from estimators.settings import FilterSettings
from estimators.wrappers import (
    EstimatorInfoWrapper,
    EstimatorObservationWrapper,
    VectorEstimatorInfoWrapper,
    VectorEstimatorObservationWrapper,
    estimate_info_keys,
    estimate_observation_names,
)
from hasa_env.sim.setup import RECORDING_COLUMNS, recording_row
from hasa_env.steering.arx import ARXForm

ENV_ID = "hasa_env/LaneKeeping-v0"
PAPER = ARXForm(a=(1.47, -0.51), b=(-5.73, 17.32, -17.65, 6.12), c=(0.11,), d=(-0.02, 0.02))
PHYSICAL = {"action": {"type": "physical"}}


def steer(info) -> np.ndarray:  # noqa: ANN001
    """A deterministic lane-keeping controller on the true state (single: (2,), vector: (N, 2))."""
    y = np.asarray(info["lateral_offset"], dtype=np.float64)
    heading = np.asarray(info["heading"], dtype=np.float64)
    delta = np.clip(-0.01 * y - 0.1 * heading, -0.5, 0.5)
    return np.stack([delta, np.zeros_like(delta)], axis=-1)


def make_ekf(config: dict | None = None) -> GaussianMixtureEKF:
    settings = FilterSettings.from_env_config(hasa_env.make_config({**PHYSICAL, **(config or {})}))
    return GaussianMixtureEKF(PAPER, settings)


def test_info_wrapper_adds_the_same_keys_every_step_and_matches_offline_filtering():
    env = EstimatorInfoWrapper(gym.make(ENV_ID, config={**PHYSICAL, "time_limit": 3.0}), make_ekf())
    obs, info = env.reset(seed=4, options={"bias_index": 1})
    keys = set(info)
    assert set(estimate_info_keys()) <= keys
    assert isinstance(info["estimate_lateral_offset"], float)
    assert isinstance(info["estimate_lane_index"], int)
    assert info["estimate_weights"].shape == (2,) and info["estimate_mean"].shape == (8,)
    rows = [recording_row(0, info, 0.0, False, False)]
    estimates = [info["estimate_lateral_offset"]]
    step, done = 0, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(steer(info))
        step += 1
        assert set(info) == keys
        rows.append(recording_row(step, info, reward, terminated, truncated))
        estimates.append(info["estimate_lateral_offset"])
        done = terminated or truncated
    assert env.observation_space.contains(obs)  # the observation is untouched
    frame = pd.DataFrame(rows, columns=list(RECORDING_COLUMNS))
    offline = run_estimator(make_ekf(), frame)
    np.testing.assert_allclose(offline.mean[0, :, 1], estimates, rtol=0, atol=1e-12)
    assert env.estimate is not None and env.estimate.weights.shape == (2,)


def test_observation_wrapper_is_a_valid_env():
    env = EstimatorObservationWrapper(gym.make(ENV_ID), make_ekf())
    assert env.observation_space.shape == (10,)
    assert len(estimate_observation_names(2)) == 10
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version.*")
        check_env(env, skip_render_check=True)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    np.testing.assert_allclose(obs[:4], info["estimate_mean"][:4], rtol=1e-6)
    np.testing.assert_allclose(obs[8:], info["estimate_weights"], rtol=1e-6)
    obs, *_ = env.step(np.zeros(2))
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)


def test_one_component_estimators_report_weights_on_the_env_hypotheses():
    env = EstimatorObservationWrapper(gym.make(ENV_ID, config=PHYSICAL), OracleEKF())
    obs, info = env.reset(seed=0, options={"bias_index": 1})
    np.testing.assert_array_equal(info["estimate_weights"], [0.0, 1.0])
    assert info["estimate_lane_index"] == 1 and obs.shape == (10,)
    assert env.observation_space.contains(obs)


def run_vector(env, steps: int) -> list[dict]:  # noqa: ANN001
    _, info = env.reset(seed=10)
    out = [info]
    for _ in range(steps):
        *_, info = env.step(steer(info))
        out.append(info)
    return out


@pytest.mark.parametrize("mode", ["vector_entry_point", "sync", "sync_same_step"])
def test_vector_wrapper_equals_single_envs_across_autoresets(mode):
    config = {**PHYSICAL, "time_limit": 0.3}  # 30 steps: several autoresets
    same_step = mode == "sync_same_step"
    kwargs = {"vector_kwargs": {"autoreset_mode": AutoresetMode.SAME_STEP}} if same_step else {}
    venv = gym.make_vec(
        ENV_ID,
        num_envs=3,
        vectorization_mode=mode.replace("_same_step", ""),
        config=config,
        **kwargs,
    )
    wrapped = EstimatorInfoWrapper(venv, make_ekf(config))
    assert isinstance(wrapped, VectorEstimatorInfoWrapper)
    infos = run_vector(wrapped, 70)
    for car in range(3):
        env = EstimatorInfoWrapper(gym.make(ENV_ID, config=config), make_ekf(config))
        _, info = env.reset(seed=10 + car)
        expected = [info]
        done = False
        for _ in range(70):
            if done:  # NEXT_STEP autoreset: the step after the end resets
                _, info = env.reset()
                done = False
            else:
                _, _, terminated, truncated, info = env.step(steer(info))
                done = terminated or truncated
                if done and same_step:  # SAME_STEP: reset at once, report the new start
                    _, info = env.reset()
                    done = False
            expected.append(info)
        for k in range(71):
            for key in ("estimate_lateral_offset", "estimate_bias", "time"):
                np.testing.assert_allclose(
                    infos[k][key][car], expected[k][key], rtol=1e-9, atol=1e-9
                )
            np.testing.assert_allclose(
                infos[k]["estimate_weights"][car], expected[k]["estimate_weights"], atol=1e-9
            )
    times = np.array([i["time"][0] for i in infos])
    assert np.sum(times == 0.0) >= 3  # the cars were reset along the way
    assert all(infos[0]["_estimate_weights"])


def test_vector_observation_wrapper_and_baseline():
    venv = gym.make_vec(
        ENV_ID, num_envs=4, vectorization_mode="vector_entry_point", config=PHYSICAL
    )
    wrapped = EstimatorObservationWrapper(venv, NoSteeringEKF())
    assert isinstance(wrapped, VectorEstimatorObservationWrapper)
    obs, info = wrapped.reset(seed=0)
    assert obs.shape == (4, 10) and wrapped.observation_space.contains(obs)
    assert wrapped.single_observation_space.shape == (10,)
    for _ in range(5):
        obs, _, _, _, info = wrapped.step(np.zeros((4, 2)))
    assert wrapped.observation_space.contains(obs)
    np.testing.assert_allclose(info["estimate_weights"], 0.5, atol=0.05)  # no steering: no clue


def test_wrapper_rejects_mismatched_timing():
    with pytest.raises(ValueError, match="action_repeat"):
        EstimatorInfoWrapper(gym.make(ENV_ID, config={"action_repeat": 2}), make_ekf())
    with pytest.raises(ValueError, match="sample time"):
        EstimatorInfoWrapper(gym.make(ENV_ID, config={"sim_frequency": 50.0}), make_ekf())


def test_vector_wrapper_partial_reset_restarts_only_the_masked_cars():
    """reset(options={"reset_mask": m}) restarts those cars' filters and leaves the others running."""
    venv = gym.make_vec(
        ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", config=PHYSICAL
    )
    wrapped = EstimatorInfoWrapper(venv, make_ekf())
    _, info = wrapped.reset(seed=3)
    for _ in range(40):
        *_, info = wrapped.step(steer(info))
    before = {k: np.array(v, copy=True) for k, v in info.items() if k.startswith("estimate_")}
    mask = np.array([False, True, False])
    _, info = wrapped.reset(options={"reset_mask": mask})
    for car in (0, 2):  # untouched filters
        np.testing.assert_array_equal(
            info["estimate_lateral_offset"][car], before["estimate_lateral_offset"][car]
        )
    # car 1 starts afresh: the same as a filter reset on its first measurements alone
    first = np.array(
        [info["sensor_speed"][1], info["sensor_camera_lateral"][1], info["sensor_steering"][1]]
    )
    est = make_ekf().reset(first, wrapped.hypotheses)
    np.testing.assert_allclose(info["estimate_lateral_offset"][1], est.lateral_offset, atol=1e-12)
    # the others keep filtering on the next step
    *_, info = wrapped.step(steer(info))
    assert info["estimate_lateral_offset"][0] != before["estimate_lateral_offset"][0]
