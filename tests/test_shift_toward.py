"""Lane shifts toward the other hypothesis (issue 24): config, road, drivers, views, env."""

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

from hasa_env import ConfigError, make_config
from hasa_env.drivers import SyntheticDriver, population, run_driver
from hasa_env.render.common import DRIVEN_LANE_COLOUR
from hasa_env.render.driver_view import DriverViewRenderer
from hasa_env.render.top_down import TopDownRenderer
from hasa_env.sim.road import make_road, nearest_other_hypothesis
from hasa_env.sim.setup import _ghost_centre, build_setup

SHIFT = {"station": 100.0, "length": 60.0, "offset": 1.8}
TOWARD = {**SHIFT, "toward": "other_hypothesis"}
ENV_ID = "hasa_env/LaneKeeping-v0"


@pytest.mark.parametrize(
    "config, match",
    [
        ({"road": {"lane_shifts": [{**SHIFT, "toward": "right"}]}},
         r"'road\.lane_shifts\[0\]\.toward' must be one of 'left', 'other_hypothesis', got 'right'"),
        ({"road": {"lane_shifts": [SHIFT, {**SHIFT, "toward": 1}]}},
         r"lane_shifts\[1\]\.toward' must be one of"),
        ({"road": {"lane_shifts": [TOWARD]}, "markings": {"hypotheses": [0.0]}},
         r"lane_shifts\[0\]\.toward' = 'other_hypothesis' needs at least two "
         r"'markings\.hypotheses', got 1"),
        ({"road": {"lane_shifts": [{**SHIFT, "towards": "left"}]}},
         r"lane_shifts\[0\]' must be an object with exactly the keys station, length, offset"),
    ],
)  # fmt: skip
def test_a_bad_toward_is_named_with_the_allowed_values(config, match):
    with pytest.raises(ConfigError, match=match):
        make_config(config)


def test_toward_is_optional_and_kept_in_the_config():
    assert make_config({"road": {"lane_shifts": [SHIFT]}})["road"]["lane_shifts"] == [SHIFT]
    cfg = make_config({"road": {"lane_shifts": [TOWARD]}, "markings": {"hypotheses": [0.0, 1.0]}})
    assert cfg["road"]["lane_shifts"] == [TOWARD]
    left = make_config({"road": {"lane_shifts": [{**SHIFT, "toward": "left"}]}})
    assert left["road"]["lane_shifts"][0]["toward"] == "left"


def test_the_shift_moves_toward_the_other_hypothesis_for_either_bias():
    road = make_road("straight", lane_shifts=[TOWARD], hypotheses=[0.0, -1.8])
    s = np.linspace(80.0, 200.0, 241)
    for bias, sign in ((0.0, -1.0), (-1.8, 1.0)):
        assert road.driven_offset(s, bias)[-1] == pytest.approx(sign * 1.8)
    for method in (road.driven_offset, road.driven_slope, road.driven_curvature):
        right, left = method(s, 0.0), method(s, -1.8)
        assert np.any(left != 0.0)
        np.testing.assert_array_equal(right, -left)  # the sign flips, nothing else
    # "left" (or no key) is the offset as given, whatever the bias
    plain = make_road("straight", lane_shifts=[SHIFT])
    as_left = make_road("straight", lane_shifts=[{**SHIFT, "toward": "left"}], hypotheses=[0, -1.8])
    for method in ("driven_offset", "driven_slope", "driven_curvature"):
        reference = getattr(plain, method)(s)
        np.testing.assert_array_equal(getattr(plain, method)(s, 0.0), reference)
        np.testing.assert_array_equal(getattr(as_left, method)(s, 0.0), reference)
        np.testing.assert_array_equal(getattr(road, method)(s, -1.8), reference)
    with pytest.raises(ValueError, match="give the episode's true bias"):
        road.driven_offset(s)


def test_per_car_biases_broadcast_along_the_leading_axis():
    road = make_road("curved", lane_shifts=[TOWARD, {**SHIFT, "station": 300.0}],
                     hypotheses=[0.0, -1.8])  # fmt: skip
    bias = np.array([0.0, -1.8, 0.0])
    stations = np.array([[110.0, 130.0], [120.0, 330.0], [150.0, 400.0]])
    for method in (road.driven_offset, road.driven_slope, road.driven_curvature):
        one_by_one = np.array([method(stations[i], bias[i]) for i in range(3)])
        np.testing.assert_array_equal(method(stations, bias), one_by_one)
        np.testing.assert_array_equal(
            method(stations[:, 0], bias), [method(stations[i, 0], bias[i]) for i in range(3)]
        )


@pytest.mark.parametrize(
    "hypotheses", [[0.0, -1.8], [0.0, -1.0, 1.0], [-0.3, 0.0, 0.3, 2.0], [1.5, -2.0]]
)
def test_the_nearest_other_hypothesis_follows_the_between_hypotheses_rule(hypotheses):
    road = make_road("straight", lane_shifts=[TOWARD], hypotheses=hypotheses)
    for bias in [*hypotheses, 0.7]:
        near = nearest_other_hypothesis(bias, hypotheses)
        assert road.shift_signs(bias) == np.sign(near - bias)
        assert _ghost_centre(bias, hypotheses) == near - bias  # halfway start: half of it
    np.testing.assert_array_equal(
        road.shift_signs(np.array(hypotheses)), [road.shift_signs(b) for b in hypotheses]
    )


def test_of_two_equally_near_hypotheses_the_lower_one_wins():
    road = make_road("straight", lane_shifts=[TOWARD], hypotheses=[1.0, 0.0, -1.0])
    assert road.shift_signs(0.0) == -1.0
    assert road.driven_offset(500.0, np.array([0.0, 1.0, -1.0])).tolist() == [-1.8, -1.8, 1.8]


def test_a_road_with_a_shift_toward_needs_two_hypotheses():
    with pytest.raises(ValueError, match="at least two distinct Road.hypotheses"):
        make_road("straight", lane_shifts=[TOWARD], hypotheses=[0.0])
    with pytest.raises(ValueError, match=r"lane_shifts\[0\]\.toward must be one of"):
        make_road("straight", lane_shifts=[{**SHIFT, "toward": "up"}], hypotheses=[0.0, 1.0])


def _drive(scenario: str, bias_index: int, params, seconds: float) -> pd.DataFrame:
    env = gym.make(ENV_ID, config={"scenario": scenario, "time_limit": seconds,
                                   "action": {"type": "physical"}})  # fmt: skip
    (frame,) = run_driver(SyntheticDriver(params), env, seed=3, options={"bias_index": bias_index})
    return frame


@pytest.mark.parametrize("bias_index", [0, 1])
def test_a_driver_in_lane_shift_ends_on_the_ghost_centre_for_either_bias(bias_index):
    """After the shift the camera reads the other hypothesis's lane centre (reading - h ~ 0)."""
    hypotheses = make_config({"scenario": "lane_shift"})["markings"]["hypotheses"]
    other = hypotheses[1 - bias_index]
    for params in population("paper", 3, 6)[::2]:  # a two-point, a preview, an intermittent driver
        frame = _drive("lane_shift", bias_index, params, 22.0)
        assert not frame["terminated"].any()
        assert frame["bias"].iloc[0] == hypotheses[bias_index]
        after = frame["station"].to_numpy() > 150.0 + 65.0 + 40.0
        assert after.sum() > 100
        seen = frame["sensor_camera_lateral"].to_numpy()[after] - other
        assert abs(seen.mean()) < 0.5 and np.median(np.abs(seen)) < 0.5, params
        before = frame["station"].to_numpy() < 140.0
        assert abs(frame["lateral_offset"].to_numpy()[before].mean()) < 0.6


@pytest.mark.parametrize("bias_index", [0, 1])
def test_a_lane_change_goes_to_the_other_hypothesis_side_and_stays_on_the_road(bias_index):
    sign = 1.0 if bias_index == 1 else -1.0  # hypotheses [0, -1.8]: b = 0 -> right
    params = population("paper", 3, 6)[1]
    frame = _drive("lane_change", bias_index, params, 28.0)
    assert not frame["terminated"].any() and frame["truncated"].iloc[-1]
    y, station = frame["lateral_offset"].to_numpy(), frame["station"].to_numpy()
    overtaking = (station > 230.0) & (station < 290.0)
    assert overtaking.sum() > 100
    assert abs(y[overtaking].mean() - sign * 3.6) < 0.6
    assert abs(y[station > 400.0].mean()) < 0.6  # back in its lane
    setup = build_setup({"scenario": "lane_change"})
    assert setup.lower_edge < -3.6 - 1.8 < 3.6 + 1.8 < setup.upper_edge


@pytest.mark.parametrize("scenario", ["lane_shift", "lane_change"])
def test_single_and_vector_envs_drive_the_scenario_alike(scenario):
    driver = SyntheticDriver(population("paper", 3, 6)[0])
    config = {"scenario": scenario, "time_limit": 14.5}
    vector = run_driver(driver, runs=2, seed=2, config=config, vectorized=True)
    single = run_driver(driver, runs=2, seed=2, config=config, vectorized=False)
    assert {a["bias"].iloc[0] for a in vector} == {0.0, -1.8}  # one run under each
    for a, b in zip(vector, single, strict=True):
        assert a["station"].iloc[-1] > 200.0  # through the (first) shift
        pd.testing.assert_frame_equal(a, b, check_exact=True)


def _yellow(frame: np.ndarray) -> np.ndarray:
    return np.all(frame == np.array(DRIVEN_LANE_COLOUR, dtype=frame.dtype), axis=-1)


@pytest.mark.parametrize("scenario", ["lane_shift", "lane_change"])
@pytest.mark.parametrize("bias_index, side", [(0, 1.0), (1, -1.0)])  # +1: right of centre
def test_both_views_draw_the_episodes_driven_lane(scenario, bias_index, side):
    env = gym.make(ENV_ID, render_mode="rgb_array",
                   config={"scenario": scenario, "render": {"width": 320, "height": 240}})  # fmt: skip
    _, info = env.reset(seed=0, options={"bias_index": bias_index, "lateral_offset": 0.0})
    setup = env.unwrapped.setup
    # after the (first) shift, the car still on the marked lane's centre: the driven lane's
    # lines all on the side of the other hypothesis (lane_shift: one straight ahead)
    info = {**info, "station": 240.0}
    for renderer in (TopDownRenderer(setup, "rgb_array"), DriverViewRenderer(setup, "rgb_array")):
        frame = renderer.render(info)
        assert frame.shape == (240, 320, 3)
        cols = np.nonzero(_yellow(frame))[1] - 160.0
        assert cols.size > 200, type(renderer).__name__
        assert np.sum(side * cols > 40.0) > 50, type(renderer).__name__
        assert np.sum(side * cols < -40.0) == 0, type(renderer).__name__
    assert env.render().shape == (240, 320, 3)  # the env's own view renders the scenario
    env.close()
