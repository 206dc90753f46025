"""Scripted driving: a synthetic driver turns a virtual wheel inside the drive loop, and
presses its button to go on through a study's screens."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from hasa_env.devices.calibration import JoystickCalibration
from hasa_env.session.loop import WAITING_STATES, DriveSession

__all__ = ["VirtualWheelDriver", "WheelButtonPresser"]


class VirtualWheelDriver:
    """A session hook: a :class:`hasa_env.drivers.Driver` turns an SDL virtual wheel.

    Before every step it asks the driver for (road-wheel angle, acceleration)
    from the session's current ``info``, converts them with the inverse of
    the wheel's calibration into raw axis values (steering wheel, throttle or
    brake) and sets the virtual axes; the session then reads them back
    through pygame's events like a real wheel. The driver is reset at each
    run's first step with a seed derived from the run's seed.

    Args:
        wheel: the virtual joystick (:class:`hasa_env.devices.virtual.VirtualJoystick`).
        driver: any driver with ``reset(seed, dt=...)`` and ``act(info, road)``.
        calibration: the wheel's calibration profile (the session's inputs must use it too).
    """

    def __init__(self, wheel: Any, driver: Any, calibration: JoystickCalibration) -> None:
        self.wheel = wheel
        """The virtual wheel turned; replace it to drive a re-plugged one."""
        self.driver = driver
        self.calibration = calibration
        self._run: tuple[int, int] | None = None
        self.commands: dict[int, tuple[float, float]] = {}
        """Step index k -> (road-wheel angle rad, acceleration m/s^2) the driver asked for
        over step k + 1 of the current run (absent while the wheel was unplugged)."""

    def __call__(self, session: DriveSession) -> None:
        if session.state != "driving" or session.info is None:
            return
        key = (session.run_index, session.run_seed or 0)
        if self._run != key:
            self._run = key
            self.driver.reset(
                int(np.random.SeedSequence([key[1], 7]).generate_state(1)[0]), dt=session.dt
            )
            self.commands = {}
            self._last_acted = -1
        if session.steps == self._last_acted:  # called again before the same step
            return
        # the driver keeps driving (its state must advance every step) even while unplugged
        steer, acc = self.driver.act(session.info, session.road)
        self._last_acted = session.steps
        if not getattr(self.wheel, "attached", True):
            return
        self.commands[session.steps] = (float(steer), float(acc))
        cal = self.calibration
        self.wheel.set_axis(cal.steering.axis, cal.raw_for_road_wheel_angle(steer))
        throttle = acc / cal.max_acceleration if acc > 0 and cal.max_acceleration > 0 else 0.0
        brake = -acc / cal.max_deceleration if acc < 0 and cal.max_deceleration > 0 else 0.0
        if cal.throttle.axis == cal.brake.axis:
            pedal = cal.brake if brake > 0 else cal.throttle
            self.wheel.set_axis(pedal.axis, pedal.raw_for_travel(max(throttle, brake)))
        else:
            self.wheel.set_axis(cal.throttle.axis, cal.throttle.raw_for_travel(throttle))
            self.wheel.set_axis(cal.brake.axis, cal.brake.raw_for_travel(brake))


class WheelButtonPresser:
    """A session hook: a scripted participant presses a virtual wheel's button to go on.

    Whenever the session waits for a confirmation (:data:`WAITING_STATES`:
    instructions, between runs, a break, the end screen), the button is
    pressed ``after`` s (wall clock) into the wait and released at the next
    call; while the wait goes on (a break shorter than its minimum ignores
    the press) it is pressed again every ``after`` s. The press goes through
    SDL and pygame's events like a real wheel's.

    Args:
        wheel: the virtual joystick (:class:`hasa_env.devices.virtual.VirtualJoystick`).
        button: which button.
        after: seconds of waiting before each press.
    """

    def __init__(self, wheel: Any, button: int = 0, after: float = 0.3) -> None:
        self.wheel = wheel
        self.button = int(button)
        self.after = float(after)
        self.presses = 0
        """Presses made so far."""
        self._since: float | None = None
        self._pressed = False

    def __call__(self, session: DriveSession) -> None:
        if self._pressed:
            self.wheel.set_button(self.button, False)
            self._pressed = False
            return
        if session.state not in WAITING_STATES or not getattr(self.wheel, "attached", True):
            self._since = None
            return
        now = time.perf_counter()
        if self._since is None:
            self._since = now
        elif now - self._since >= self.after:
            self.wheel.set_button(self.button, True)
            self._pressed = True
            self.presses += 1
            self._since = now
