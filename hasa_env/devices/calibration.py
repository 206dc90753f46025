"""Calibration files of the input devices: load, validate, map, save.

A calibration file is a JSON object; two kinds exist (``"device"``):

``"joystick"`` (a wheel with pedals, a gamepad, a joystick)::

    {
      "format": "hasa_env input calibration", "version": 1,
      "device": "joystick",
      "name": "Logitech G29 Driving Force",
      "match_names": ["G29"],          # used for devices whose name contains one of these
      "wheel_range_deg": 900.0,        # steering-wheel travel lock to lock (deg)
      "steering_ratio": 15.0,          # steering-wheel angle / road-wheel angle
      "steering": {"axis": 0, "centre": 0.0, "left": -1.0, "right": 1.0, "deadzone": 0.0},
      "throttle": {"axis": 2, "rest": 1.0, "full": -1.0, "deadzone": 0.02},
      "brake":    {"axis": 3, "rest": 1.0, "full": -1.0, "deadzone": 0.02},
      "max_acceleration": 3.0,         # m/s^2 at full throttle
      "max_deceleration": 6.0          # m/s^2 at full brake
    }

Axis values are pygame's normalised readings in [-1, 1]. The mapping is
linear: the steering axis maps ``centre`` -> 0 and ``left`` / ``right`` -> the
left / right lock (+-wheel_range/2, left positive as in ISO 8855), then the
road-wheel angle is the steering-wheel angle divided by ``steering_ratio``;
a pedal maps ``rest`` -> 0 and ``full`` -> 1 (a G29's pedals rest at +1 and
read -1 when pressed). A deadzone d (fraction of the travel) maps travel
u <= d to 0 and rescales the rest, ``(u - d) / (1 - d)``, so the full value
is still reached. Readings beyond ``left``/``right``/``full`` saturate.

``"keyboard"``::

    {
      "format": "hasa_env input calibration", "version": 1,
      "device": "keyboard", "name": "keyboard",
      "max_road_wheel_angle_deg": 1.5, # steering angle held keys ramp to (deg, road wheel)
      "ramp_time": 0.8,                # s from 0 to the full angle while a key is held
      "return_time_constant": 0.15,    # s, exponential decay to 0 when released
      "acceleration": 2.0, "deceleration": 5.0,   # m/s^2 while up / down is held
      "keys": {"left": ["left", "a"], "right": ["right", "d"],
               "throttle": ["up", "w"], "brake": ["down", "s"]}
    }

Shipped defaults live in ``hasa_env/data`` (``g29.json``, ``gamepad.json``,
``keyboard.json``) and are found through :mod:`importlib.resources`, so
they work from any working directory and from an installed wheel.
:func:`load_calibration` validates every field (through the shared validator,
:mod:`hasa_env.validation`) and raises :class:`CalibrationError` naming the
file, the field and the allowed range.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from hasa_env.atomic import write_atomic
from hasa_env.validation import Field, schema, validate, version

__all__ = [
    "CALIBRATION_FORMAT",
    "CALIBRATION_VERSION",
    "SHIPPED_CALIBRATIONS",
    "CalibrationError",
    "SteeringAxis",
    "PedalAxis",
    "JoystickCalibration",
    "KeyboardCalibration",
    "load_calibration",
    "parse_calibration",
    "shipped_calibration",
    "shipped_calibration_path",
    "save_calibration",
    "user_calibration_path",
]

CALIBRATION_FORMAT = "hasa_env input calibration"
CALIBRATION_VERSION = 1
SHIPPED_CALIBRATIONS = ("g29", "gamepad", "keyboard")
"""Names of the calibration files shipped in ``hasa_env/data`` (without ``.json``)."""

_MAX_AXIS = 63


class CalibrationError(ValueError):
    """An invalid calibration file: names the file, the field and what is allowed."""

    def __init__(self, source: str, field_name: str | None, message: str) -> None:
        """``message`` follows the field's name (``"= 5 is out of range: allowed [0, 1]"``), or
        follows ``source`` alone when ``field_name`` is None."""
        self.source = source
        self.field = field_name
        text = f"{source}: field '{field_name}' {message}" if field_name else f"{source}: {message}"
        super().__init__(text)


# ---------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class SteeringAxis:
    """The steering axis: raw value at the centre and at each lock, deadzone (fraction)."""

    axis: int
    centre: float = 0.0
    left: float = -1.0
    right: float = 1.0
    deadzone: float = 0.0

    def travel(self, raw: float) -> float:
        """Signed travel in [-1, 1] (left positive) of a raw axis value (linear, saturating)."""
        raw = _clip(raw)
        if raw == self.centre:
            return 0.0
        if (raw - self.centre) * (self.left - self.centre) > 0.0:
            u, sign = (raw - self.centre) / (self.left - self.centre), 1.0
        else:
            u, sign = (raw - self.centre) / (self.right - self.centre), -1.0
        travel = _deadzone(min(u, 1.0), self.deadzone)
        return sign * travel if travel > 0.0 else 0.0


@dataclass(frozen=True)
class PedalAxis:
    """A pedal axis: raw value at rest and fully pressed, deadzone (fraction of travel)."""

    axis: int
    rest: float
    full: float
    deadzone: float = 0.0

    def travel(self, raw: float) -> float:
        """Pedal travel in [0, 1] (0 at rest, 1 fully pressed) of a raw axis value."""
        u = (_clip(raw) - self.rest) / (self.full - self.rest)
        return _deadzone(min(max(u, 0.0), 1.0), self.deadzone)

    def raw_for_travel(self, travel: float) -> float:
        """Raw axis value giving pedal ``travel`` in [0, 1] (inverse of :meth:`travel`)."""
        u = min(max(float(travel), 0.0), 1.0)
        if u == 0.0:
            return self.rest
        d = self.deadzone
        return self.rest + (d + u * (1.0 - d)) * (self.full - self.rest)


@dataclass(frozen=True)
class JoystickCalibration:
    """How a joystick's axes map to steering and pedals (see the module docstring).

    Attributes:
        name: profile name.
        steering, throttle, brake: the axes.
        wheel_range_deg: steering-wheel travel lock to lock (deg).
        steering_ratio: steering-wheel angle / road-wheel angle.
        max_acceleration: m/s^2 at full throttle.
        max_deceleration: m/s^2 (positive) at full brake.
        match_names: the profile is used for devices whose name contains one
            of these (case-insensitive); empty: any device.
        source: where it was loaded from (for messages).
        notes: free text kept from the file.
    """

    name: str
    steering: SteeringAxis
    throttle: PedalAxis
    brake: PedalAxis
    wheel_range_deg: float = 900.0
    steering_ratio: float = 15.0
    max_acceleration: float = 3.0
    max_deceleration: float = 6.0
    match_names: tuple[str, ...] = ()
    source: str = "<memory>"
    notes: str = ""
    device: str = field(default="joystick", init=False)

    @property
    def max_steering_wheel_angle(self) -> float:
        """Steering-wheel angle at either lock (rad)."""
        return math.radians(0.5 * self.wheel_range_deg)

    @property
    def axes_needed(self) -> int:
        """Number of axes a device must have for this profile."""
        return 1 + max(self.steering.axis, self.throttle.axis, self.brake.axis)

    def matches(self, device_name: str) -> bool:
        """True if this profile is meant for a device called ``device_name``."""
        if not self.match_names:
            return True
        low = device_name.lower()
        return any(m.lower() in low for m in self.match_names)

    def steering_wheel_angle(self, raw: float) -> float:
        """Steering-wheel angle (rad, left positive) of a raw steering-axis value."""
        return self.steering.travel(raw) * self.max_steering_wheel_angle

    def road_wheel_angle(self, raw: float) -> float:
        """Road-wheel angle (rad, left positive) of a raw steering-axis value."""
        return self.steering_wheel_angle(raw) / self.steering_ratio

    def raw_for_road_wheel_angle(self, angle: float) -> float:
        """Raw steering-axis value that commands a road-wheel ``angle`` (rad); inverse mapping.

        Saturates at the locks; inside the deadzone the inverse is not unique
        and the centre is returned for a zero angle.
        """
        u = angle * self.steering_ratio / self.max_steering_wheel_angle
        mag = min(abs(u), 1.0)
        if mag == 0.0:
            return self.steering.centre
        d = self.steering.deadzone
        travel = d + mag * (1.0 - d)
        end = self.steering.left if u > 0 else self.steering.right
        return self.steering.centre + travel * (end - self.steering.centre)

    def acceleration(self, throttle: float, brake: float) -> float:
        """Longitudinal acceleration (m/s^2) of pedal travels in [0, 1]."""
        return throttle * self.max_acceleration - brake * self.max_deceleration

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of this calibration (round-trips through :func:`parse_calibration`)."""
        out: dict[str, Any] = {
            "format": CALIBRATION_FORMAT,
            "version": CALIBRATION_VERSION,
            "device": "joystick",
            "name": self.name,
            "match_names": list(self.match_names),
            "wheel_range_deg": self.wheel_range_deg,
            "steering_ratio": self.steering_ratio,
            "steering": _asdict(self.steering),
            "throttle": _asdict(self.throttle),
            "brake": _asdict(self.brake),
            "max_acceleration": self.max_acceleration,
            "max_deceleration": self.max_deceleration,
        }
        if self.notes:
            out["notes"] = self.notes
        return out


@dataclass(frozen=True)
class KeyboardCalibration:
    """Keyboard steering: held keys ramp the road-wheel angle; released, it decays to 0.

    The defaults (1.5 deg in 0.8 s, 0.15 s return) were tuned with a model of a
    person pressing keys (:mod:`hasa_env.session.keyboard_person`, docs/design.md §11).

    Attributes:
        max_road_wheel_angle_deg: angle (deg, road wheel) a held key ramps to.
        ramp_time: s from 0 to the full angle.
        return_time_constant: s, time constant of the exponential return to 0.
        acceleration, deceleration: m/s^2 while the throttle / brake key is held.
        keys: action -> list of pygame key names (``pygame.key.key_code`` names).
    """

    name: str = "keyboard"
    max_road_wheel_angle_deg: float = 1.5
    ramp_time: float = 0.8
    return_time_constant: float = 0.15
    acceleration: float = 2.0
    deceleration: float = 5.0
    keys: Mapping[str, tuple[str, ...]] = field(
        default_factory=lambda: {
            "left": ("left", "a"),
            "right": ("right", "d"),
            "throttle": ("up", "w"),
            "brake": ("down", "s"),
        }
    )
    source: str = "<memory>"
    notes: str = ""
    device: str = field(default="keyboard", init=False)

    @property
    def max_road_wheel_angle(self) -> float:
        """Road-wheel angle (rad) a held key ramps to."""
        return math.radians(self.max_road_wheel_angle_deg)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "format": CALIBRATION_FORMAT,
            "version": CALIBRATION_VERSION,
            "device": "keyboard",
            "name": self.name,
            "max_road_wheel_angle_deg": self.max_road_wheel_angle_deg,
            "ramp_time": self.ramp_time,
            "return_time_constant": self.return_time_constant,
            "acceleration": self.acceleration,
            "deceleration": self.deceleration,
            "keys": {k: list(v) for k, v in self.keys.items()},
        }
        if self.notes:
            out["notes"] = self.notes
        return out


def _asdict(axis: SteeringAxis | PedalAxis) -> dict[str, Any]:
    return {k: getattr(axis, k) for k in axis.__dataclass_fields__}


def _clip(raw: float) -> float:
    # pygame divides int16 readings by 32767, so -32768 reads -1.00003
    return -1.0 if raw < -1.0 else (1.0 if raw > 1.0 else float(raw))


def _deadzone(u: float, deadzone: float) -> float:
    return 0.0 if u <= deadzone else (u - deadzone) / (1.0 - deadzone)


# ----------------------------------------------------------------- validation
def _raw(doc: str) -> Field:
    return Field("number", doc=doc, low=-1.0, high=1.0)


_AXIS = Field("integer", doc="Axis index as pygame numbers them.", low=0, high=_MAX_AXIS)
_DEADZONE = Field("number", 0.0, "Fraction of the travel that reads 0.", low=0.0, high=0.5)
_HEADER: dict[str, Field] = {
    "format": Field("choice", choices=(CALIBRATION_FORMAT,)),
    "version": version(CALIBRATION_VERSION),
    "device": Field("choice", choices=("joystick", "keyboard")),
    "name": Field("string", doc="Profile name."),
}
_JOYSTICK = schema(
    {
        **_HEADER,
        "match_names": Field("strings", [], "Used for devices whose name contains one of these."),
        "wheel_range_deg": Field(
            "number", doc="Steering-wheel travel lock to lock.", unit="deg", low=10.0, high=3600.0
        ),
        "steering_ratio": Field(
            "number", doc="Steering-wheel angle / road-wheel angle.", low=0.1, high=100.0
        ),
        "steering": Field(
            "mapping",
            fields={
                "axis": _AXIS,
                "centre": _raw("Raw value with the wheel centred."),
                "left": _raw("Raw value at the left lock."),
                "right": _raw("Raw value at the right lock."),
                "deadzone": _DEADZONE,
            },
        ),
        **{
            pedal: Field(
                "mapping",
                fields={
                    "axis": _AXIS,
                    "rest": _raw("Raw value with the pedal released."),
                    "full": _raw("Raw value with the pedal fully pressed."),
                    "deadzone": _DEADZONE,
                },
            )
            for pedal in ("throttle", "brake")
        },
        "max_acceleration": Field(
            "number", doc="At full throttle.", unit="m/s^2", low=0.0, high=30.0
        ),
        "max_deceleration": Field("number", doc="At full brake.", unit="m/s^2", low=0.0, high=30.0),
        "notes": Field("string", "", "Free text."),
    }
)
_KEYBOARD = schema(
    {
        **_HEADER,
        "max_road_wheel_angle_deg": Field(
            "number",
            doc="Road-wheel angle a held key ramps to.",
            unit="deg",
            low=0.0,
            high=60.0,
            low_open=True,
        ),
        "ramp_time": Field("number", doc="From 0 to the full angle.", unit="s", low=0.0, high=10.0),
        "return_time_constant": Field(
            "number", doc="Of the return to 0.", unit="s", low=0.0, high=10.0
        ),
        "acceleration": Field("number", doc="Throttle key held.", unit="m/s^2", low=0.0, high=30.0),
        "deceleration": Field("number", doc="Brake key held.", unit="m/s^2", low=0.0, high=30.0),
        "keys": Field(
            "mapping",
            fields={
                action: Field("strings", doc="pygame key names.", non_empty=True)
                for action in ("left", "right", "throttle", "brake")
            },
        ),
        "notes": Field("string", "", "Free text."),
    }
)


def _check_steering_axis(axis: SteeringAxis, source: str) -> None:
    if (axis.left - axis.centre) * (axis.right - axis.centre) >= 0.0:
        raise CalibrationError(
            source,
            "steering.left",
            f"= {axis.left!r} and 'steering.right' = {axis.right!r} must lie on opposite sides "
            f"of 'steering.centre' = {axis.centre!r}",
        )


def _check_pedal_axis(axis: PedalAxis, name: str, source: str) -> None:
    if abs(axis.full - axis.rest) < 0.1:
        raise CalibrationError(
            source,
            f"{name}.full",
            f"= {axis.full!r} must differ from '{name}.rest' = {axis.rest!r} by at least 0.1 "
            "(was the pedal pressed during calibration?)",
        )


def parse_calibration(
    data: Any, source: str = "<memory>"
) -> JoystickCalibration | KeyboardCalibration:
    """Validate a calibration JSON object (already parsed) and build the calibration.

    Raises:
        CalibrationError: a missing or unknown field, a value of the wrong type or
            out of range, or inconsistent axes; the message names ``source`` and the field.
    """

    def fail(path: str, message: str) -> CalibrationError:
        exc = CalibrationError(source, None, message)  # the message names the field itself
        exc.field = path or None
        return exc

    device = data.get("device") if isinstance(data, Mapping) else None
    keyboard = isinstance(device, str) and device == "keyboard"
    doc = validate(
        data,
        _KEYBOARD if keyboard else _JOYSTICK,
        describe=lambda path: f"field '{path}'" if path else "the document",
        error=fail,
    )
    if keyboard:
        return KeyboardCalibration(
            name=doc["name"],
            max_road_wheel_angle_deg=doc["max_road_wheel_angle_deg"],
            ramp_time=doc["ramp_time"],
            return_time_constant=doc["return_time_constant"],
            acceleration=doc["acceleration"],
            deceleration=doc["deceleration"],
            keys={action: tuple(names) for action, names in doc["keys"].items()},
            source=source,
            notes=doc["notes"],
        )
    steering = SteeringAxis(**doc["steering"])
    _check_steering_axis(steering, source)
    throttle = PedalAxis(**doc["throttle"])
    _check_pedal_axis(throttle, "throttle", source)
    brake = PedalAxis(**doc["brake"])
    _check_pedal_axis(brake, "brake", source)
    cal = JoystickCalibration(
        name=doc["name"],
        steering=steering,
        throttle=throttle,
        brake=brake,
        wheel_range_deg=doc["wheel_range_deg"],
        steering_ratio=doc["steering_ratio"],
        max_acceleration=doc["max_acceleration"],
        max_deceleration=doc["max_deceleration"],
        match_names=tuple(doc["match_names"]),
        source=source,
        notes=doc["notes"],
    )
    if steering.axis in (throttle.axis, brake.axis):
        which = "throttle" if steering.axis == throttle.axis else "brake"
        raise CalibrationError(
            source,
            "steering.axis",
            f"= {steering.axis} is also the {which} axis; use separate axes",
        )
    if throttle.axis == brake.axis:
        # one axis for both pedals (e.g. a gamepad stick): they must share the rest value
        # and be pressed in opposite directions
        same_rest = abs(throttle.rest - brake.rest) < 1e-9
        opposite = (throttle.full - throttle.rest) * (brake.full - brake.rest) < 0.0
        if not (same_rest and opposite):
            raise CalibrationError(
                source,
                "brake.axis",
                f"= {brake.axis} is also the throttle axis; that needs the same 'rest' and 'full' "
                "values on opposite sides of it",
            )
    return cal


def load_calibration(path: str | os.PathLike[str]) -> JoystickCalibration | KeyboardCalibration:
    """Load and validate a calibration file (see the module docstring for the fields).

    Raises:
        CalibrationError: unreadable file, invalid JSON or an invalid field (naming file and field).
    """
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CalibrationError(source, None, "file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CalibrationError(source, None, f"unreadable: {exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CalibrationError(
            source, None, f"not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}"
        ) from None
    return parse_calibration(data, source)


def shipped_calibration_path(name: str) -> Path:
    """Path of a shipped default calibration (``"g29"``, ``"gamepad"`` or ``"keyboard"``).

    Resolved relative to the installed package (:mod:`importlib.resources`),
    never the working directory.
    """
    if name not in SHIPPED_CALIBRATIONS:
        raise ValueError(
            f"unknown shipped calibration {name!r}; allowed: {', '.join(SHIPPED_CALIBRATIONS)}"
        )
    ref = resources.files("hasa_env").joinpath("data", f"{name}.json")
    return Path(str(ref))


def shipped_calibration(name: str) -> JoystickCalibration | KeyboardCalibration:
    """Load a shipped default calibration (``"g29"``, ``"gamepad"`` or ``"keyboard"``)."""
    if name not in SHIPPED_CALIBRATIONS:
        raise ValueError(
            f"unknown shipped calibration {name!r}; allowed: {', '.join(SHIPPED_CALIBRATIONS)}"
        )
    ref = resources.files("hasa_env").joinpath("data", f"{name}.json")
    return parse_calibration(
        json.loads(ref.read_text(encoding="utf-8")), f"hasa_env/data/{name}.json"
    )


def user_calibration_path() -> Path:
    """The file ``hasa-drive calibrate`` writes: ``$XDG_CONFIG_HOME/hasa-env/calibration.json``.

    (``~/.config/hasa-env/calibration.json`` when ``XDG_CONFIG_HOME`` is unset.)
    """
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return Path(base) / "hasa-env" / "calibration.json"


def save_calibration(
    calibration: JoystickCalibration | KeyboardCalibration, path: str | os.PathLike[str]
) -> Path:
    """Validate and write a calibration file atomically (:func:`hasa_env.atomic.write_atomic`:
    a new randomly named temporary file, never one a symlink could redirect, then
    ``os.replace``)."""
    data = calibration.to_dict()
    parse_calibration(data, str(path))  # never write a file we would refuse to read
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(target, json.dumps(data, indent=2) + "\n")
    return target
