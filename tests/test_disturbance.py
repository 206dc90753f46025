"""External disturbances (crosswind gusts, road camber): seeded, reproducible, what they say."""

import gymnasium as gym
import numpy as np
import pytest

import hasa_env  # noqa: F401 - registers the ids
from hasa_env.sim.config import ConfigError
from hasa_env.sim.dynamics import ARRAY_OPS, SCALAR_OPS
from hasa_env.sim.setup import build_setup

WINDY = {"disturbance": {"crosswind": 0.5, "crosswind_bandwidth": 1.0, "components": 8}}


def _drive(config, seed=3, steps=1500, steering=0.0):
    env = gym.make("hasa_env/LaneKeeping-v0", config={"action": {"type": "physical"}, **config})
    _, info = env.reset(seed=seed, options={"lateral_offset": 0.0})
    y, imu = [info["lateral_offset"]], []
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(np.array([steering, 0.0]))
        y.append(info["lateral_offset"])
        imu.append(info["sensor_imu_lateral"])
        if terminated or truncated:
            break
    return np.array(y), np.array(imu)


def test_off_by_default_and_validated():
    assert build_setup(None).disturbance is None
    assert build_setup(WINDY).disturbance is not None
    with pytest.raises(ConfigError, match="disturbance.crosswind"):
        build_setup({"disturbance": {"crosswind": -1.0}})
    with pytest.raises(ConfigError, match="disturbance.components"):
        build_setup({"disturbance": {"crosswind": 1.0, "components": 0}})


def test_the_sums_have_the_configured_standard_deviation():
    setup = build_setup({"disturbance": {"crosswind": 0.5, "camber": 0.3, "components": 8}})
    d = setup.disturbance
    assert d.n_phases == 16
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 2000.0, 0.05)
    phases = np.repeat(rng.uniform(0, 2 * np.pi, (1, 16)), t.size, axis=0)
    wind = d.lateral_acceleration(t, np.zeros_like(t), phases, ARRAY_OPS)
    camber = d.lateral_acceleration(np.zeros_like(t), 20.0 * t, phases, ARRAY_OPS)
    # each sum alone: the other term is a constant offset at t = 0 (resp. s = 0)
    assert wind.std() == pytest.approx(0.5, rel=0.1)
    assert camber.std() == pytest.approx(0.3, rel=0.1)
    # one car (floats) and N cars (arrays) give the same bits
    phases_one = rng.uniform(0, 2 * np.pi, 16).tolist()
    scalar = d.lateral_acceleration(12.34, 56.7, phases_one, SCALAR_OPS)
    array = d.lateral_acceleration(
        np.array([12.34]), np.array([56.7]), np.array([phases_one]), ARRAY_OPS
    )
    assert scalar == array[0]


def test_a_disturbed_car_drifts_and_its_imu_shows_it():
    calm_y, calm_imu = _drive({})
    windy_y, windy_imu = _drive(WINDY)
    assert np.allclose(calm_y, 0.0, atol=1e-9)  # straight and undisturbed: no drift
    assert np.abs(windy_y).max() > 0.5  # pushed out of the lane centre
    assert windy_imu.std() > 3 * calm_imu.std()  # the IMU measures the gusts


def test_reproducible_by_seed_and_new_phases_per_seed():
    a, _ = _drive(WINDY, seed=5, steps=400)
    b, _ = _drive(WINDY, seed=5, steps=400)
    c, _ = _drive(WINDY, seed=6, steps=400)
    assert np.array_equal(a, b)
    n = min(a.size, c.size)
    assert not np.allclose(a[:n], c[:n])


def test_the_sensor_noise_stream_is_unchanged_when_off():
    """Old seeds keep their episodes: without a disturbance nothing extra is drawn."""
    env = gym.make("hasa_env/LaneKeeping-v0")
    env_off = gym.make("hasa_env/LaneKeeping-v0", config={"disturbance": {"crosswind": 0.0}})
    _, a = env.reset(seed=9)
    _, b = env_off.reset(seed=9)
    assert a == b
