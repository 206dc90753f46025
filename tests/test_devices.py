"""Input layer: calibration files and mapping, keyboard and joystick sources, hot-plug.

The joystick tests drive a real SDL virtual joystick (SDL_JoystickAttachVirtual
in pygame's own SDL library, through ctypes); they are skipped only if that
library cannot be found.
"""

from __future__ import annotations

import json
import math
import sys
import types

import pytest
from _input_helpers import virtual_or_skip

from hasa_env.devices import (
    CalibrationError,
    InputManager,
    JoystickCalibration,
    KeyboardCalibration,
    PedalAxis,
    SteeringAxis,
    load_calibration,
    parse_calibration,
    save_calibration,
    shipped_calibration,
    shipped_calibration_path,
)
from hasa_env.devices.virtual import VirtualJoystick

G29_WHEEL_LOCK = math.radians(450.0)


@pytest.fixture
def wheel(pg):
    w = virtual_or_skip(VirtualJoystick.g29)
    yield w
    w.detach()


def _g29_dict() -> dict:
    return json.loads(shipped_calibration_path("g29").read_text())


# ------------------------------------------------------------ calibration files
def test_shipped_calibrations_resolve_from_the_package_not_the_working_directory(
    tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    g29 = shipped_calibration("g29")
    assert isinstance(g29, JoystickCalibration)
    assert shipped_calibration_path("g29").parent.name == "data"
    assert shipped_calibration_path("g29").parent.parent.name == "hasa_env"
    assert g29.wheel_range_deg == 900.0 and g29.steering_ratio == 15.0
    assert (g29.throttle.rest, g29.throttle.full) == (1.0, -1.0)  # G29 pedals rest at +1
    assert (g29.brake.rest, g29.brake.full) == (1.0, -1.0)
    assert isinstance(shipped_calibration("keyboard"), KeyboardCalibration)
    assert isinstance(shipped_calibration("gamepad"), JoystickCalibration)
    with pytest.raises(ValueError, match="unknown shipped calibration"):
        shipped_calibration("g27")


def test_g29_steering_mapping_is_linear_with_left_positive_and_ratio_15():
    g29 = shipped_calibration("g29")
    # SDL reports a G29's full left lock as -1: +450 deg at the wheel, +30 deg at the road wheel
    assert g29.steering_wheel_angle(-1.0) == pytest.approx(G29_WHEEL_LOCK)
    assert g29.road_wheel_angle(-1.0) == pytest.approx(math.radians(30.0))
    assert g29.road_wheel_angle(0.5) == pytest.approx(-math.radians(15.0))
    assert g29.road_wheel_angle(-0.25) == pytest.approx(math.radians(7.5))
    assert g29.road_wheel_angle(0.0) == 0.0 and math.copysign(1.0, g29.road_wheel_angle(0.0)) == 1.0
    assert g29.road_wheel_angle(-1.00003) == pytest.approx(
        math.radians(30.0)
    )  # pygame's -32768 / 32767
    for angle in (-0.3, -0.01, 0.0, 0.002, 0.2):
        assert g29.road_wheel_angle(g29.raw_for_road_wheel_angle(angle)) == pytest.approx(
            angle, abs=1e-12
        )


def test_pedal_polarity_and_deadzone():
    pedal = PedalAxis(axis=2, rest=1.0, full=-1.0, deadzone=0.02)
    assert pedal.travel(1.0) == 0.0
    assert pedal.travel(-1.0) == 1.0
    assert pedal.travel(0.97) == 0.0  # 1.5 % travel is inside the 2 % deadzone
    assert pedal.travel(0.0) == pytest.approx((0.5 - 0.02) / 0.98)
    assert pedal.travel(1.2) == 0.0 and pedal.travel(-1.5) == 1.0
    for u in (0.0, 0.1, 0.5, 1.0):
        assert pedal.travel(pedal.raw_for_travel(u)) == pytest.approx(u)
    g29 = shipped_calibration("g29")
    assert g29.acceleration(1.0, 0.0) == 3.0 and g29.acceleration(0.0, 1.0) == -6.0


def test_steering_deadzone_and_asymmetric_calibration():
    axis = SteeringAxis(axis=0, centre=0.1, left=-0.9, right=0.9, deadzone=0.1)
    assert axis.travel(0.1) == 0.0
    assert axis.travel(0.05) == 0.0  # 5 % of the left travel: inside the deadzone
    assert axis.travel(-0.9) == 1.0 and axis.travel(0.9) == -1.0
    assert axis.travel(-0.4) == pytest.approx((0.5 - 0.1) / 0.9)
    assert axis.travel(0.5) == pytest.approx(-(0.5 - 0.1) / 0.9)


@pytest.mark.parametrize(
    ("edit", "field", "fragment"),
    [
        (lambda d: d["throttle"].update(rest=2.0), "throttle.rest", "allowed [-1, 1]"),
        (lambda d: d.update(wheel_range_deg=5.0), "wheel_range_deg", "allowed [10, 3600]"),
        (lambda d: d.update(steering_ratio=0), "steering_ratio", "allowed [0.1, 100]"),
        (lambda d: d["brake"].update(axis=-1), "brake.axis", "integers [0, 63]"),
        (lambda d: d["brake"].update(axis=1.5), "brake.axis", "must be an integer"),
        (lambda d: d["steering"].update(deadzone=0.9), "steering.deadzone", "allowed [0, 0.5]"),
        (lambda d: d.update(colour="red"), "colour", "unknown field 'colour' (allowed keys here"),
        (lambda d: d["steering"].pop("left"), "steering.left", "missing"),
        (lambda d: d["steering"].update(left=0.5), "steering.left", "opposite sides"),
        (lambda d: d["brake"].update(full=0.95), "brake.full", "must differ from"),
        (lambda d: d["throttle"].update(axis=0), "steering.axis", "also the throttle axis"),
        (lambda d: d["brake"].update(axis=2), "brake.axis", "also the throttle axis"),
        (lambda d: d.update(version=2), "version", "= 2 is not allowed: only 1"),
        (lambda d: d.update(device="pedals"), "device", "one of 'joystick', 'keyboard'"),
        (lambda d: d.update(match_names="G29"), "match_names", "list of non-empty strings"),
    ],
)
def test_invalid_calibration_files_name_file_field_and_allowed_range(
    tmp_path, edit, field, fragment
):
    data = _g29_dict()
    edit(data)
    path = tmp_path / "wheel.json"
    path.write_text(json.dumps(data))
    with pytest.raises(CalibrationError) as info:
        load_calibration(path)
    message = str(info.value)
    assert str(path) in message and info.value.field == field
    assert f"'{field}'" in message
    assert fragment in message


def test_unreadable_calibration_files(tmp_path):
    with pytest.raises(CalibrationError, match="file not found"):
        load_calibration(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "hasa_env input calibration",\n "version": }')
    with pytest.raises(CalibrationError, match=r"bad.json: not valid JSON: .* line 2"):
        load_calibration(bad)
    with pytest.raises(
        CalibrationError, match=r"list.json: the document must be a mapping \(JSON object\)"
    ):
        parse_calibration([1, 2], "list.json")


def test_one_axis_for_both_pedals_needs_opposite_directions():
    gamepad = shipped_calibration("gamepad")
    assert gamepad.throttle.axis == gamepad.brake.axis
    assert gamepad.acceleration(gamepad.throttle.travel(-1.0), gamepad.brake.travel(-1.0)) == 3.0
    assert gamepad.acceleration(gamepad.throttle.travel(1.0), gamepad.brake.travel(1.0)) == -6.0
    data = gamepad.to_dict()
    data["brake"]["full"] = -1.0
    with pytest.raises(CalibrationError, match="opposite sides"):
        parse_calibration(data, "pad.json")


def test_save_and_load_round_trip(tmp_path):
    g29 = shipped_calibration("g29")
    path = save_calibration(g29, tmp_path / "sub" / "g29_copy.json")
    again = load_calibration(path)
    assert again.to_dict() == g29.to_dict()
    kb = shipped_calibration("keyboard")
    assert load_calibration(save_calibration(kb, tmp_path / "kb.json")).to_dict() == kb.to_dict()


# ----------------------------------------------------------------- keyboard
def _key(pg, key, down=True):
    return pg.event.Event(pg.KEYDOWN if down else pg.KEYUP, key=key, mod=0)


def test_keyboard_ramps_to_and_decays_from_the_steering_angle_with_posted_events(pg):
    manager = InputManager(use_joystick=False, pygame_module=pg)
    kb = manager.keyboard.calibration
    full = math.radians(kb.max_road_wheel_angle_deg)
    dt = 0.01
    pg.event.post(_key(pg, pg.K_LEFT))
    assert manager.poll() == []
    angles = [manager.read(dt).road_wheel_angle for _ in range(100)]
    steps_to_full = round(kb.ramp_time / dt)
    assert angles[steps_to_full // 2 - 1] == pytest.approx(full / 2)  # linear ramp
    assert angles[steps_to_full - 1] == pytest.approx(full)
    assert angles[-1] == pytest.approx(full)  # saturates
    pg.event.post(_key(pg, pg.K_LEFT, down=False))
    manager.poll()
    decay = [manager.read(dt).road_wheel_angle for _ in range(25)]
    assert decay[-1] == pytest.approx(full * math.exp(-25 * dt / kb.return_time_constant))
    # the other key ramps through zero to the right at the same rate
    pg.event.post(_key(pg, pg.K_d))
    manager.poll()
    reading = None
    for _ in range(200):
        reading = manager.read(dt)
    assert reading.road_wheel_angle == pytest.approx(-full)
    assert reading.source == "keyboard" and math.isnan(reading.raw_steering)
    # both held: no steering command, decays
    pg.event.post(_key(pg, pg.K_a))
    manager.poll()
    assert abs(manager.read(dt).road_wheel_angle) < full


def test_keyboard_pedals_and_control_notices(pg):
    manager = InputManager(use_joystick=False, pygame_module=pg)
    kb = manager.keyboard.calibration
    pg.event.post(_key(pg, pg.K_UP))
    manager.poll()
    assert manager.read(0.01).acceleration == kb.acceleration
    pg.event.post(_key(pg, pg.K_UP, down=False))
    pg.event.post(_key(pg, pg.K_DOWN))
    manager.poll()
    assert manager.read(0.01).acceleration == -kb.deceleration
    for key, kind in ((pg.K_SPACE, "confirm"), (pg.K_p, "pause"), (pg.K_ESCAPE, "quit")):
        pg.event.post(_key(pg, key))
        assert [n.kind for n in manager.poll()] == [kind]
    pg.event.post(pg.event.Event(pg.QUIT))
    assert [n.kind for n in manager.poll()] == ["quit"]


def test_unknown_key_name_is_a_clear_error(pg):
    kb = KeyboardCalibration(
        keys={"left": ("leftish",), "right": ("d",), "throttle": ("w",), "brake": ("s",)}
    )
    with pytest.raises(ValueError, match=r"keys.left.*'leftish'"):
        InputManager(kb, pygame_module=pg)


def test_axis_events_of_unknown_devices_are_ignored(pg):
    manager = InputManager(pygame_module=pg)
    pg.event.post(pg.event.Event(pg.JOYAXISMOTION, instance_id=4242, joy=4242, axis=0, value=-1.0))
    assert manager.poll() == []
    assert manager.read(0.01).source == "keyboard"
    assert manager.read(0.01).road_wheel_angle == 0.0


# -------------------------------------------------------- virtual joystick
def test_virtual_g29_hot_plug_mapping_and_pedal_polarity(pg, wheel):
    manager = InputManager(pygame_module=pg)
    notices = manager.poll()
    assert [n.kind for n in notices] == ["connected"]
    assert notices[0].instance_id == wheel.instance_id
    assert manager.active is not None and manager.active.instance_id == wheel.instance_id
    assert manager.active.calibration.name == "Logitech G29 Driving Force"  # chosen by name
    rest = manager.read(0.01)
    assert rest.source.startswith("joystick:") and rest.acceleration == 0.0
    assert rest.raw_throttle == pytest.approx(1.0, abs=1e-4) and rest.throttle == 0.0
    wheel.set_axis(0, -0.5)  # half way to the left lock
    wheel.set_axis(3, -1.0)  # brake pressed fully: the G29 reads -1
    manager.poll()
    r = manager.read(0.01)
    assert r.steering_wheel_angle == pytest.approx(0.5 * G29_WHEEL_LOCK, rel=1e-4)
    assert r.road_wheel_angle == pytest.approx(0.5 * G29_WHEEL_LOCK / 15.0, rel=1e-4)
    assert r.brake == 1.0 and r.acceleration == -6.0
    assert r.raw_brake == pytest.approx(-1.0, abs=1e-4) and r.raw_steering == pytest.approx(
        -0.5, abs=1e-4
    )
    wheel.set_axis(3, 1.0)
    wheel.set_axis(2, 0.0)  # throttle half pressed
    manager.poll()
    r = manager.read(0.01)
    assert r.brake == 0.0
    assert r.throttle == pytest.approx((0.5 - 0.02) / 0.98, abs=1e-4)
    assert r.acceleration == pytest.approx(3.0 * r.throttle)


def test_unplug_falls_back_to_the_keyboard_and_ignores_the_recentring_events(pg, wheel):
    manager = InputManager(pygame_module=pg)
    manager.poll()
    wheel.set_axis(0, 0.6)
    wheel.set_axis(2, -1.0)
    manager.poll()
    device = manager.active
    before = dict(device.axes)
    assert manager.read(0.01).acceleration == 3.0
    wheel.detach()
    events = pg.event.get()
    # SDL re-centres a removed joystick's axes (value 0) in the same batch as the removal
    recentring = [
        e for e in events if e.type == pg.JOYAXISMOTION and e.instance_id == device.instance_id
    ]
    assert any(e.value == 0.0 for e in recentring)
    notices = manager.handle_events(events)
    assert [n.kind for n in notices] == ["disconnected"]
    assert "keyboard" in notices[0].message
    assert device.axes == before  # the junk zeros never reached the device state
    assert manager.active is None and device.instance_id not in manager.devices
    r = manager.read(0.01)
    assert r.source == "keyboard" and r.acceleration == 0.0 and r.road_wheel_angle == 0.0
    # a late axis event of the unplugged device is ignored too
    pg.event.post(
        pg.event.Event(pg.JOYAXISMOTION, instance_id=device.instance_id, axis=0, value=-1.0)
    )
    assert manager.poll() == []
    assert manager.read(0.01).source == "keyboard"
    # plugged in again: a new instance id, picked up
    again = virtual_or_skip(VirtualJoystick.g29)
    try:
        notices = manager.poll()
        assert [n.kind for n in notices] == ["connected"]
        assert again.instance_id != device.instance_id
        assert manager.active.instance_id == again.instance_id
    finally:
        again.detach()


def test_pedals_count_as_at_rest_until_they_move(pg):
    # a G29 reports 0 for a pedal that has not moved since it was opened: that is not "half pressed"
    wheel = virtual_or_skip(
        lambda: VirtualJoystick(num_axes=4, name="Logitech G29 Driving Force Racing Wheel")
    )
    try:
        manager = InputManager(pygame_module=pg)
        manager.poll()
        assert manager.active is not None
        r = manager.read(0.01)
        assert r.acceleration == 0.0 and r.throttle == 0.0 and r.brake == 0.0
        wheel.set_axis(3, -1.0)
        manager.poll()
        assert manager.read(0.01).acceleration == -6.0
    finally:
        wheel.detach()


def test_a_device_too_small_for_its_profile_is_ignored_with_a_notice(pg):
    small = virtual_or_skip(
        lambda: VirtualJoystick(num_axes=2, name="Logitech G29 (two axes only)")
    )
    try:
        g29 = shipped_calibration("g29")
        manager = InputManager(profiles=[g29], pygame_module=pg)
        notices = manager.poll()
        assert [n.kind for n in notices] == ["ignored_device"]
        assert "has 2 axes" in notices[0].message and "needs 4" in notices[0].message
        assert manager.active is None
        small.set_axis(0, -1.0)
        manager.poll()
        assert manager.read(0.01).source == "keyboard"
    finally:
        small.detach()


def test_generic_gamepad_profile_for_unknown_devices_and_button_confirm(pg):
    pad = virtual_or_skip(
        lambda: VirtualJoystick(num_axes=2, num_buttons=4, name="Some Gamepad", joystick_type=1)
    )
    try:
        manager = InputManager(pygame_module=pg)
        manager.poll()
        assert manager.active.calibration.name == "generic joystick / gamepad"
        pad.set_axis(0, 1.0)  # stick right
        pad.set_axis(1, -1.0)  # stick forward: throttle
        manager.poll()
        r = manager.read(0.01)
        assert r.road_wheel_angle == pytest.approx(-math.radians(90.0 / 15.0), rel=1e-4)
        assert r.acceleration == pytest.approx(3.0)
        pad.set_button(1, True)
        assert [n.kind for n in manager.poll()] == ["confirm"]
    finally:
        pad.detach()


# ------------------------------------------------------------ force feedback
def test_force_feedback_without_evdev_is_reported_cleanly(monkeypatch):
    from hasa_env.devices.force_feedback import Autocentre, ForceFeedbackUnavailable

    monkeypatch.setitem(sys.modules, "evdev", None)
    monkeypatch.setattr(sys, "platform", "linux")
    with pytest.raises(ForceFeedbackUnavailable, match="evdev"):
        Autocentre("Logitech G29", 0.5)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        Autocentre("Logitech G29", 1.5)


def test_force_feedback_writes_the_autocentre_strength(monkeypatch):
    from hasa_env.devices.force_feedback import Autocentre, ForceFeedbackUnavailable

    writes = []

    class FakeDevice:
        def __init__(self, path):
            self.path = path
            self.name = {"/dev/input/event3": "Logitech G29 Driving Force Racing Wheel"}.get(
                path, "Keyboard"
            )

        def capabilities(self):
            return {21: []} if "G29" in self.name else {1: []}

        def write(self, kind, code, value):
            writes.append((kind, code, value))

        def close(self):
            writes.append("closed")

    fake = types.ModuleType("evdev")
    fake.ecodes = types.SimpleNamespace(EV_FF=21, FF_AUTOCENTER=0x61)
    fake.list_devices = lambda: ["/dev/input/event1", "/dev/input/event3"]
    fake.InputDevice = FakeDevice
    monkeypatch.setitem(sys.modules, "evdev", fake)
    monkeypatch.setattr(sys, "platform", "linux")
    spring = Autocentre("Logitech G29 Driving Force Racing Wheel", 0.5)
    assert writes == [(21, 0x61, round(0.5 * 0xFFFF))]
    spring.close()
    assert writes[-2:] == [(21, 0x61, 0), "closed"]
    with pytest.raises(ForceFeedbackUnavailable, match="no evdev device"):
        Autocentre("Thrustmaster T300", 0.5)
