"""The keyboard ramp is tuned with a model of a person pressing keys (docs/design.md §11, 23).

The shipped ramp (1.5 deg in 0.8 s, 0.15 s return) lets the modelled person
hold the lane where the earlier one (3 deg in 0.5 s, 0.25 s return) made
them swerve out of it, and an accidental 0.8 s press leaves far more time to
react before the car is off the road.
"""

from __future__ import annotations

import math

import pytest

from hasa_env.devices.calibration import KeyboardCalibration, shipped_calibration
from hasa_env.session.keyboard_person import (
    PREVIOUS_RAMP,
    KeyboardPerson,
    drive_with_keyboard,
    ramp_table,
)

SHIPPED = shipped_calibration("keyboard")


def test_the_shipped_ramp_numbers():
    assert isinstance(SHIPPED, KeyboardCalibration)
    assert (SHIPPED.max_road_wheel_angle_deg, SHIPPED.ramp_time, SHIPPED.return_time_constant) == (
        1.5,
        0.8,
        0.15,
    )
    assert KeyboardCalibration() == KeyboardCalibration(**{
        k: getattr(SHIPPED, k) for k in ("max_road_wheel_angle_deg", "ramp_time",
                                         "return_time_constant", "acceleration", "deceleration")
    })  # fmt: skip
    # 1.5 deg covers the curved track's tightest bend (120 m): L / R = 2.8 / 120 rad
    assert SHIPPED.max_road_wheel_angle > 2.8 / 120.0


def test_the_modelled_person_holds_the_lane_with_the_shipped_ramp_not_with_the_old_one():
    runs = [
        drive_with_keyboard(
            SHIPPED, KeyboardPerson(), track=track, speed=speed, seed=seed, seconds=20.0
        )  # fmt: skip
        for track in ("straight", "curved")
        for speed in (15.0, 20.0)
        for seed in (0, 1)
    ]
    assert all(r.in_lane for r in runs), [(r.left_road, r.max_offset) for r in runs]
    assert max(r.rms_offset for r in runs) < 0.3
    old = [
        drive_with_keyboard(PREVIOUS_RAMP, KeyboardPerson(), speed=20.0, seed=seed, seconds=20.0)
        for seed in (0, 1)
    ]
    assert not any(r.in_lane for r in old)  # it swerves out of the lane, or off the road


def test_an_accidental_press_leaves_time_to_react():
    for cal, earliest, latest in ((SHIPPED, 5.5, 7.0), (PREVIOUS_RAMP, 2.0, 3.0)):
        uncorrected = drive_with_keyboard(cal, None, seconds=20.0, mistake=0.8)
        assert uncorrected.left_road and earliest < uncorrected.seconds < latest
    corrected = drive_with_keyboard(SHIPPED, KeyboardPerson(), seconds=10.0, mistake=0.8)
    assert not corrected.left_road and corrected.max_offset < 2.5


def test_the_person_model_taps_for_small_errors_and_holds_for_large_ones():
    person = KeyboardPerson(perception_noise=0.0, reaction_time=0.0)
    person.reset(0, 0.01)
    info = {"time": 0.0, "speed": 15.0, "heading": 0.0, "lateral_offset": -0.2,
            "steering": 0.0, "road_curvature": 0.0}  # fmt: skip
    keys = [person.key({**info, "time": k * 0.01}) for k in range(15)]
    assert keys[0] == "left" and keys.count("left") == 5  # 0.05 s: the shortest tap
    person.reset(0, 0.01)
    far = {**info, "lateral_offset": 1.0}
    keys = [person.key({**far, "time": k * 0.01}) for k in range(15)]
    assert keys == ["right"] * 15  # held through the whole decision interval
    with pytest.raises(ValueError, match="decision_interval must be > 0"):
        KeyboardPerson(decision_interval=0.0)


def test_ramp_table_reports_each_calibration_and_speed():
    rows = ramp_table([SHIPPED], tracks=("straight",), speeds=(15.0,), seeds=(0,),
                      reaction_times=(0.25,), seconds=5.0)  # fmt: skip
    (row,) = rows
    assert row["runs"] == 1 and row["in_lane"] == 1 and row["left_road"] == 0
    assert row["ramp"] == "1.5 deg in 0.8 s, return 0.15 s"
    assert math.isfinite(row["mistake_corrected_max_offset"]) and row["mistake_off_road_at"] > 5
