"""Scripted driving: a synthetic driver turns a virtual wheel inside the drive loop."""

from __future__ import annotations

from typing import Any

import numpy as np

from hasa_env.devices.calibration import JoystickCalibration
from hasa_env.session.loop import DriveSession

__all__ = ["VirtualWheelDriver"]


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
