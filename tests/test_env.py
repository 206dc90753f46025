"""The single lane-keeping env: API compliance, determinism, config, errors."""

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import hasa_env
from hasa_env import ConfigError, default_config, make_config
from hasa_env.sim.setup import INFO_KEYS


@pytest.mark.parametrize("env_id", hasa_env.ENV_IDS)
@pytest.mark.parametrize("obs_type", ["sensors", "state", "both"])
def test_check_env_passes_without_warnings(env_id, obs_type):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id, render_mode="rgb_array", config={"observation": {"type": obs_type}})
        check_env(env.unwrapped)
        env.close()


def test_passive_checker_via_make_is_silent():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make("hasa_env/LaneKeeping-v0")
        env.reset(seed=1)
        for _ in range(5):
            env.step(env.action_space.sample())


def _rollout(env, seed, steps=300, options=None):
    obs, info = env.reset(seed=seed, options=options)
    rng = np.random.default_rng(123)
    out = [(obs, info)]
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(rng.uniform(-0.05, 0.05, 2).astype(np.float32))
        out.append((obs, r, term, trunc, info))
        if term or trunc:
            break
    return out


@pytest.mark.parametrize("env_id", hasa_env.ENV_IDS)
def test_same_seed_bit_identical(env_id):
    a = _rollout(gym.make(env_id), seed=7)
    b = _rollout(gym.make(env_id), seed=7)
    c = _rollout(gym.make(env_id), seed=8)
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x[0], y[0])
        assert x[-1] == y[-1]
    assert any(not np.array_equal(x[0], y[0]) for x, y in zip(a, c, strict=False))


def test_info_keys_identical_at_reset_and_step():
    env = gym.make("hasa_env/LaneKeeping-v0")
    _, info0 = env.reset(seed=0)
    _, _, _, _, info1 = env.step(env.action_space.sample())
    assert tuple(info0) == tuple(info1) == INFO_KEYS
    for key in INFO_KEYS:
        assert type(info0[key]) is type(info1[key]), key


def test_observation_is_post_step_state():
    env = gym.make(
        "hasa_env/LaneKeeping-v0",
        config={"observation": {"type": "both"}, "noise": {"camera": 0.0, "speed": 0.0}},
    )
    obs, info = env.reset(seed=3, options={"bias_index": 1})
    prev_y = info["lateral_offset"]
    obs, _, _, _, info = env.step(np.array([0.5, 1.0], dtype=np.float32))
    assert info["lateral_offset"] != prev_y
    assert obs["state"][0] == np.float32(info["lateral_offset"])
    assert obs["state"][2] == np.float32(info["speed"])
    assert obs["sensors"][1] == np.float32(info["lateral_offset"] + info["bias"])
    assert obs["sensors"][0] == np.float32(info["speed"])
    assert info["steering"] == pytest.approx(0.25)  # 0.5 of max_steering 0.5 rad
    assert info["time"] == pytest.approx(0.01)


def test_bias_drawn_per_episode_and_fixed_by_options():
    env = gym.make("hasa_env/LaneKeeping-v0")
    seen = {env.reset(seed=s)[1]["bias"] for s in range(40)}
    assert seen == {0.0, -1.8}
    _, info = env.reset(seed=0, options={"bias_index": 0})
    assert info["bias"] == 0.0 and info["bias_index"] == 0
    _, info = env.reset(options={"bias": -1.8})
    assert info["bias_index"] == 1
    _, info = env.reset(options={"lateral_offset": 0.2, "speed": 30.0})
    assert info["lateral_offset"] == 0.2 and info["speed"] == 30.0


def test_many_hypotheses_and_probabilities():
    cfg = {"markings": {"hypotheses": [0.0, -1.8, 1.8, 3.6], "probabilities": [0.1, 0.2, 0.3, 0.4]}}
    env = gym.make("hasa_env/LaneKeeping-v0", config=cfg)
    counts = np.zeros(4)
    for s in range(400):
        counts[env.reset(seed=s)[1]["bias_index"]] += 1
    assert np.all(counts > 0) and counts[3] > counts[0]


def test_normalized_and_physical_actions():
    env = gym.make(
        "hasa_env/LaneKeeping-v0",
        config={"action": {"min_acceleration": -8, "max_acceleration": 4}},
    )
    env.reset(seed=0)
    *_, info = env.step(np.array([-1.0, 1.0]))
    assert info["steering"] == -0.5 and info["acceleration"] == 4.0
    *_, info = env.step(np.array([3.0, -7.0]))  # clipped
    assert info["steering"] == 0.5 and info["acceleration"] == -8.0
    phys = gym.make("hasa_env/LaneKeeping-v0", config={"action": {"type": "physical"}})
    assert phys.action_space.high[0] == pytest.approx(0.5) and phys.action_space.low[1] == -6.0
    phys.reset(seed=0)
    *_, info = phys.step(np.array([0.01, 1.5]))
    assert info["steering"] == 0.01 and info["acceleration"] == 1.5


@pytest.mark.parametrize("bad", [[np.nan, 0.0], [0.0, np.inf], [0.0, -np.inf]])
def test_nan_and_inf_actions_raise(bad):
    env = gym.make("hasa_env/LaneKeeping-v0", disable_env_checker=True)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array(bad))


def test_wrong_action_shape_raises():
    env = gym.make("hasa_env/LaneKeeping-v0", disable_env_checker=True)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))


def test_step_before_reset_raises():
    env = hasa_env.LaneKeepingEnv()
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))


@pytest.mark.parametrize(
    ("config", "message"),
    [
        (
            {"noise": {"camera": -1.0}},
            r"'noise.camera' = -1.0 is out of range: allowed .*\[0, 10\]",
        ),
        ({"noise": {"camra": 0.1}}, r"unknown config key 'noise.camra'"),
        ({"bogus": 1}, r"unknown config key 'bogus'"),
        ({"track": "oval"}, r"'track' = 'oval' is not allowed: one of 'straight', 'curved'"),
        ({"action_repeat": 0}, r"'action_repeat' = 0 is out of range"),
        ({"action_repeat": 1.5}, r"'action_repeat' must be an integer"),
        ({"time_limit": 0}, r"'time_limit' = 0 is out of range: allowed .*\(0, "),
        ({"markings": {"hypotheses": []}}, r"'markings.hypotheses' must be a non-empty list"),
        ({"markings": {"probabilities": [1.0]}}, r"'markings.probabilities' has 1 entries"),
        ({"markings": {"probabilities": [0.3, 0.3]}}, r"must sum to 1"),
        ({"noise": {"speed": float("nan")}}, r"'noise.speed' must be a finite number"),
        ({"noise": 3}, r"'noise' must be a mapping"),
        ({"vehicle": {"wheelbase": "long"}}, r"'vehicle.wheelbase' must be a finite number"),
    ],
)
def test_bad_config_names_key_and_range(config, message):
    with pytest.raises(ConfigError, match=message):
        gym.make("hasa_env/LaneKeeping-v0", config=config)


def test_config_deep_merges():
    env = gym.make("hasa_env/LaneKeeping-v0", config={"noise": {"camera": 0.2}})
    cfg = env.unwrapped.config
    assert cfg["noise"]["camera"] == 0.2
    assert cfg["noise"]["speed"] == default_config()["noise"]["speed"]
    curved = gym.make("hasa_env/LaneKeepingCurved-v0", config={"noise": {"camera": 0.2}})
    assert curved.unwrapped.config["track"] == "curved"


def test_default_config_is_valid_and_fresh():
    a = default_config()
    a["noise"]["camera"] = 99
    assert default_config()["noise"]["camera"] == 0.05
    assert make_config() == make_config({})
    assert "noise.camera" in hasa_env.describe_config()


def test_bad_reset_options():
    env = gym.make("hasa_env/LaneKeeping-v0")
    with pytest.raises(ValueError, match="unknown reset option 'colour'"):
        env.reset(options={"colour": 1})
    with pytest.raises(ValueError, match=r"'bias_index' = 5 is out of range"):
        env.reset(options={"bias_index": 5})
    with pytest.raises(ValueError, match=r"'speed' = -3.0 is out of range"):
        env.reset(options={"speed": -3.0})
    with pytest.raises(ValueError, match=r"'bias' = -1.8 and 'bias_index' = 0 disagree"):
        env.reset(options={"bias": -1.8, "bias_index": 0})  # (bias_index 1 was kept silently)
    _, info = env.reset(options={"bias": -1.8, "bias_index": 1})
    assert info["bias"] == -1.8 and info["bias_index"] == 1
    _, info = env.reset(options={"bias": 0.7})  # no hypothesis: a lane the estimator lacks
    assert info["bias"] == 0.7 and info["bias_index"] == -1


def test_truncated_at_time_limit_with_action_repeat():
    env = gym.make("hasa_env/LaneKeeping-v0", config={"time_limit": 1.0, "action_repeat": 10})
    env.reset(seed=0)
    steps = 0
    while True:
        _, _, term, trunc, info = env.step(np.zeros(2))
        steps += 1
        if term or trunc:
            break
    assert trunc and not term and steps == 10
    assert info["time"] == pytest.approx(1.0)
    # a step of 0.07 s does not divide 1 s: truncated at the end of the step that reaches it
    env = gym.make("hasa_env/LaneKeeping-v0", config={"time_limit": 1.0, "action_repeat": 7})
    env.reset(seed=0)
    times = []
    while not times or not (term or trunc):
        _, _, term, trunc, info = env.step(np.zeros(2))
        times.append(info["time"])
    assert trunc and times[-2] < 1.0 <= times[-1] == pytest.approx(1.05)


def test_terminated_when_leaving_road():
    env = gym.make("hasa_env/LaneKeeping-v0", config={"observation": {"type": "state"}})
    env.reset(seed=0)
    for _ in range(2000):
        obs, reward, term, trunc, info = env.step(np.array([-0.3, 0.0]))
        if term:
            break
    assert term and not trunc
    assert info["lateral_offset"] < -1.8 - 0.5
    assert reward < -5  # off-road penalty


def test_reward_is_one_at_centre_with_steady_steering():
    env = gym.make("hasa_env/LaneKeeping-v0")
    env.reset(seed=0, options={"lateral_offset": 0.0})
    _, reward, *_ = env.step(np.zeros(2))
    assert reward == pytest.approx(1.0)


def test_imu_measures_lateral_acceleration():
    env = gym.make("hasa_env/LaneKeeping-v0", config={"noise": {"imu": 0.0}})
    env.reset(seed=0, options={"lateral_offset": 0.0})
    delta = 0.02
    for _ in range(3):
        *_, info = env.step(np.array([delta / 0.5, 0.0]))
    expected = 15.0**2 * math.tan(delta) / 2.8  # v^2 tan(delta) / L at small heading
    assert info["sensor_imu_lateral"] == pytest.approx(expected, rel=0.01)


def test_curved_track_state_observation_sees_curvature():
    env = gym.make("hasa_env/LaneKeepingCurved-v0", config={"observation": {"type": "state"}})
    env.reset(seed=0, options={"lateral_offset": 0.0})
    curvatures = []
    for _ in range(1500):
        obs, _, term, trunc, info = env.step(
            np.array(
                [
                    math.atan(2.8 * info_k) / 0.5
                    if (info_k := (curvatures[-1] if curvatures else 0.0))
                    else 0.0,
                    0.0,
                ]
            )
        )
        curvatures.append(float(obs[4]))
        if term or trunc:
            break
    assert max(np.abs(curvatures)) > 1 / 300


def test_rgb_array_frames_show_the_road_headless():
    env = gym.make("hasa_env/LaneKeeping-v0", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (480, 640, 3) and frame.dtype == np.uint8
    grey = np.all(np.abs(frame.astype(int) - np.array([90, 90, 96])) < 3, axis=-1)
    white = np.all(frame > 235, axis=-1)
    red = (frame[..., 0] > 180) & (frame[..., 1] < 60)
    assert grey.mean() > 0.1  # road surface
    assert white.sum() > 200  # lane markings
    assert red.sum() > 100  # the car
    ghost = np.all(np.abs(frame.astype(int) - np.array([200, 185, 90])) < 3, axis=-1)
    assert ghost.sum() > 50  # ghost markings of the -1.8 m hypothesis


def test_render_without_mode_warns_and_human_mode_accepted():
    env = hasa_env.LaneKeepingEnv()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    with pytest.raises(ValueError, match="render_mode"):
        hasa_env.LaneKeepingEnv(render_mode="ascii")
    human = gym.make("hasa_env/LaneKeeping-v0", render_mode="human")
    human.reset(seed=0)
    human.step(np.zeros(2))
    human.close()


def test_imu_averages_over_the_whole_env_step_with_action_repeat():
    """With action_repeat, the IMU is the mean acceleration since the previous observation."""
    env = gym.make(
        "hasa_env/LaneKeeping-v0",
        config={"action_repeat": 5, "noise": {"imu": 0.0}, "action": {"type": "physical"}},
    )
    _, info0 = env.reset(seed=0)
    *_, info1 = env.step(np.array([0.05, 2.0]))
    interval = 5 * 0.01
    assert info1["sensor_imu_lateral"] == pytest.approx(
        (info1["lateral_velocity"] - info0["lateral_velocity"]) / interval, rel=1e-12
    )
    assert info1["sensor_imu_longitudinal"] == pytest.approx(
        (info1["longitudinal_velocity"] - info0["longitudinal_velocity"]) / interval, rel=1e-12
    )
