"""Optional force feedback on Linux: the wheel's autocentre spring via evdev.

Off by default (``hasa-drive --autocentre STRENGTH`` turns it on). Needs the
``evdev`` Python package (``pip install evdev``; not a dependency of hasa-env,
imported only when asked for) and write access to the wheel's
``/dev/input/event*`` node (membership of the ``input`` group or a udev
rule). Anything missing is reported once and driving goes on without force
feedback.
"""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["Autocentre", "ForceFeedbackUnavailable"]


class ForceFeedbackUnavailable(RuntimeError):
    """Force feedback cannot be used here; the message says why."""


class Autocentre:
    """Sets a wheel's autocentre spring strength through evdev (``FF_AUTOCENTER``).

    Args:
        device_name: the joystick's name as pygame reports it; the evdev device
            whose name contains it (or is contained in it) is used.
        strength: spring strength in [0, 1] (fraction of the device maximum).

    Raises:
        ForceFeedbackUnavailable: not Linux, no ``evdev`` package, no matching
            device with force feedback, or no permission to write to it.
        ValueError: ``strength`` outside [0, 1].
    """

    def __init__(self, device_name: str, strength: float) -> None:
        if not 0.0 <= strength <= 1.0:
            raise ValueError(f"autocentre strength must be in [0, 1], got {strength!r}")
        if not sys.platform.startswith("linux"):
            raise ForceFeedbackUnavailable(
                f"force feedback via evdev needs Linux, this is {sys.platform}"
            )
        try:
            import evdev  # optional (Linux force feedback): pip install evdev
        except ImportError:
            raise ForceFeedbackUnavailable(
                "force feedback needs the 'evdev' package (pip install evdev); driving without it"
            ) from None
        self._evdev = evdev
        self.device = self._find(device_name)
        self.strength = strength
        self.set(strength)

    def _find(self, device_name: str) -> Any:
        evdev = self._evdev
        ecodes = evdev.ecodes
        wanted = device_name.lower()
        seen = []
        for path in evdev.list_devices():
            try:
                dev = evdev.InputDevice(path)
            except OSError as exc:
                seen.append(f"{path} ({exc.strerror or exc})")
                continue
            name = str(dev.name).lower()
            if wanted in name or (name and name in wanted):
                if ecodes.EV_FF not in dev.capabilities():
                    raise ForceFeedbackUnavailable(f"{dev.path} ({dev.name}) has no force feedback")
                return dev
            seen.append(f"{path} ({dev.name})")
        raise ForceFeedbackUnavailable(
            f"no evdev device named like {device_name!r} (readable: {', '.join(seen) or 'none'}); "
            "check permissions on /dev/input/event*"
        )

    def set(self, strength: float) -> None:
        """Set the spring strength in [0, 1]."""
        ecodes = self._evdev.ecodes
        try:
            self.device.write(ecodes.EV_FF, ecodes.FF_AUTOCENTER, int(round(strength * 0xFFFF)))
        except OSError as exc:
            raise ForceFeedbackUnavailable(
                f"cannot write to {self.device.path}: {exc.strerror or exc} "
                "(add yourself to the 'input' group or add a udev rule)"
            ) from None

    def close(self) -> None:
        """Turn the spring off and release the device."""
        try:
            self.set(0.0)
        except ForceFeedbackUnavailable:
            pass
        finally:
            self.device.close()
