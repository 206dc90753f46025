"""The input layer: keyboard and joystick sources behind one :class:`InputManager`.

Everything is driven by pygame events, so a real wheel, posted events and an
SDL virtual joystick (:mod:`hasa_env.devices.virtual`) go through the same
code:

- :class:`KeyboardSource` keeps the set of held keys from ``KEYDOWN`` /
  ``KEYUP`` events; each :meth:`KeyboardSource.read` advances its analogue
  steering angle by the simulation step ``dt``: a held key ramps the angle
  linearly towards the full angle, released keys let it decay exponentially
  to zero. The angle therefore depends on simulated time, not on the frame
  rate.
- :class:`JoystickDevice` keeps the latest value of every axis from
  ``JOYAXISMOTION`` events and maps them with its
  :class:`~hasa_env.devices.calibration.JoystickCalibration`.
- :class:`InputManager` handles hot-plug: ``JOYDEVICEADDED`` opens the device
  (keyed by its SDL instance id, which stays unique across re-plugging) and
  picks its calibration profile by name; ``JOYDEVICEREMOVED`` of the active
  device falls back to the keyboard and reports a ``"disconnected"`` notice
  (the drive loop pauses). Axis events of devices that are not connected are
  ignored, including the re-centring events SDL emits for a device in the
  same batch as its removal, so a disconnect never records junk.

Set ``SDL_JOYSTICK_ALLOW_BACKGROUND_EVENTS=1`` (done by :func:`init_pygame_input`)
so the wheel keeps working when the window loses focus.
"""

from __future__ import annotations

import math
import os
import sys
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from hasa_env.devices.calibration import (
    JoystickCalibration,
    KeyboardCalibration,
    shipped_calibration,
)

__all__ = [
    "no_screen_reason",
    "InputReading",
    "Notice",
    "KeyboardSource",
    "JoystickDevice",
    "InputManager",
    "init_pygame_input",
    "RAW_INPUT_COLUMNS",
]

RAW_INPUT_COLUMNS = (
    "source",
    "raw_steering",
    "raw_throttle",
    "raw_brake",
    "steering_wheel_angle",
    "road_wheel_angle",
    "throttle",
    "brake",
    "acceleration",
)
"""Fields of an :class:`InputReading` in a raw-input side file (after ``step`` and ``time``)."""


def init_pygame_input(video: bool = True) -> Any:
    """Initialise pygame's event, keyboard and joystick subsystems (no audio); return ``pygame``.

    Sets ``SDL_JOYSTICK_ALLOW_BACKGROUND_EVENTS=1`` first (unless already set),
    so joystick events keep arriving when the window is not focused.
    """
    os.environ.setdefault("SDL_JOYSTICK_ALLOW_BACKGROUND_EVENTS", "1")
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    import pygame  # pygame: only when input devices are opened

    if video and not pygame.display.get_init():
        pygame.display.init()
    if not pygame.joystick.get_init():
        pygame.joystick.init()
    return pygame


@dataclass(frozen=True)
class InputReading:
    """What the driver commands at one simulation step.

    Attributes:
        source: ``"keyboard"`` or ``"joystick:<device name>"``.
        road_wheel_angle: steering command delta (rad, left positive).
        steering_wheel_angle: steering-wheel angle (rad); keyboard: equals the
            road-wheel angle (no steering column).
        throttle, brake: pedal travel in [0, 1] (keyboard: 0 or 1).
        acceleration: longitudinal acceleration command (m/s^2).
        raw_steering, raw_throttle, raw_brake: the raw axis values as pygame
            reports them (normalised, about [-1, 1]); NaN for the keyboard.
    """

    source: str
    road_wheel_angle: float
    steering_wheel_angle: float
    throttle: float
    brake: float
    acceleration: float
    raw_steering: float = math.nan
    raw_throttle: float = math.nan
    raw_brake: float = math.nan

    def action(self) -> list[float]:
        """The env's physical action ``[steering rad, acceleration m/s^2]``."""
        return [self.road_wheel_angle, self.acceleration]

    def as_row(self) -> list[Any]:
        """Values in :data:`RAW_INPUT_COLUMNS` order."""
        return [getattr(self, c) for c in RAW_INPUT_COLUMNS]


@dataclass(frozen=True)
class Notice:
    """Something the drive loop should react to.

    ``kind``: ``"connected"`` (a joystick became the active source),
    ``"disconnected"`` (the active joystick was unplugged: pause),
    ``"ignored_device"`` (a joystick no profile can use), ``"confirm"``
    (space / enter / any joystick button: start or resume), ``"pause"`` (P),
    ``"quit"`` (Escape or the window closed).
    """

    kind: str
    message: str
    instance_id: int | None = None


class KeyboardSource:
    """Analogue steering from the keyboard (see :class:`KeyboardCalibration`).

    Args:
        calibration: key bindings, angle, ramp and return times.
        pygame_module: the imported ``pygame`` (key codes are resolved with it).
    """

    def __init__(self, calibration: KeyboardCalibration, pygame_module: Any) -> None:
        self.calibration = calibration
        self._held: set[int] = set()
        self.angle = 0.0
        """Current road-wheel angle (rad)."""
        self._codes: dict[str, frozenset[int]] = {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for action, names in calibration.keys.items():
                codes = set()
                for name in names:
                    try:
                        codes.add(pygame_module.key.key_code(name))
                    except ValueError:
                        raise ValueError(
                            f"{calibration.source}: field 'keys.{action}': "
                            f"unknown key name {name!r} "
                            "(use pygame key names such as 'left', 'a', 'space')"
                        ) from None
                self._codes[action] = frozenset(codes)

    def key_down(self, key: int) -> None:
        self._held.add(key)

    def key_up(self, key: int) -> None:
        self._held.discard(key)

    def release_all(self) -> None:
        """Forget held keys (e.g. when the window loses focus)."""
        self._held.clear()

    def _pressed(self, action: str) -> bool:
        return not self._held.isdisjoint(self._codes[action])

    def read(self, dt: float) -> InputReading:
        """Advance the steering angle by ``dt`` s and return the reading."""
        cal = self.calibration
        full = cal.max_road_wheel_angle
        left, right = self._pressed("left"), self._pressed("right")
        target = full if left and not right else (-full if right and not left else 0.0)
        if target != 0.0:
            rate = full / cal.ramp_time if cal.ramp_time > 0.0 else math.inf
            step = rate * dt
            if abs(target - self.angle) <= step:
                self.angle = target
            else:
                self.angle += math.copysign(step, target - self.angle)
        elif cal.return_time_constant > 0.0:
            self.angle *= math.exp(-dt / cal.return_time_constant)
        else:
            self.angle = 0.0
        throttle = 1.0 if self._pressed("throttle") else 0.0
        brake = 1.0 if self._pressed("brake") else 0.0
        return InputReading(
            source="keyboard",
            road_wheel_angle=self.angle,
            steering_wheel_angle=self.angle,
            throttle=throttle,
            brake=brake,
            acceleration=throttle * cal.acceleration - brake * cal.deceleration,
        )


class JoystickDevice:
    """An open joystick and the latest value of each of its axes.

    A pedal axis counts as *at rest* until it reports a value different from
    the one it had when the device was opened: some wheels (the G29 among
    them) report 0 for a pedal that has not moved since the device was
    opened, which would read as half pressed, and SDL emits that stale value
    as motion events when the device opens.
    """

    def __init__(self, joystick: Any, calibration: JoystickCalibration) -> None:
        self.joystick = joystick
        self.calibration = calibration
        self.instance_id = int(joystick.get_instance_id())
        self.name = str(joystick.get_name())
        steer = calibration.steering.axis
        self.axes: dict[int, float] = {steer: float(joystick.get_axis(steer))}
        self._unmoved: dict[int, float] = {
            a: float(joystick.get_axis(a))
            for a in (calibration.throttle.axis, calibration.brake.axis)
        }

    def on_axis(self, axis: int, value: float) -> None:
        value = float(value)
        if axis in self._unmoved:
            if value == self._unmoved[axis]:
                return
            del self._unmoved[axis]
        self.axes[axis] = value

    def read(self) -> InputReading:
        cal = self.calibration
        raw_s = self.axes.get(cal.steering.axis, cal.steering.centre)
        raw_t = self.axes.get(cal.throttle.axis, cal.throttle.rest)
        raw_b = self.axes.get(cal.brake.axis, cal.brake.rest)
        wheel = cal.steering_wheel_angle(raw_s)
        throttle, brake = cal.throttle.travel(raw_t), cal.brake.travel(raw_b)
        return InputReading(
            source=f"joystick:{self.name}",
            road_wheel_angle=wheel / cal.steering_ratio,
            steering_wheel_angle=wheel,
            throttle=throttle,
            brake=brake,
            acceleration=cal.acceleration(throttle, brake),
            raw_steering=raw_s,
            raw_throttle=raw_t,
            raw_brake=raw_b,
        )

    def close(self) -> None:
        try:
            self.joystick.quit()
        except Exception:  # noqa: BLE001 - the device may already be gone
            pass


class InputManager:
    """One input layer over the keyboard and any number of hot-plugged joysticks.

    Args:
        keyboard: keyboard calibration (default: the shipped ``keyboard.json``).
        profiles: joystick calibrations, tried in order; a joystick uses the
            first whose ``match_names`` match its name (a profile without
            ``match_names`` matches any device). Default: the shipped G29
            profile, then the generic gamepad profile.
        use_joystick: False ignores joysticks (keyboard only).
        pygame_module: the imported ``pygame``; default: :func:`init_pygame_input`.

    Feed it every event batch with :meth:`handle_events` (it returns the
    :class:`Notice` objects to act on) and call :meth:`read` once per
    simulation step.
    """

    def __init__(
        self,
        keyboard: KeyboardCalibration | None = None,
        profiles: Sequence[JoystickCalibration] | None = None,
        *,
        use_joystick: bool = True,
        pygame_module: Any = None,
    ) -> None:
        self._pg = pygame_module if pygame_module is not None else init_pygame_input()
        kb = keyboard if keyboard is not None else shipped_calibration("keyboard")
        if not isinstance(kb, KeyboardCalibration):
            raise TypeError(
                "keyboard must be a keyboard calibration, "
                f"got a {kb.device} calibration ({kb.source})"
            )
        self.keyboard = KeyboardSource(kb, self._pg)
        if profiles is None:
            profiles = [shipped_calibration("g29"), shipped_calibration("gamepad")]  # type: ignore[list-item]
        for p in profiles:
            if not isinstance(p, JoystickCalibration):
                raise TypeError(
                    "profiles must be joystick calibrations, "
                    f"got a {p.device} calibration ({p.source})"
                )
        self.profiles = list(profiles)
        self.use_joystick = use_joystick
        self.devices: dict[int, JoystickDevice] = {}
        """Open joysticks by SDL instance id."""
        self.active: JoystickDevice | None = None
        """The joystick that drives, or None (keyboard)."""
        self._confirm_keys = {self._pg.K_SPACE, self._pg.K_RETURN, self._pg.K_KP_ENTER}

    @property
    def pygame(self) -> Any:
        """The ``pygame`` module this input layer uses."""
        return self._pg

    # ------------------------------------------------------------ devices
    def profile_for(self, name: str) -> JoystickCalibration | None:
        """The first profile meant for a device called ``name`` (None if none)."""
        return next((p for p in self.profiles if p.matches(name)), None)

    @property
    def source_name(self) -> str:
        """``"keyboard"`` or ``"joystick:<name>"`` of the active source."""
        return "keyboard" if self.active is None else f"joystick:{self.active.name}"

    @property
    def steering_ratio(self) -> float | None:
        """Steering ratio of the active joystick's profile (None for the keyboard)."""
        return None if self.active is None else self.active.calibration.steering_ratio

    def _added(self, device_index: int) -> Notice | None:
        pg = self._pg
        try:
            joystick = pg.joystick.Joystick(device_index)
        except pg.error as exc:
            return Notice("ignored_device", f"could not open joystick {device_index}: {exc}")
        instance_id = int(joystick.get_instance_id())
        if instance_id in self.devices:
            return None
        name = str(joystick.get_name())
        profile = self.profile_for(name)
        if profile is None:
            return Notice(
                "ignored_device", f"no calibration profile matches joystick {name!r}", instance_id
            )
        if joystick.get_numaxes() < profile.axes_needed:
            return Notice(
                "ignored_device",
                f"joystick {name!r} has {joystick.get_numaxes()} axes but profile {profile.name!r} "
                f"({profile.source}) needs {profile.axes_needed}",
                instance_id,
            )
        device = JoystickDevice(joystick, profile)
        self.devices[instance_id] = device
        if self.active is None:
            self.active = device
            return Notice(
                "connected", f"driving with {name} (profile {profile.name!r})", instance_id
            )
        return None

    def _removed(self, instance_id: int) -> Notice | None:
        device = self.devices.pop(instance_id, None)
        if device is None:
            return None
        device.close()
        if device is self.active:
            self.active = None
            return Notice(
                "disconnected",
                f"{device.name} was disconnected: paused, steering falls back to the keyboard.\n"
                "Plug the wheel back in, or press SPACE to go on with the keyboard.",
                instance_id,
            )
        return None

    # ------------------------------------------------------------- events
    def handle_events(self, events: Iterable[Any]) -> list[Notice]:
        """Process one batch of pygame events (e.g. ``pygame.event.get()``); return the notices.

        Axis events of a device removed in the same batch are dropped (SDL
        re-centres a removed device's axes just before reporting the removal).
        """
        pg = self._pg
        events = list(events)
        removed = {int(e.instance_id) for e in events if e.type == pg.JOYDEVICEREMOVED}
        notices: list[Notice] = []
        for e in events:
            t = e.type
            if t == pg.JOYAXISMOTION:
                iid = int(e.instance_id)
                if iid not in removed and iid in self.devices:
                    self.devices[iid].on_axis(int(e.axis), float(e.value))
            elif t == pg.KEYDOWN:
                if e.key == pg.K_ESCAPE:
                    notices.append(Notice("quit", "Escape pressed"))
                elif e.key in self._confirm_keys:
                    notices.append(Notice("confirm", "key"))
                elif e.key == pg.K_p:
                    notices.append(Notice("pause", "P pressed"))
                self.keyboard.key_down(e.key)
            elif t == pg.KEYUP:
                self.keyboard.key_up(e.key)
            elif t == pg.JOYBUTTONDOWN:
                if int(e.instance_id) in self.devices and int(e.instance_id) not in removed:
                    notices.append(Notice("confirm", "joystick button", int(e.instance_id)))
            elif t == pg.JOYDEVICEADDED:
                if self.use_joystick:
                    n = self._added(int(e.device_index))
                    if n is not None:
                        notices.append(n)
            elif t == pg.JOYDEVICEREMOVED:
                n = self._removed(int(e.instance_id))
                if n is not None:
                    notices.append(n)
            elif t == pg.QUIT:
                notices.append(Notice("quit", "window closed"))
            elif t == getattr(pg, "WINDOWFOCUSLOST", -1):
                self.keyboard.release_all()
        return notices

    def poll(self) -> list[Notice]:
        """``handle_events(pygame.event.get())``."""
        return self.handle_events(self._pg.event.get())

    def read(self, dt: float) -> InputReading:
        """The driver's command for the next simulation step of ``dt`` s.

        The keyboard's ramps advance by ``dt`` every call (so switching to the
        keyboard mid-run starts from a decayed angle, not a stale one).
        """
        keyboard = self.keyboard.read(dt)
        if self.active is not None:
            return self.active.read()
        return keyboard

    def close(self) -> None:
        """Close every open joystick."""
        for device in self.devices.values():
            device.close()
        self.devices.clear()
        self.active = None


def no_screen_reason() -> str | None:
    """Why there is no screen to drive on (None if there seems to be one)."""
    driver = os.environ.get("SDL_VIDEODRIVER", "").lower()
    if driver in ("dummy", "offscreen", "evdev"):
        return f"SDL_VIDEODRIVER={driver} (a video driver without a screen)"
    if sys.platform.startswith("linux") and not driver:
        if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
            return "neither DISPLAY nor WAYLAND_DISPLAY is set (no X11 or Wayland session)"
    return None
