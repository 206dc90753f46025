"""``hasa-drive calibrate``: measure a wheel's axes (centre, locks, pedals) by movement.

:class:`Calibrator` is the dialogue as a state machine over pygame events
(testable headless); :func:`calibrate` runs it on the first joystick found
and writes the calibration file (:mod:`hasa_env.devices.calibration`).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hasa_env.devices.calibration import (
    JoystickCalibration,
    PedalAxis,
    SteeringAxis,
    save_calibration,
)
from hasa_env.devices.sources import init_pygame_input, no_screen_reason

__all__ = ["CALIBRATION_STEPS", "NO_DEVICE", "Calibrator", "calibrate"]

NO_DEVICE = 3
"""Exit code when no joystick turns up within the timeout: the machine lacks something."""


@dataclass
class _CalibrationStep:
    key: str
    prompt: str


CALIBRATION_STEPS = (
    _CalibrationStep(
        "centre",
        "Press and release every pedal once, then centre the wheel, take your feet off the pedals "
        "and press a wheel button.",
    ),
    _CalibrationStep("left", "Turn the wheel to the LEFT lock, hold it, and press a wheel button."),
    _CalibrationStep(
        "right", "Turn the wheel to the RIGHT lock, hold it, and press a wheel button."
    ),
    _CalibrationStep(
        "throttle", "Centre the wheel, press the THROTTLE fully, hold it, and press a wheel button."
    ),
    _CalibrationStep(
        "brake", "Release the throttle, press the BRAKE fully, hold it, and press a wheel button."
    ),
)


class Calibrator:
    """``hasa-drive calibrate`` as a state machine over pygame events (testable headless).

    It snapshots every axis of the joystick at each confirmed step
    (:data:`CALIBRATION_STEPS`): the centre / rest position, each lock and each
    pedal pressed fully. The steering axis is the one that moved most between
    the two locks; throttle and brake are the axes (other than steering) that
    moved most from rest when pressed, so the axis order of any wheel or
    operating system is found, not assumed.

    Args:
        joystick: an open ``pygame.joystick.Joystick``.
        min_travel: smallest change (of the normalised axis value) accepted as a movement.
    """

    def __init__(self, joystick: Any, min_travel: float = 0.3) -> None:
        self.joystick = joystick
        self.instance_id = int(joystick.get_instance_id())
        self.min_travel = min_travel
        self.snapshots: dict[str, list[float]] = {}
        self.step = 0
        self.error: str | None = None

    @property
    def done(self) -> bool:
        return self.step >= len(CALIBRATION_STEPS)

    @property
    def prompt(self) -> str:
        if self.done:
            return "Calibration complete."
        return (
            f"Step {self.step + 1}/{len(CALIBRATION_STEPS)}: {CALIBRATION_STEPS[self.step].prompt}"
        )

    def _axes(self) -> list[float]:
        return [float(self.joystick.get_axis(i)) for i in range(self.joystick.get_numaxes())]

    def handle_events(self, events: Sequence[Any], pygame_module: Any) -> bool:
        """Process events; this joystick's buttons (or SPACE / Enter) confirm the current step.

        Returns True when a step was taken (see :attr:`error` for a rejected one).
        """
        pg = pygame_module
        confirmed = False
        for e in events:
            if e.type == pg.JOYBUTTONDOWN and int(e.instance_id) == self.instance_id:
                confirmed = True
            elif e.type == pg.KEYDOWN and e.key in (pg.K_SPACE, pg.K_RETURN):
                confirmed = True
        if not confirmed or self.done:
            return False
        return self.confirm()

    def confirm(self) -> bool:
        """Snapshot the axes for the current step; False (see :attr:`error`) if implausible."""
        key = CALIBRATION_STEPS[self.step].key
        axes = self._axes()
        self.error = None
        if key != "centre":
            centre = self.snapshots["centre"]
            moved = [abs(a - c) for a, c in zip(axes, centre, strict=True)]
            if max(moved, default=0.0) < self.min_travel:
                self.error = (
                    f"no axis moved by {self.min_travel} or more from the centre position; "
                    "try again"
                )
                return False
        self.snapshots[key] = axes
        self.step += 1
        if self.done:
            try:
                self._assign()
            except ValueError as exc:
                self.error = str(exc)
                self.step = 0
                self.snapshots.clear()
                return False
        return True

    def _assign(self) -> None:
        snap = self.snapshots
        centre, left, right = snap["centre"], snap["left"], snap["right"]
        steering = int(np.argmax(np.abs(np.subtract(left, right))))
        if abs(left[steering] - right[steering]) < 2 * self.min_travel:
            raise ValueError(
                "the wheel's locks were not told apart: no axis moved between them; start again"
            )
        if (left[steering] - centre[steering]) * (right[steering] - centre[steering]) >= 0:
            raise ValueError(
                "the left and right locks are on the same side of the centre; start again"
            )

        def pedal(key: str, exclude: set[int]) -> int:
            moved = np.abs(np.subtract(snap[key], centre))
            for i in exclude:
                moved[i] = -1.0
            axis = int(np.argmax(moved))
            if moved[axis] < self.min_travel:
                raise ValueError(
                    f"the {key} pedal did not move any axis (other than steering); start again"
                )
            return axis

        throttle = pedal("throttle", {steering})
        brake = pedal("brake", {steering, throttle})
        self.axes = {"steering": steering, "throttle": throttle, "brake": brake}

    def result(
        self,
        name: str,
        *,
        wheel_range_deg: float = 900.0,
        steering_ratio: float = 15.0,
        pedal_deadzone: float = 0.02,
        steering_deadzone: float = 0.0,
        max_acceleration: float = 3.0,
        max_deceleration: float = 6.0,
    ) -> JoystickCalibration:
        """The calibration measured (after :attr:`done`)."""
        if not self.done:
            raise RuntimeError(f"calibration not finished: {self.prompt}")
        a, snap = self.axes, self.snapshots
        s, t, b = a["steering"], a["throttle"], a["brake"]
        return JoystickCalibration(
            name=name,
            steering=SteeringAxis(
                s, snap["centre"][s], snap["left"][s], snap["right"][s], steering_deadzone
            ),
            throttle=PedalAxis(t, snap["centre"][t], snap["throttle"][t], pedal_deadzone),
            brake=PedalAxis(b, snap["centre"][b], snap["brake"][b], pedal_deadzone),
            wheel_range_deg=wheel_range_deg,
            steering_ratio=steering_ratio,
            max_acceleration=max_acceleration,
            max_deceleration=max_deceleration,
            match_names=(name,),
            notes="Measured by hasa-drive calibrate on "
            f"{_dt.datetime.now().isoformat(timespec='seconds')}.",
        )


def _round_calibration(cal: JoystickCalibration) -> JoystickCalibration:
    def r(x: float) -> float:
        return round(min(max(x, -1.0), 1.0), 5)

    st, th, br = cal.steering, cal.throttle, cal.brake
    return JoystickCalibration(
        name=cal.name,
        steering=SteeringAxis(st.axis, r(st.centre), r(st.left), r(st.right), st.deadzone),
        throttle=PedalAxis(th.axis, r(th.rest), r(th.full), th.deadzone),
        brake=PedalAxis(br.axis, r(br.rest), r(br.full), br.deadzone),
        wheel_range_deg=cal.wheel_range_deg,
        steering_ratio=cal.steering_ratio,
        max_acceleration=cal.max_acceleration,
        max_deceleration=cal.max_deceleration,
        match_names=cal.match_names,
        notes=cal.notes,
    )


STOP_SIGNALS = tuple(
    getattr(signal, name)
    for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
    if hasattr(signal, name)
)
"""Signals that stop the calibration dialogue (Ctrl-C, kill, a closed terminal, Ctrl-\\)."""


class _Stopped(Exception):
    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def _stop_on_signals() -> Iterator[None]:
    """Turn :data:`STOP_SIGNALS` into :class:`_Stopped` while the dialogue waits.

    SDL (which pygame starts) takes SIGINT and SIGTERM for itself and turns
    them into a QUIT event, so without this a wait loop that only polls for a
    joystick would ignore Ctrl-C and ``kill`` until it times out.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: Any) -> None:
        raise _Stopped(signum)

    previous = {sig: signal.signal(sig, stop) for sig in STOP_SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


def calibrate(
    output: Path,
    *,
    wheel_range_deg: float,
    steering_ratio: float,
    timeout: float,
    log: Callable[[str], None] = print,
    pygame_module: Any = None,
) -> int:
    """Run the calibration dialogue on the first joystick found; write ``output``; exit code.

    Every wait (for a joystick, for each step) ends on Escape, a QUIT event,
    Ctrl-C, SIGTERM, SIGHUP or SIGQUIT (nothing is written; exit code 1, or
    128 + the signal's number), or after ``timeout`` s (exit code 1; :data:`NO_DEVICE`,
    3, when no joystick turned up at all).
    """
    if no_screen_reason() is not None:
        os.environ["SDL_VIDEODRIVER"] = (
            "dummy"  # the terminal is enough; pygame's event queue needs video
        )
    pg = pygame_module if pygame_module is not None else init_pygame_input()
    try:
        with _stop_on_signals():
            return _dialogue(output, wheel_range_deg, steering_ratio, timeout, log, pg)
    except _Stopped as stop:
        log(f"hasa-drive calibrate: stopped by {stop}; nothing written")
        return 128 + stop.signum


def _quit(events: Sequence[Any], pg: Any) -> bool:
    return any(e.type == pg.QUIT or (e.type == pg.KEYDOWN and e.key == pg.K_ESCAPE) for e in events)


def _dialogue(
    output: Path,
    wheel_range_deg: float,
    steering_ratio: float,
    timeout: float,
    log: Callable[[str], None],
    pg: Any,
) -> int:
    deadline = time.monotonic() + timeout
    joystick = None
    log("hasa-drive calibrate: waiting for a joystick or wheel (plug it in now) ...")
    while joystick is None:
        events = pg.event.get()
        if _quit(events, pg):
            log("hasa-drive calibrate: cancelled; nothing written")
            return 1
        for e in events:
            if e.type == pg.JOYDEVICEADDED:
                joystick = pg.joystick.Joystick(e.device_index)
                break
        if joystick is None:
            if time.monotonic() > deadline:
                print(
                    f"hasa-drive calibrate: error: no joystick found in {timeout:g} s; is the "
                    "wheel plugged in (and in PS3 mode for a G29)?",
                    file=sys.stderr,
                    flush=True,
                )
                return NO_DEVICE
            time.sleep(0.02)
    name = str(joystick.get_name())
    log(f"hasa-drive calibrate: {name} with {joystick.get_numaxes()} axes")
    cal = Calibrator(joystick)
    log(cal.prompt)
    while not cal.done:
        events = pg.event.get()
        if any(
            e.type == pg.JOYDEVICEREMOVED and int(e.instance_id) == cal.instance_id for e in events
        ):
            log("hasa-drive calibrate: the device was unplugged; nothing written")
            return 1
        if _quit(events, pg):
            log("hasa-drive calibrate: cancelled; nothing written")
            return 1
        before = cal.step
        took = cal.handle_events(events, pg)
        if cal.error:
            log(f"  {cal.error}")
            cal.error = None
            if cal.step == 0 and before != 0:
                log(cal.prompt)
        elif took and not cal.done:
            log(cal.prompt)
        if time.monotonic() > deadline:
            log("hasa-drive calibrate: timed out; nothing written")
            return 1
        time.sleep(0.01)
    result = _round_calibration(
        cal.result(name, wheel_range_deg=wheel_range_deg, steering_ratio=steering_ratio)
    )
    path = save_calibration(result, output)
    a = cal.axes
    log(
        f"hasa-drive calibrate: steering axis {a['steering']}, throttle axis {a['throttle']}, "
        f"brake axis {a['brake']}; wheel range {wheel_range_deg:g} deg, "
        f"steering ratio {steering_ratio:g}:1"
    )
    log(f"hasa-drive calibrate: wrote {path}")
    return 0
