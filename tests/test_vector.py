"""The native vector env reproduces N single envs step for step."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import hasa_env
from hasa_env.core import INFO_KEYS

CONFIG = {
    "time_limit": 0.37,  # several autoresets within the test
    "noise": {"block_size": 7},  # several noise-block refills too
    "observation": {"type": "both"},
    "initial_state": {"lateral_offset_std": 0.3, "speed_std": 2.0},
}


@pytest.mark.parametrize("env_id", hasa_env.ENV_IDS)
def test_vector_env_matches_sync_vector_of_single_envs(env_id):
    n = 5
    native = gym.make_vec(
        env_id, num_envs=n, vectorization_mode="vector_entry_point", config=CONFIG
    )
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", config=CONFIG)
    assert isinstance(native.unwrapped, hasa_env.LaneKeepingVectorEnv)
    assert native.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert native.single_observation_space == sync.single_observation_space
    assert native.single_action_space == sync.single_action_space
    obs_a, info_a = native.reset(seed=11)
    obs_b, info_b = sync.reset(seed=11)
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(120):
        for part in ("sensors", "state"):
            np.testing.assert_array_equal(obs_a[part], obs_b[part])
        for key in INFO_KEYS:
            np.testing.assert_array_equal(info_a[key], info_b[key], err_msg=key)
        actions = rng.uniform(-1.5, 1.5, (n, 2))  # some clipped
        obs_a, rew_a, term_a, trunc_a, info_a = native.step(actions)
        obs_b, rew_b, term_b, trunc_b, info_b = sync.step(actions)
        np.testing.assert_array_equal(rew_a, rew_b)
        np.testing.assert_array_equal(term_a, term_b)
        np.testing.assert_array_equal(trunc_a, trunc_b)
        ends += int(np.sum(term_a | trunc_a))
    assert ends >= n * 2  # the comparison crossed autoresets


def test_vector_env_spaces_and_info_masks():
    env = gym.make_vec(
        "hasa_env/LaneKeeping-v0", num_envs=3, vectorization_mode="vector_entry_point"
    )
    obs, info = env.reset(seed=0)
    assert obs.shape == (3, 6) and obs.dtype == np.float32
    assert env.observation_space.contains(obs)
    assert set(INFO_KEYS) <= set(info) and info["_lateral_offset"].all()
    obs, rew, term, trunc, info = env.step(env.action_space.sample())
    assert rew.shape == (3,) and term.dtype == bool


def test_vector_env_rejects_bad_actions_and_counts():
    env = hasa_env.LaneKeepingVectorEnv(num_envs=2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        env.step(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="env 1"):
        env.step(np.array([[0.0, 0.0], [np.nan, 0.0]]))
    with pytest.raises(ValueError, match="num_envs"):
        hasa_env.LaneKeepingVectorEnv(num_envs=0)


def test_vector_rgb_array_render():
    env = hasa_env.LaneKeepingVectorEnv(num_envs=2, render_mode="rgb_array")
    env.reset(seed=0)
    frames = env.render()
    assert len(frames) == 2 and frames[0].shape == (480, 640, 3)
