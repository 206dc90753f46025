"""Input devices for human drivers: keyboard, joysticks, steering wheels (G29), calibration.

- :mod:`~hasa_env.devices.calibration`: calibration files (shipped defaults
  ``g29``, ``gamepad``, ``keyboard`` in ``hasa_env/data``), validation, the
  linear axis mapping;
- :mod:`~hasa_env.devices.sources`: the event-driven input layer with
  hot-plug (:class:`InputManager`);
- :mod:`~hasa_env.devices.calibrator`: the ``hasa-drive calibrate`` dialogue;
- :mod:`~hasa_env.devices.virtual`: SDL virtual joysticks (tests, scripted
  drives);
- :mod:`~hasa_env.devices.force_feedback`: optional autocentre via evdev.
"""

from hasa_env.devices.calibration import (
    CalibrationError,
    JoystickCalibration,
    KeyboardCalibration,
    PedalAxis,
    SteeringAxis,
    load_calibration,
    parse_calibration,
    save_calibration,
    shipped_calibration,
    shipped_calibration_path,
    user_calibration_path,
)
from hasa_env.devices.sources import (
    RAW_INPUT_COLUMNS,
    InputManager,
    InputReading,
    JoystickDevice,
    KeyboardSource,
    Notice,
    init_pygame_input,
    no_screen_reason,
)

__all__ = [
    "no_screen_reason",
    "CalibrationError",
    "JoystickCalibration",
    "KeyboardCalibration",
    "PedalAxis",
    "SteeringAxis",
    "load_calibration",
    "parse_calibration",
    "save_calibration",
    "shipped_calibration",
    "shipped_calibration_path",
    "user_calibration_path",
    "RAW_INPUT_COLUMNS",
    "InputManager",
    "InputReading",
    "JoystickDevice",
    "KeyboardSource",
    "Notice",
    "init_pygame_input",
]
