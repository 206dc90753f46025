"""Shared by the input-device and drive tests (pytest puts tests/ on sys.path)."""

import pytest

from hasa_env.devices.virtual import VirtualJoystickUnavailable


def virtual_or_skip(factory):
    """``factory()`` (an SDL virtual joystick), or skip the test where SDL has none."""
    try:
        return factory()
    except VirtualJoystickUnavailable as exc:  # pragma: no cover - depends on the pygame build
        pytest.skip(f"no SDL virtual joystick: {exc}")
