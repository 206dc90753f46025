"""SDL virtual joysticks through ctypes, in pygame's own SDL2 library.

SDL 2.0.14+ can attach a *virtual* joystick (``SDL_JoystickAttachVirtual``)
whose axes and buttons a program sets itself; SDL then reports it like a
real device: ``JOYDEVICEADDED`` when attached, ``JOYAXISMOTION`` when an axis
changes (at the next event pump), ``JOYDEVICEREMOVED`` when detached. That
exercises the real hot-plug and event path without hardware, headless, so
the tests and the scripted drives (a synthetic driver turning a virtual G29)
use it.

The functions must come from the *same* SDL library instance pygame uses.
:func:`find_sdl_library` looks for it, in order: the ``libSDL2`` mapped into
this process (Linux ``/proc/self/maps``, after importing pygame), then the
libraries bundled next to the pygame package (``pygame.libs``,
``pygame_ce.libs``, ``pygame/.dylibs``, ``SDL2.dll``), choosing one whose
version matches ``pygame.get_sdl_version()``. :class:`VirtualJoystick`
checks that pygame sees the attached device and raises
:class:`VirtualJoystickUnavailable` otherwise.
"""

from __future__ import annotations

import ctypes
import glob
import os
import sys
from pathlib import Path
from typing import Any

__all__ = [
    "VirtualJoystick",
    "VirtualJoystickUnavailable",
    "find_sdl_library",
    "sdl_library",
    "JOYSTICK_TYPE_WHEEL",
    "JOYSTICK_TYPE_GAMECONTROLLER",
    "G29_VENDOR_ID",
    "G29_PRODUCT_ID",
]

JOYSTICK_TYPE_GAMECONTROLLER = 1
JOYSTICK_TYPE_WHEEL = 2
G29_VENDOR_ID = 0x046D
G29_PRODUCT_ID = 0xC24F
_DESC_VERSION = 1


class VirtualJoystickUnavailable(RuntimeError):
    """pygame's SDL library (or its virtual-joystick API) could not be found or used."""


class _Version(ctypes.Structure):
    _fields_ = [("major", ctypes.c_uint8), ("minor", ctypes.c_uint8), ("patch", ctypes.c_uint8)]


class _VirtualJoystickDesc(ctypes.Structure):
    """``SDL_VirtualJoystickDesc`` of SDL 2.24 - 2.32 (version 1); callbacks left NULL."""

    _fields_ = [
        ("version", ctypes.c_uint16),
        ("type", ctypes.c_uint16),
        ("naxes", ctypes.c_uint16),
        ("nbuttons", ctypes.c_uint16),
        ("nhats", ctypes.c_uint16),
        ("vendor_id", ctypes.c_uint16),
        ("product_id", ctypes.c_uint16),
        ("padding", ctypes.c_uint16),
        ("button_mask", ctypes.c_uint32),
        ("axis_mask", ctypes.c_uint32),
        ("name", ctypes.c_char_p),
        ("userdata", ctypes.c_void_p),
        ("Update", ctypes.c_void_p),
        ("SetPlayerIndex", ctypes.c_void_p),
        ("Rumble", ctypes.c_void_p),
        ("RumbleTriggers", ctypes.c_void_p),
        ("SetLED", ctypes.c_void_p),
        ("SendEffect", ctypes.c_void_p),
    ]


def _candidates() -> list[str]:
    paths: list[str] = []
    if sys.platform.startswith("linux"):
        try:
            with open("/proc/self/maps", encoding="utf-8") as f:
                for line in f:
                    part = line.split()[-1] if line.split() else ""
                    if (
                        "libSDL2-2" in part
                        or "libSDL2-2.0" in part
                        or os.path.basename(part).startswith("libSDL2-")
                    ):
                        if part.startswith("/") and part not in paths:
                            paths.append(part)
        except OSError:
            pass
    import pygame  # pygame: only when a virtual device is used

    pkg = Path(pygame.__file__).resolve().parent
    site = pkg.parent
    patterns = [
        str(site / "pygame.libs" / "libSDL2-*"),
        str(site / "pygame_ce.libs" / "libSDL2-*"),
        str(pkg / ".dylibs" / "libSDL2*"),
        str(pkg / "SDL2.dll"),
        str(pkg / "libSDL2*"),
    ]
    for pattern in patterns:
        for p in sorted(glob.glob(pattern)):
            if "SDL2_" not in os.path.basename(p) and p not in paths:
                paths.append(p)
    return paths


def _version_of(lib: Any) -> tuple[int, int, int]:
    v = _Version()
    lib.SDL_GetVersion(ctypes.byref(v))
    return (v.major, v.minor, v.patch)


def find_sdl_library() -> str:
    """Path of the SDL2 library pygame uses (see the module docstring).

    Raises:
        VirtualJoystickUnavailable: none found, or none with pygame's SDL version.
    """
    import pygame  # pygame: only when a virtual device is used

    wanted = tuple(pygame.get_sdl_version())
    tried = []
    for path in _candidates():
        try:
            lib = ctypes.CDLL(path)
            version = _version_of(lib)
        except (OSError, AttributeError) as exc:
            tried.append(f"{path} ({exc})")
            continue
        if version == wanted:
            return path
        tried.append(f"{path} (SDL {'.'.join(map(str, version))})")
    raise VirtualJoystickUnavailable(
        f"pygame's SDL {'.'.join(map(str, wanted))} library not found next to {pygame.__file__}; "
        f"tried: {', '.join(tried) or 'nothing'}"
    )


_LIB: Any = None


def sdl_library() -> Any:
    """pygame's SDL2 library as a ``ctypes.CDLL`` with the joystick functions typed."""
    global _LIB
    if _LIB is not None:
        return _LIB
    lib = ctypes.CDLL(find_sdl_library())
    try:
        lib.SDL_JoystickAttachVirtual.argtypes = [
            ctypes.c_int,
            ctypes.c_int,
            ctypes.c_int,
            ctypes.c_int,
        ]
        lib.SDL_JoystickAttachVirtual.restype = ctypes.c_int
        lib.SDL_JoystickDetachVirtual.argtypes = [ctypes.c_int]
        lib.SDL_JoystickDetachVirtual.restype = ctypes.c_int
        lib.SDL_JoystickOpen.argtypes = [ctypes.c_int]
        lib.SDL_JoystickOpen.restype = ctypes.c_void_p
        lib.SDL_JoystickClose.argtypes = [ctypes.c_void_p]
        lib.SDL_JoystickClose.restype = None
        lib.SDL_JoystickInstanceID.argtypes = [ctypes.c_void_p]
        lib.SDL_JoystickInstanceID.restype = ctypes.c_int32
        lib.SDL_NumJoysticks.argtypes = []
        lib.SDL_NumJoysticks.restype = ctypes.c_int
        lib.SDL_JoystickGetDeviceInstanceID.argtypes = [ctypes.c_int]
        lib.SDL_JoystickGetDeviceInstanceID.restype = ctypes.c_int32
        lib.SDL_JoystickSetVirtualAxis.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int16]
        lib.SDL_JoystickSetVirtualAxis.restype = ctypes.c_int
        lib.SDL_JoystickSetVirtualButton.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_uint8]
        lib.SDL_JoystickSetVirtualButton.restype = ctypes.c_int
        lib.SDL_JoystickName.argtypes = [ctypes.c_void_p]
        lib.SDL_JoystickName.restype = ctypes.c_char_p
        lib.SDL_GetError.argtypes = []
        lib.SDL_GetError.restype = ctypes.c_char_p
    except AttributeError as exc:
        raise VirtualJoystickUnavailable(
            f"SDL library has no virtual-joystick API (needs SDL >= 2.0.14): {exc}"
        ) from None
    if hasattr(lib, "SDL_JoystickAttachVirtualEx"):
        lib.SDL_JoystickAttachVirtualEx.argtypes = [ctypes.POINTER(_VirtualJoystickDesc)]
        lib.SDL_JoystickAttachVirtualEx.restype = ctypes.c_int
    _LIB = lib
    return lib


def axis_to_int16(value: float) -> int:
    """SDL's int16 axis value for a normalised value in [-1, 1] (saturating)."""
    v = -1.0 if value < -1.0 else (1.0 if value > 1.0 else float(value))
    return int(round(v * 32767.0)) if v > -1.0 else -32768


class VirtualJoystick:
    """A virtual joystick attached to pygame's SDL; set its axes, press its buttons, detach it.

    pygame's joystick subsystem must be initialised (:func:`hasa_env.devices.init_pygame_input`).
    The ``JOYDEVICEADDED`` event is queued on attach; axis changes are reported
    at the next ``pygame.event.pump()`` / ``get()``.

    Args:
        num_axes, num_buttons, num_hats: the device's controls.
        name: device name (needs SDL >= 2.24; older SDL names it "Virtual Joystick").
        vendor_id, product_id: USB ids reported (SDL >= 2.24).
        joystick_type: SDL joystick type (2 = wheel).

    Example: a virtual G29 (its pedals at rest)::

        wheel = VirtualJoystick.g29()
        wheel.set_axis(0, -0.1)   # a little to the left
    """

    def __init__(
        self,
        num_axes: int = 4,
        num_buttons: int = 8,
        num_hats: int = 0,
        *,
        name: str = "hasa-env virtual joystick",
        vendor_id: int = 0,
        product_id: int = 0,
        joystick_type: int = JOYSTICK_TYPE_WHEEL,
    ) -> None:
        import pygame  # pygame: only when a virtual device is used

        if not pygame.joystick.get_init():
            raise VirtualJoystickUnavailable(
                "call pygame.joystick.init() (or init_pygame_input()) first"
            )
        lib = sdl_library()
        self._lib = lib
        self.name = name
        self.num_axes = num_axes
        before = pygame.joystick.get_count()
        if hasattr(lib, "SDL_JoystickAttachVirtualEx"):
            self._name_bytes = name.encode("utf-8")
            desc = _VirtualJoystickDesc(
                version=_DESC_VERSION,
                type=joystick_type,
                naxes=num_axes,
                nbuttons=num_buttons,
                nhats=num_hats,
                vendor_id=vendor_id,
                product_id=product_id,
                name=self._name_bytes,
            )
            index = lib.SDL_JoystickAttachVirtualEx(ctypes.byref(desc))
        else:  # pragma: no cover - SDL < 2.24
            index = lib.SDL_JoystickAttachVirtual(joystick_type, num_axes, num_buttons, num_hats)
        if index < 0:
            raise VirtualJoystickUnavailable(
                f"SDL_JoystickAttachVirtual failed: {lib.SDL_GetError().decode()}"
            )
        self._handle = lib.SDL_JoystickOpen(index)
        if not self._handle:
            lib.SDL_JoystickDetachVirtual(index)
            raise VirtualJoystickUnavailable(
                f"SDL_JoystickOpen failed: {lib.SDL_GetError().decode()}"
            )
        self.instance_id = int(lib.SDL_JoystickInstanceID(self._handle))
        reported = lib.SDL_JoystickName(self._handle)
        self.name = reported.decode("utf-8", "replace") if reported else name
        """The name SDL reports (``name`` needs SDL >= 2.24)."""
        if pygame.joystick.get_count() != before + 1:
            self._release(index)
            raise VirtualJoystickUnavailable(
                "the virtual joystick was attached to an SDL library pygame does not use"
            )
        self.attached = True

    @classmethod
    def g29(
        cls, name: str = "Logitech G29 Driving Force Racing Wheel (virtual)"
    ) -> VirtualJoystick:
        """A virtual wheel laid out like a G29 on Linux (axes 0 wheel, 1 clutch, 2 throttle,
        3 brake), with the pedals at rest (+1)."""
        wheel = cls(
            num_axes=6,
            num_buttons=25,
            num_hats=1,
            name=name,
            vendor_id=G29_VENDOR_ID,
            product_id=G29_PRODUCT_ID,
        )
        for axis in (1, 2, 3):
            wheel.set_axis(axis, 1.0)
        return wheel

    def device_index(self) -> int:
        """Current SDL device index (indices shift when other devices go away)."""
        lib = self._lib
        for i in range(lib.SDL_NumJoysticks()):
            if lib.SDL_JoystickGetDeviceInstanceID(i) == self.instance_id:
                return i
        raise VirtualJoystickUnavailable(
            f"virtual joystick {self.instance_id} is no longer attached"
        )

    def set_axis(self, axis: int, value: float) -> None:
        """Set axis ``axis`` to a normalised ``value`` in [-1, 1] (int16 inside SDL)."""
        self._check(axis, self.num_axes, "axis")
        if self._lib.SDL_JoystickSetVirtualAxis(self._handle, axis, axis_to_int16(value)) < 0:
            raise VirtualJoystickUnavailable(
                f"SDL_JoystickSetVirtualAxis: {self._lib.SDL_GetError().decode()}"
            )

    def set_button(self, button: int, pressed: bool) -> None:
        """Press (True) or release (False) button ``button``."""
        if not self.attached:
            raise VirtualJoystickUnavailable("the virtual joystick was detached")
        if self._lib.SDL_JoystickSetVirtualButton(self._handle, button, 1 if pressed else 0) < 0:
            raise VirtualJoystickUnavailable(
                f"SDL_JoystickSetVirtualButton: {self._lib.SDL_GetError().decode()}"
            )

    def _check(self, index: int, count: int, what: str) -> None:
        if not self.attached:
            raise VirtualJoystickUnavailable("the virtual joystick was detached")
        if not 0 <= index < count:
            raise ValueError(f"{what} {index} out of range: this virtual joystick has {count}")

    def _release(self, index: int) -> None:
        self._lib.SDL_JoystickClose(self._handle)
        self._handle = None
        self._lib.SDL_JoystickDetachVirtual(index)

    def detach(self) -> None:
        """Unplug the device (pygame then reports ``JOYDEVICEREMOVED``); idempotent."""
        if not getattr(self, "attached", False):
            return
        index = self.device_index()
        self.attached = False
        self._release(index)

    def __enter__(self) -> VirtualJoystick:
        return self

    def __exit__(self, *exc: object) -> None:
        self.detach()
