"""Near/far-point bearings and the features of a recorded run."""

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hasa_env.sim.road import curved_road, straight_road
from hasa_env.sim.setup import RECORDING_COLUMNS
from hasa_env.steering.features import near_far_bearings, road_of_frame, steering_features

finite = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(
    station=st.floats(0.0, 4000.0),
    offset=st.floats(-5.0, 5.0),
    heading=st.floats(-0.5, 0.5),
    near=st.floats(1.0, 30.0),
    far=st.floats(5.0, 80.0),
)
def test_exact_and_paper_bearings_agree_on_a_straight_road(station, offset, heading, near, far):
    road = straight_road()
    exact = near_far_bearings(road, station, offset, heading, near, far, exact=True)
    paper = near_far_bearings(road, station, offset, heading, near, far, exact=False)
    expected = (-(heading + math.atan(offset / near)), -(heading + math.atan(offset / far)))
    np.testing.assert_allclose(exact, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(paper, expected, rtol=0, atol=1e-15)


def test_exact_geometry_on_a_straight_road_is_not_a_shortcut():
    """The exact path (lane_centre_bearing) is used for a straight road given as a curved
    road's straight part, and still equals the formula there."""
    road = curved_road()
    s = np.linspace(0.0, 100.0, 11)  # the first 150 m are straight; points 20 m ahead too
    y = np.linspace(-1.0, 1.0, 11)
    th = np.linspace(-0.1, 0.1, 11)
    phi, omega = near_far_bearings(road, s, y, th, 6.2, 20.0, exact=True)
    np.testing.assert_allclose(phi, -(th + np.arctan(y / 6.2)), atol=1e-9)
    np.testing.assert_allclose(omega, -(th + np.arctan(y / 20.0)), atol=1e-9)


def test_exact_bearing_in_a_bend_is_the_chord_angle():
    road = curved_road()
    # the first bend: 150 m straight, 50 m clothoid, then a 250 m-radius left arc
    s = 260.0
    assert road.curvature_at(s) == pytest.approx(1 / 250.0)
    phi, omega = near_far_bearings(road, s, 0.0, 0.0, 6.2, 20.0, exact=True)
    # on a circle the chord to the point d ahead (arc length) makes the angle d / (2 R)
    # with the tangent; the road's 0.5 m grid interpolation costs ~1e-4 m of position
    assert phi == pytest.approx(6.2 / 500.0, abs=5e-5)
    assert omega == pytest.approx(20.0 / 500.0, abs=2e-5)
    straight = near_far_bearings(road, s, 0.0, 0.0, 6.2, 20.0, exact=False)
    assert straight == (0.0, 0.0)


def test_bearing_arguments_are_checked():
    with pytest.raises(ValueError, match="positive"):
        near_far_bearings(None, 0.0, 0.0, 0.0, near=0.0)


def _frame(n=6, curvature=0.0):
    rng = np.random.default_rng(0)
    data = {c: np.zeros(n) for c in RECORDING_COLUMNS}
    data["step"] = np.arange(n)
    data["time"] = np.arange(n) * 0.01
    data["station"] = np.arange(n) * 0.15
    data["lateral_offset"] = rng.uniform(-1, 1, n)
    data["heading"] = rng.uniform(-0.05, 0.05, n)
    data["speed"] = np.full(n, 15.0)
    data["steering"] = rng.uniform(-0.01, 0.01, n)
    data["sensor_steering"] = data["steering"] + 1e-4 * rng.standard_normal(n)
    data["lateral_velocity"] = 15.0 * np.sin(data["heading"])
    data["road_curvature"] = np.full(n, curvature)
    return pd.DataFrame(data)


def test_features_pair_each_steering_with_the_bearings_seen_one_row_earlier():
    frame = _frame()
    features = steering_features(frame, steering="applied")
    assert list(features.columns) == ["delta", "phi", "omega", "lateral_velocity", "speed"]
    np.testing.assert_array_equal(features["delta"], frame["steering"])
    assert features.attrs["steering"] == "steering"
    measured = steering_features(frame)  # the default: what the steering sensor read
    np.testing.assert_array_equal(measured["delta"], frame["sensor_steering"])
    assert measured.attrs["steering"] == "sensor_steering"
    assert not np.array_equal(measured["delta"], features["delta"])
    with pytest.raises(ValueError, match="steering must be one of"):
        steering_features(frame, steering="true")
    y, th = frame["lateral_offset"].to_numpy(), frame["heading"].to_numpy()
    assert np.isnan(features.loc[0, ["phi", "omega", "lateral_velocity", "speed"]]).all()
    np.testing.assert_allclose(features["phi"][1:], -(th + np.arctan(y / 6.2))[:-1], atol=1e-15)
    np.testing.assert_allclose(features["omega"][1:], -(th + np.arctan(y / 20.0))[:-1], atol=1e-15)
    np.testing.assert_array_equal(features["lateral_velocity"][1:], frame["lateral_velocity"][:-1])
    assert features.attrs["near_distance"] == 6.2
    assert features.attrs["decision_lag"] == 1
    assert features.attrs["dt"] == pytest.approx(0.01)
    same_row = steering_features(frame, decision_lag=0, near=5.0, far=15.0)
    np.testing.assert_allclose(same_row["phi"], -(th + np.arctan(y / 5.0)), atol=1e-15)


def test_features_use_the_road_named_in_the_recording_metadata():
    frame = _frame(curvature=1 / 250.0)
    frame["station"] = 260.0 + np.arange(len(frame)) * 0.15
    frame.attrs = {"config": {"track": "curved", "road": {"lane_width": 3.6}}}
    assert road_of_frame(frame).name == "curved"
    by_metadata = steering_features(frame)
    by_argument = steering_features(frame, road=curved_road())
    pd.testing.assert_frame_equal(by_metadata, by_argument)
    frame.attrs = {}
    with pytest.warns(UserWarning, match="road_curvature"):
        steering_features(frame)


def test_features_need_the_recording_columns():
    with pytest.raises(ValueError, match="lateral_offset"):
        steering_features(pd.DataFrame({"steering": [0.0]}))
    with pytest.raises(ValueError, match="decision_lag"):
        steering_features(_frame(), decision_lag=-1)
