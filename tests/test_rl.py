"""RL helpers that need only gymnasium: partial reset, action wrappers, advisor, evaluation."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import hasa_env
from hasa_env import LaneKeepingVectorEnv
from hasa_env.drivers import SpeedProfile, SyntheticDriver, population
from hasa_env.rl import (
    ActionRepeat,
    ConstantSteering,
    DriverPolicy,
    HumanAdvisor,
    SteeringOnly,
    VectorSteeringOnly,
    env_action,
    evaluate,
    make_vector_env,
)
from hasa_env.sim.setup import INFO_KEYS

ENV_ID = "hasa_env/LaneKeeping-v0"


def _driver() -> SyntheticDriver:
    params = population("paper-pi", 0)[0]
    return SyntheticDriver(dataclasses.replace(params, speed=SpeedProfile.hold()))


def test_partial_reset_resets_only_masked_cars_like_their_autoreset():
    config = {"time_limit": 0.2, "initial_state": {"lateral_offset_std": 0.5}}
    a = LaneKeepingVectorEnv(num_envs=3, config=config)
    b = LaneKeepingVectorEnv(num_envs=3, config=config)
    a.reset(seed=4)
    b.reset(seed=4)
    actions = np.tile([0.1, 0.0], (3, 1))
    for _ in range(20):  # car episodes end at step 20 (0.2 s)
        obs_a, *_ = a.step(actions)
        obs_b, _, term, trunc, _ = b.step(actions)
    assert (term | trunc).all()
    # a: reset car 1 now; b: let the autoreset reset every car on the next step
    mask = np.array([False, True, False])
    obs_reset, info = a.reset(options={"reset_mask": mask})
    np.testing.assert_array_equal(info["_lateral_offset"], mask)
    np.testing.assert_array_equal(obs_reset[[0, 2]], obs_a[[0, 2]])  # others untouched
    obs_auto, reward, term, trunc, info_auto = b.step(actions)
    np.testing.assert_array_equal(obs_reset[1], obs_auto[1])  # same draws as the autoreset
    for key in INFO_KEYS:
        assert info[key][1] == info_auto[key][1], key
    # the reset car no longer has a pending autoreset: the next step moves it
    obs_next, reward, *_ = a.step(actions)
    assert reward[1] != 0.0
    assert obs_next[1, 1] != obs_reset[1, 1]


def test_partial_reset_rejects_bad_masks():
    env = LaneKeepingVectorEnv(num_envs=2)
    with pytest.raises(RuntimeError, match="reset_mask must come first"):
        env.reset(options={"reset_mask": np.array([True, False])})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="bool array of shape"):
        env.reset(options={"reset_mask": np.array([True, False, True])})
    with pytest.raises(ValueError, match="at least one"):
        env.reset(options={"reset_mask": np.zeros(2, dtype=bool)})
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"reset_mask": np.array([True, False]), "colour": 1})


def test_make_vector_env_uses_the_ids_track():
    env = make_vector_env("hasa_env/LaneKeepingCurved-v0", num_envs=2, steering_only=True)
    assert env.unwrapped.config["track"] == "curved"
    assert isinstance(env.unwrapped, LaneKeepingVectorEnv)
    assert env.single_action_space.shape == (1,)
    with pytest.raises(ValueError, match="not one of the lane-keeping env's ids"):
        make_vector_env("CartPole-v1")
    import advisor_tasks  # noqa: F401 - registers the advisor ids

    with pytest.raises(ValueError, match=r"gym.make_vec\('hasa_env/LaneKeepingAdvisor-v0', "):
        make_vector_env("hasa_env/LaneKeepingAdvisor-v0")  # points to the way that works


@pytest.mark.parametrize("action_type", ["normalized", "physical"])
def test_steering_only_holds_the_speed(action_type):
    config = {"action": {"type": action_type}, "time_limit": 2.0}
    env = SteeringOnly(gym.make(ENV_ID, config=config))
    assert env.action_space.shape == (1,)
    _, info = env.reset(seed=1)
    speed = info["speed"]
    for _ in range(50):
        _, _, _, _, info = env.step(env.action_space.sample())
        assert info["acceleration"] == 0.0
    assert info["speed"] == speed
    with pytest.raises(ValueError, match=r"shape \(1,\)"):
        env.step(np.zeros(2))


def test_vector_steering_only():
    env = VectorSteeringOnly(make_vector_env(num_envs=3))
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.full((3, 1), 0.5))
    np.testing.assert_allclose(info["steering"], 0.25)  # 0.5 x max_steering 0.5 rad
    np.testing.assert_array_equal(info["acceleration"], 0.0)
    with pytest.raises(ValueError, match=r"shape \(3, 1\)"):
        env.step(np.zeros((3, 2)))


def test_env_action_maps_physical_commands():
    env = gym.make(ENV_ID)  # normalized, limits 0.5 rad and -6..6 m/s^2
    np.testing.assert_allclose(env_action(env, 0.25, 3.0), [0.5, 0.5])
    phys = gym.make(ENV_ID, config={"action": {"type": "physical"}})
    np.testing.assert_allclose(env_action(phys, 0.25, 3.0), [0.25, 3.0])
    np.testing.assert_allclose(env_action(SteeringOnly(env), 0.25, 3.0), [0.5])


def test_action_repeat_equals_the_envs_own_action_repeat():
    """The true state after k held actions is the same as with config action_repeat = k."""
    config = {"initial_state": {"heading_std": 0.01}, "time_limit": 3.0}
    wrapped = ActionRepeat(gym.make(ENV_ID, config=config), 10)
    native = gym.make(ENV_ID, config={**config, "action_repeat": 10})
    _, info_w = wrapped.reset(seed=3)
    _, info_n = native.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(30):
        action = rng.uniform(-0.02, 0.02, 2)
        _, reward_w, term_w, trunc_w, info_w = wrapped.step(action)
        _, reward_n, term_n, trunc_n, info_n = native.step(action)
        for key in ("time", "station", "lateral_offset", "heading", "speed", "steering"):
            assert info_w[key] == info_n[key], key
        assert len(info_w["substep_lateral_offset"]) == 10
        assert info_w["substep_lateral_offset"][-1] == info_w["lateral_offset"]
        assert (term_w, trunc_w) == (term_n, trunc_n)
    assert trunc_w and not term_w  # the whole 3 s episode was compared
    with pytest.raises(ValueError, match="positive integer"):
        ActionRepeat(wrapped, 0)


def test_human_advisor_reports_the_drivers_steering_with_a_drivers_timing():
    """A policy that applies the advice reproduces a human driving: both readings agree."""
    config = {"action": {"type": "physical"}, "noise": {"steering": 0.0}}
    env = HumanAdvisor(SteeringOnly(gym.make(ENV_ID, config=config)), _driver())
    _, info = env.reset(seed=5)
    assert info["sensor_steering"] == info["sensor_steering_applied"]
    commands = set()
    for _ in range(300):
        command = env.command
        commands.add(round(command, 6))
        _, _, _, _, info = env.step(np.array([command]))
        assert info["sensor_steering"] == command
        assert info["sensor_steering_applied"] == info["steering"] == command
    assert len(commands) > 10  # the driver really steers
    # a policy that ignores the advice: the two readings part
    _, info = env.reset(seed=5)
    for _ in range(100):
        _, _, _, _, info = env.step(np.array([0.0]))
    assert info["sensor_steering_applied"] == 0.0
    assert abs(info["sensor_steering"]) > 1e-4


def test_human_advisor_is_reproducible():
    def run() -> list[float]:
        env = HumanAdvisor(
            gym.make(ENV_ID, config={"initial_state": {"heading_std": 0.02}}), _driver()
        )
        env.reset(seed=9)
        return [env.step(np.zeros(2))[4]["sensor_steering"] for _ in range(50)]

    assert run() == run()


def test_evaluate_zero_steering_on_a_straight_road_holds_the_offset():
    """From y = -0.5 m with heading 0 nothing moves the car sideways: |y| = 0.5 m exactly."""
    config = {"action_repeat": 10, "time_limit": 5.0}

    def make() -> gym.Env:
        return SteeringOnly(gym.make(ENV_ID, config=config))

    result = evaluate(ConstantSteering(), make, episodes=4, seed=0)
    assert result.episodes == 4
    assert result.mean_abs_lateral_error == pytest.approx(0.5, abs=1e-12)
    assert result.rms_lateral_error == pytest.approx(0.5, abs=1e-12)
    assert result.mean_return == pytest.approx(50 * (1 - (0.5 / 1.8) ** 2), rel=1e-12)
    assert result.offroad_rate == 0.0
    assert result.mean_duration == pytest.approx(5.0)


def test_evaluate_driver_centres_and_constant_steering_leaves_the_road():
    config = {"action_repeat": 10, "time_limit": 10.0}

    def make() -> gym.Env:
        return SteeringOnly(gym.make(ENV_ID, config=config))

    human = evaluate(DriverPolicy(_driver()), make, episodes=2, seed=0)
    assert human.offroad_rate == 0.0 and human.mean_abs_lateral_error < 0.35
    left = evaluate(ConstantSteering(0.05, name="left"), make, episodes=2, seed=0)
    assert left.offroad_rate == 1.0 and left.mean_duration < 10.0
    assert human.mean_return > left.mean_return
    assert "left" in left.line() and "off-road 100.0 %" in left.line()
    with pytest.raises(ValueError, match="episodes"):
        evaluate(ConstantSteering(), make, episodes=0)


def test_wrappers_reject_non_hasa_envs():
    with pytest.raises(TypeError, match="hasa_env"):
        SteeringOnly(gym.make("Pendulum-v1"))
    with pytest.raises(TypeError, match="hasa_env"):
        HumanAdvisor(gym.make("Pendulum-v1"), _driver())
    assert hasa_env.ENV_IDS  # the ids are registered by the import
