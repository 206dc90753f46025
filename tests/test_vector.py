"""The native vector env reproduces N single envs step for step."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import hasa_env
from hasa_env.sim.setup import INFO_KEYS

CONFIG = {
    "time_limit": 0.37,  # several autoresets within the test
    "noise": {"block_size": 7},  # several noise-block refills too
    "observation": {"type": "both"},
    "initial_state": {"lateral_offset_std": 0.3, "speed_std": 2.0},
}


DISTURBED = {"disturbance": {"crosswind": 0.6, "camber": 0.4, "components": 5}}


@pytest.mark.parametrize("env_id", hasa_env.ENV_IDS)
@pytest.mark.parametrize("action_repeat", [1, 3])
@pytest.mark.parametrize("extra", [{}, DISTURBED], ids=["calm", "disturbed"])
def test_vector_env_matches_sync_vector_of_single_envs(env_id, action_repeat, extra):
    n = 5
    config = {**CONFIG, "action_repeat": action_repeat, **extra}
    native = gym.make_vec(
        env_id, num_envs=n, vectorization_mode="vector_entry_point", config=config
    )
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", config=config)
    assert isinstance(native.unwrapped, hasa_env.LaneKeepingVectorEnv)
    assert native.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert native.single_observation_space == sync.single_observation_space
    assert native.single_action_space == sync.single_action_space
    obs_a, info_a = native.reset(seed=11)
    obs_b, info_b = sync.reset(seed=11)
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(120 // action_repeat):
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
    assert ends >= n  # the comparison crossed autoresets


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


def test_partial_reset_with_reset_mask_touches_only_masked_cars():
    env = hasa_env.LaneKeepingVectorEnv(num_envs=3, config={"observation": {"type": "state"}})
    env.reset(seed=5)
    for _ in range(50):
        env.step(np.tile([0.1, 0.5], (3, 1)))
    before = env.step(np.zeros((3, 2)))[4]
    mask = np.array([False, True, False])
    obs, info = env.reset(seed=100, options={"reset_mask": mask})
    assert info["time"][1] == 0.0 and info["lateral_offset"][1] == -0.5
    for i in (0, 2):
        assert info["time"][i] == before["time"][i]
        assert info["lateral_offset"][i] == before["lateral_offset"][i]
    # the reset car equals a single env seeded with seed + its index
    single = hasa_env.LaneKeepingEnv(config={"observation": {"type": "state"}})
    s_obs, s_info = single.reset(seed=101)
    np.testing.assert_array_equal(obs[1], s_obs)
    assert s_info["bias"] == info["bias"][1]
    with pytest.raises(ValueError, match="reset_mask"):
        env.reset(options={"reset_mask": [True, False]})


def test_off_road_detected_at_every_sample_within_an_action_repeat():
    """A car that crosses the road edge between observations still terminates."""
    cfg = {"action_repeat": 50, "action": {"type": "physical"}, "road": {"lanes_left": 0}}
    env = hasa_env.LaneKeepingEnv(config=cfg)
    env.reset(seed=0, options={"lateral_offset": 2.0, "heading": 0.45, "speed": 10.0})
    # steer hard right: the car leaves the left edge (2.3 m) and comes back within the step
    _, _, term, _, info = env.step(np.array([-0.5, 0.0]))
    assert term and info["lateral_offset"] < 2.3


def test_vector_render_honours_the_view_config():
    env = hasa_env.LaneKeepingVectorEnv(
        num_envs=1,
        render_mode="rgb_array",
        config={"render": {"view": "driver", "width": 320, "height": 180}},
    )
    env.reset(seed=0)
    top = hasa_env.LaneKeepingVectorEnv(
        num_envs=1, render_mode="rgb_array", config={"render": {"width": 320, "height": 180}}
    )
    top.reset(seed=0)
    assert env.render()[0].shape == (180, 320, 3)
    assert not np.array_equal(env.render()[0], top.render()[0])
