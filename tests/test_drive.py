"""hasa-drive: the drive loop with a virtual wheel, pauses and hot-plug, crash safety, calibrate."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from _input_helpers import virtual_or_skip

from hasa_cli.drive import EXIT_NO_SCREEN, main
from hasa_env.devices import InputManager, JoystickCalibration, load_calibration
from hasa_env.devices.calibration import shipped_calibration
from hasa_env.devices.calibrator import calibrate
from hasa_env.devices.virtual import VirtualJoystick
from hasa_env.drivers import SyntheticDriver, population
from hasa_env.recording import load_recording
from hasa_env.recording.raw_inputs import load_raw_inputs, raw_inputs_path
from hasa_env.session import DriveSession, DriveSettings, VirtualWheelDriver

# one int16 step of a G29 axis at the road wheel: 450 deg / 32767 / 15
QUANTUM = math.radians(450.0) / 32767 / 15.0


def _g29_for(wheel: VirtualJoystick) -> JoystickCalibration:
    g29 = shipped_calibration("g29")
    fields = {k: getattr(g29, k) for k in g29.__dataclass_fields__ if k != "device"}
    return JoystickCalibration(**{**fields, "match_names": (wheel.name,)})


def _session(tmp_path, pg, wheel, hook_extra=None, seconds=3.0, driver="2", **settings):
    profile = _g29_for(wheel)
    inputs = InputManager(profiles=[profile], pygame_module=pg)
    params = {p.name: p for p in population("paper", seed=0)}[driver]
    # a foot at rest (no pedal remnant): the pedals' raw reading at rest is checked below
    params = params.with_speed(dataclasses.replace(params.speed, pedal_noise=0.0))
    wheel_driver = VirtualWheelDriver(wheel, SyntheticDriver(params), profile)

    def hook(session):
        wheel_driver(session)
        if hook_extra is not None:
            hook_extra(session)

    s = DriveSettings(
        participant="p01", seconds=seconds, runs=1, output=tmp_path, seed=11, **settings
    )
    messages: list[str] = []
    session = DriveSession(
        s, inputs, realtime=False, hook=hook, log=messages.append, max_idle_iterations=1000
    )
    return session, wheel_driver, messages


def test_without_a_screen_hasa_drive_says_so_and_exits_nonzero(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    code = main(["--participant", "p01", "--output", str(tmp_path)])
    assert code == EXIT_NO_SCREEN != 0
    err = capsys.readouterr().err
    assert "no screen" in err and "SDL_VIDEODRIVER=dummy" in err and "hasa-replay" in err
    assert not any(tmp_path.iterdir())


def test_scripted_drive_with_a_virtual_wheel_is_reproduced_by_hasa_replay(tmp_path, pg, capsys):
    wheel = virtual_or_skip(VirtualJoystick.g29)
    try:
        session, driver, _ = _session(tmp_path, pg, wheel, seconds=5.0)
        results = session.run()
    finally:
        wheel.detach()
    assert len(results) == 1 and results[0].steps == 500 and results[0].end_reason == "truncated"
    rec = load_recording(results[0].path)
    assert rec.path.parent == tmp_path / "p01" and rec.complete and rec.steps == 500
    meta = rec.meta["metadata"]
    assert meta["participant"] == "p01" and meta["input"]["source_at_start"].startswith("joystick:")
    assert rec.meta["config"]["initial_state"]["lateral_offset"] == -0.5
    assert rec.data["lateral_offset"].iloc[0] == -0.5 and rec.data["speed"].iloc[0] == 15.0
    assert rec.meta["config"]["scenario"] == meta["protocol"]["scenario"] == "paper"
    # what the driver asked for reached the env through SDL, up to the axis' int16 resolution
    assert sorted(driver.commands) == list(range(500))
    commanded = np.array([driver.commands[k][0] for k in range(500)])
    recorded = rec.data["steering"].to_numpy()[1:]
    assert np.max(np.abs(recorded - commanded)) <= QUANTUM
    assert np.ptp(recorded) > 50 * QUANTUM  # the wheel really turned
    raw = load_raw_inputs(rec.path)
    assert len(raw) == 500 and list(raw["step"]) == list(range(1, 501))
    assert raw["source"].str.startswith("joystick:").all()
    assert np.array_equal(raw["road_wheel_angle"].to_numpy(), recorded)  # bit for bit
    assert np.allclose(raw["raw_throttle"], 1.0, atol=1e-4)  # G29 pedals at rest read +1
    # hasa-replay re-simulates the recorded actions and finds the same trajectory bit for bit
    from hasa_cli.replay import main as replay_main

    capsys.readouterr()
    assert replay_main([str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "replay matches the recording bit for bit (501 rows)" in out


def test_unplugging_mid_run_pauses_falls_back_to_the_keyboard_and_records_no_junk(tmp_path, pg):
    wheel = virtual_or_skip(VirtualJoystick.g29)
    spare: list[VirtualJoystick] = []
    events: list[tuple[int, str]] = []

    def script(session):
        if session.state == "driving" and session.steps == 100 and not events:
            wheel.set_axis(2, -1.0)  # full throttle as the cable goes: must not leak into the run
            wheel.detach()
            events.append((session.steps, "unplugged"))
        elif session.state == "paused" and len(events) == 1:
            assert "keyboard" in session.message
            pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_SPACE, mod=0))
            events.append((session.steps, "space"))
        elif session.state == "driving" and session.steps == 200 and len(events) == 2:
            spare.append(virtual_or_skip(VirtualJoystick.g29))  # plugged in again
            wheel_driver.wheel = spare[0]
            events.append((session.steps, "plugged"))
        elif session.state == "paused" and len(events) == 3:
            pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_SPACE, mod=0))
            events.append((session.steps, "space"))

    try:
        session, wheel_driver, messages = _session(
            tmp_path, pg, wheel, hook_extra=script, seconds=3.0
        )
        session.inputs.profiles = [_g29_for(wheel)]
        results = session.run()
    finally:
        wheel.detach()
        for w in spare:
            w.detach()
    assert [e[1] for e in events] == ["unplugged", "space", "plugged", "space"]
    assert any("disconnected" in m for m in messages)
    rec = load_recording(results[0].path)
    assert rec.steps == 300  # paused time is not recorded
    raw = load_raw_inputs(rec.path)
    source = raw["source"].to_numpy()
    assert all(s.startswith("joystick:") for s in source[:100])
    assert all(s == "keyboard" for s in source[100:200])
    assert all(s.startswith("joystick:") for s in source[200:])
    acc = rec.data["acceleration"].to_numpy()
    assert np.all(acc[101:201] == 0.0)  # keyboard, no key held: no throttle, no junk brake
    assert np.isnan(raw["raw_steering"].to_numpy()[100:200]).all()
    speed = rec.data["speed"].to_numpy()
    assert speed[200] == pytest.approx(speed[100])
    steer = rec.data["steering"].to_numpy()
    # the keyboard starts from its own (zero) angle: no jump to a stale or re-centred wheel value
    assert steer[101] == 0.0


def test_escape_mid_run_keeps_every_completed_step(tmp_path, pg):
    wheel = virtual_or_skip(VirtualJoystick.g29)

    def script(session):
        if session.state == "driving" and session.steps == 50:
            pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_ESCAPE, mod=0))

    try:
        session, _, _ = _session(tmp_path, pg, wheel, hook_extra=script, seconds=3.0)
        results = session.run()
    finally:
        wheel.detach()
    rec = load_recording(results[0].path)
    assert rec.steps == 50 and rec.complete and rec.meta["end_reason"] == "stopped"
    assert len(load_raw_inputs(rec.path)) == 50
    assert session.state == "quit"


def test_an_exception_mid_run_keeps_every_completed_step(tmp_path, pg):
    wheel = virtual_or_skip(VirtualJoystick.g29)

    def script(session):
        if session.state == "driving" and session.steps == 80:
            raise RuntimeError("simulated crash")

    try:
        session, _, _ = _session(tmp_path, pg, wheel, hook_extra=script, seconds=3.0)
        with pytest.raises(RuntimeError, match="simulated crash"):
            session.run()
    finally:
        wheel.detach()
    (csv,) = sorted((tmp_path / "p01").glob("*.csv"))
    rec = load_recording(csv)
    assert rec.steps == 80 and rec.meta["end_reason"] == "stopped"
    assert len(load_raw_inputs(csv)) == 80


@pytest.mark.slow
def test_a_killed_process_keeps_every_completed_step(tmp_path):
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}
    cmd = [
        sys.executable,
        "-m",
        "hasa_cli.drive",
        "synthetic",
        "--seconds",
        "600",
        "--output",
        str(tmp_path),
    ]
    cmd += ["--participant", "killed", "--seed", "5", "--driver", "2"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    csv = tmp_path / "killed" / "run_000.csv"
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if csv.exists() and csv.stat().st_size > 100_000:
                break
            time.sleep(0.05)
        else:
            pytest.fail("the synthetic drive did not start writing")
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load_recording(csv)
    assert not rec.complete and rec.steps > 100
    raw = load_raw_inputs(csv)
    assert len(raw) >= rec.steps - 1
    from hasa_env.recording import compare_recordings, replay

    assert compare_recordings(rec.data, replay(rec)) is None  # every kept step is genuine


def test_real_time_loop_paces_physics_by_the_simulation_clock(tmp_path, pg):
    display = pg.display.set_mode((320, 180))
    inputs = InputManager(use_joystick=False, pygame_module=pg)
    frames = []

    posted = []

    def script(session):
        if session.state == "idle" and not posted:
            pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_SPACE, mod=0))
            pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_LEFT, mod=0))
            posted.append(True)

    settings = DriveSettings(
        participant="rt", seconds=0.5, runs=1, output=tmp_path, seed=1, countdown=0.2
    )
    session = DriveSession(
        settings, inputs, display=display, realtime=True, hook=script, fps=60, log=lambda m: None
    )
    original = session._draw

    def counting_draw(info, message=None):
        frames.append(info["time"])
        original(info, message)

    session._draw = counting_draw
    start = time.perf_counter()
    results = session.run()
    elapsed = time.perf_counter() - start
    session.close()
    assert results[0].steps == 50  # 0.5 s at 100 Hz, whatever the frame rate
    assert elapsed >= 0.5 + 0.2 - 0.02  # run in real time after the countdown
    assert elapsed < 10.0  # generous: a loaded CI machine is slow, but not this slow
    driving = [t for t in frames if t > 0]
    assert (
        5 <= len(driving) <= 45
    )  # ~60 fps for 0.5 s (fewer on a loaded machine): not one per step
    rec = load_recording(results[0].path)
    assert rec.data["steering"].iloc[-1] > 0.0  # the held left key steered left
    raw = load_raw_inputs(rec.path)
    assert raw["wall_time"].iloc[-1] == pytest.approx(0.5, abs=0.15)


def test_calibrate_finds_the_axes_by_movement_and_writes_a_valid_file(tmp_path, pg):
    # a wheel whose pedal axes come in another order than the shipped G29 profile's
    wheel = virtual_or_skip(
        lambda: VirtualJoystick(num_axes=4, num_buttons=4, name="Racing Wheel (other order)")
    )
    for axis in (1, 2, 3):
        wheel.set_axis(axis, 1.0)
    lines: list[str] = []
    refused = []

    def space():
        pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_SPACE, mod=0))

    def log(line: str) -> None:
        lines.append(line)
        if line.startswith("Step 1/5"):
            wheel.set_axis(0, 0.02)
            space()
        elif line.startswith("Step 2/5") and not refused:
            space()  # confirmed without turning: refused, asked again
            refused.append(True)
        elif "no axis moved" in line:
            wheel.set_axis(0, -0.98)
            space()
        elif line.startswith("Step 3/5"):
            wheel.set_axis(0, 0.97)
            space()
        elif line.startswith("Step 4/5"):
            wheel.set_axis(0, 0.0)
            wheel.set_axis(3, -0.99)  # throttle on axis 3
            space()
        elif line.startswith("Step 5/5"):
            wheel.set_axis(3, 1.0)
            wheel.set_axis(1, -1.0)  # brake on axis 1
            space()

    out = tmp_path / "cal.json"
    try:
        code = calibrate(
            out, wheel_range_deg=900.0, steering_ratio=15.0, timeout=20.0, log=log, pygame_module=pg
        )
    finally:
        wheel.detach()
    assert code == 0, lines
    assert any("no axis moved" in line for line in lines)
    cal = load_calibration(out)
    assert isinstance(cal, JoystickCalibration)
    assert (cal.steering.axis, cal.throttle.axis, cal.brake.axis) == (0, 3, 1)
    assert cal.steering.centre == pytest.approx(0.02, abs=1e-4)
    assert cal.steering.left == pytest.approx(-0.98, abs=1e-4)
    assert cal.throttle.rest == pytest.approx(1.0, abs=1e-4) and cal.throttle.full == pytest.approx(
        -0.99, abs=1e-4
    )
    assert cal.match_names == ("Racing Wheel (other order)",)
    assert cal.road_wheel_angle(-0.98) == pytest.approx(math.radians(30.0))
    assert json.loads(out.read_text())["format"] == "hasa_env input calibration"


def test_synthetic_command_labels_its_recordings(tmp_path, capsys):
    code = main(
        ["synthetic", "--seconds", "1", "--output", str(tmp_path), "--driver", "2", "--seed", "4"]
    )
    assert code == 0
    (csv,) = sorted(tmp_path.rglob("run_*.csv"))
    rec = load_recording(csv)
    meta = rec.meta["metadata"]
    assert meta["synthetic"] is True and meta["synthetic_driver"]["driver"] == "2"
    assert "Not a human" in meta["synthetic_driver"]["description"]
    assert rec.steps == 100 and raw_inputs_path(csv).exists()
    assert csv.parent.name == "synthetic-paper-0-2"


def test_settings_are_validated(tmp_path):
    with pytest.raises(ValueError, match=r"drive setting 'participant' must be a string of at"):
        DriveSettings(participant="../escape", output=tmp_path)
    with pytest.raises(ValueError, match=r"at most 64 characters .* \(65 characters\)$"):
        DriveSettings(participant="p" * 65, output=tmp_path)
    assert DriveSettings(participant="p" * 64, output=tmp_path).participant == "p" * 64
    with pytest.raises(ValueError, match="drive setting 'runs' must be a positive integer, got 0"):
        DriveSettings(participant="p", runs=0)
    with pytest.raises(SystemExit):
        main(["--participant", "p", "--bias", "left"])
    s = DriveSettings(participant="p", bias=-1.8, output=Path("x"))
    assert s.reset_options() == {"steering": 0.0, "bias": -1.8}  # the start: in the config
    start = s.env_config()["initial_state"]
    assert (start["lateral_offset"], start["speed"], start["heading"]) == (-0.5, 15.0, 0.0)
    assert s.env_config()["time_limit"] == 30.0 and s.env_config()["action"]["type"] == "physical"
    assert s.env_config()["scenario"] == "paper"


def test_settings_scenario_lies_under_the_options_given():
    with pytest.raises(ValueError, match=r"drive setting 'scenario' = 'nope' is not allowed: one "):
        DriveSettings(participant="p", scenario="nope")
    with pytest.raises(ValueError, match=r"'config.scenario' = 'lane_shift' differs from the "):
        DriveSettings(participant="p", config={"scenario": "lane_shift"})
    with pytest.raises(
        ValueError, match=r"'lateral_offset' = 12.0 is out of range: allowed \[-10, 10\] m"
    ):
        DriveSettings(participant="p", lateral_offset=12.0)
    late = DriveSettings(participant="p", scenario="late_ambiguity").env_config()
    assert late["initial_state"]["speed"] == 25.0 and late["initial_state"]["between_hypotheses"]
    given = DriveSettings(
        participant="p", scenario="late_ambiguity", speed=12.0, lateral_offset=0.2
    )
    start = given.env_config()["initial_state"]
    assert (start["speed"], start["lateral_offset"], start["between_hypotheses"]) == (
        12.0,
        0.2,
        False,
    )
    close = DriveSettings(participant="p", scenario="close_hypotheses", config={"markings": {
        "hypotheses": [0.0, -1.8]}}).env_config()  # fmt: skip
    assert close["markings"]["hypotheses"] == [0.0, -1.8]  # the user's key wins
    assert close["initial_state"]["lateral_offset_std"] == 0.25  # the scenario's others apply
    assert given.reset_options() == {"steering": 0.0}


def _synthetic_recording(tmp_path, *args):
    out = tmp_path / "-".join(a.strip("-") for a in args)
    assert main(["synthetic", "--output", str(out), "--seed", "4", *args]) == 0
    (csv,) = sorted(out.rglob("run_*.csv"))
    return load_recording(csv)


def test_synthetic_drive_in_a_lane_shift_follows_the_driven_lane(tmp_path):
    rec = _synthetic_recording(tmp_path, "--scenario", "lane_shift", "--seconds", "25")
    assert rec.config["scenario"] == "lane_shift"
    assert rec.config["road"]["lane_shifts"] == [
        {"station": 150.0, "length": 65.0, "offset": 1.8, "toward": "other_hypothesis"}
    ]
    assert rec.path.parent.name == "synthetic-paper-0-Ill-lane_shift"
    d = rec.data
    after = d["station"] > 260.0  # well after the shift's end at 215 m
    assert after.sum() > 500
    # the recording's road moves the lane toward the other hypothesis of the recorded bias
    bias = float(d["bias"].iloc[0])
    shifted = float(rec.road.driven_offset(300.0, bias))
    assert abs(shifted) == 1.8 and np.sign(shifted) == (1.0 if bias == -1.8 else -1.0)
    assert abs(d["lateral_offset"][after].mean() - shifted) < 0.3
    assert abs(d["lateral_offset"][d["station"] < 140.0].mean()) < 0.6  # before: the old lane


def test_synthetic_late_ambiguity_starts_between_the_hypotheses_unless_told(tmp_path):
    common = ("--scenario", "late_ambiguity", "--seconds", "0.1", "--bias")
    for bias, halfway in (("0", -0.9), ("-1.8", 0.9)):
        rec = _synthetic_recording(tmp_path, *common, bias)
        first = rec.data.iloc[0]
        assert first["lateral_offset"] == pytest.approx(halfway) and first["speed"] == 25.0
        assert first["heading"] == pytest.approx(0.02 * (1 if halfway > 0 else -1))  # to the ghost
        assert rec.config["scenario"] == "late_ambiguity"
    rec = _synthetic_recording(tmp_path, *common, "0", "--lateral-offset", "0.2", "--speed", "12")
    first = rec.data.iloc[0]
    assert first["lateral_offset"] == 0.2 and first["speed"] == 12.0
    assert rec.meta["metadata"]["protocol"]["between_hypotheses"] is False
    assert rec.meta["metadata"]["protocol"]["heading_toward_other"] == 0.02


def test_synthetic_driver_keeps_the_scenarios_preferred_offset(tmp_path):
    from hasa_env.scenarios import scenario_drivers

    rec = _synthetic_recording(
        tmp_path, "--scenario", "off_centre_drivers", "--seconds", "0.1", "--population-seed", "3"
    )
    (expected,) = [
        p for p in scenario_drivers(population("paper", seed=3), "off_centre_drivers", 3)
        if p.name == "Ill"
    ]  # fmt: skip
    params = rec.meta["metadata"]["synthetic_driver"]["params"]
    assert 0.2 <= abs(params["preferred_offset"]) <= 0.5
    assert params["preferred_offset"] == expected.preferred_offset
    assert rec.config["markings"]["hypotheses"] == [0.0, -0.8]
    with pytest.raises(SystemExit):
        main(["synthetic", "--scenario", "nope"])


def test_an_estimator_runs_alongside_and_feeds_the_hud(tmp_path, pg):
    pytest.importorskip("estimators.wrappers")
    from estimators.wrappers import estimator_wrapper
    from hasa_env.steering import GeneralizedModel

    wheel = virtual_or_skip(VirtualJoystick.g29)
    seen = []

    def script(session):
        if session.state == "driving" and session.info is not None:
            seen.append(session.info.get("estimate_weights"))

    try:
        session, _, _ = _session(tmp_path, pg, wheel, hook_extra=script, seconds=1.0, bias=-1.8)
        session.env_wrapper = estimator_wrapper(GeneralizedModel.paper(), 15.0)
        results = session.run()
    finally:
        wheel.detach()
    assert len(seen) >= 100 and all(w is not None and len(w) == 2 for w in seen)
    assert np.allclose([sum(w) for w in seen], 1.0)
    rec = load_recording(results[0].path)
    assert rec.steps == 100 and "estimate_weights" not in rec.data.columns


def test_raw_input_file_never_overwrites_an_orphaned_one(tmp_path):
    from hasa_env.devices import InputReading
    from hasa_env.recording.raw_inputs import RawInputWriter

    path = tmp_path / "run_000.inputs.tsv"
    path.write_text("old data\n")
    writer = RawInputWriter(path)
    writer.write(1, 0.01, 0.0, InputReading("keyboard", 0.01, 0.01, 0.0, 0.0, 0.0))
    writer.close()
    (orphan,) = tmp_path.glob("run_000.inputs.tsv.orphaned-*")
    assert orphan.read_text() == "old data\n"
    frame = load_raw_inputs(path)
    assert list(frame["step"]) == [1] and frame["road_wheel_angle"].iloc[0] == 0.01
    assert np.isnan(frame["raw_steering"].iloc[0]) and frame["source"].iloc[0] == "keyboard"


def test_free_drive_takes_a_scenario(tmp_path):
    from hasa_cli.drive import _drive_parser, _drive_setup

    def settings(*extra):
        argv = ["--participant", "p", "--output", str(tmp_path), "--scenario", "late_ambiguity"]
        return _drive_setup(_drive_parser().parse_args([*argv, *extra]), print)[0]

    start = settings().env_config()["initial_state"]
    assert settings().scenario == "late_ambiguity"
    assert start["speed"] == 25.0 and start["between_hypotheses"] is True
    start = settings("--lateral-offset", "-0.5").env_config()["initial_state"]
    assert start["lateral_offset"] == -0.5 and start["between_hypotheses"] is False
    with pytest.raises(SystemExit):
        main(["--participant", "p", "--scenario", "nope"])
