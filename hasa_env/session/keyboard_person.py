"""A model of a person holding a lane with two steering keys: to tune the keyboard ramp.

Keyboard steering is a ramp (:class:`hasa_env.devices.sources.KeyboardSource`):
a held key drives the road-wheel angle linearly towards a full angle, a
released one lets it decay to zero. A person cannot hold a lane with every
ramp: the key acts on the steering angle, the angle on the yaw rate, the yaw
rate on the lateral velocity, so a ramp that is too fast or too large makes
each press a big swerve. :class:`KeyboardPerson` models how a person steers
with keys, so ramps can be compared without a person at hand:

- **perception with a delay**: the person acts on what the car did
  ``reaction_time`` s ago (0.25 s: a simple reaction time) and misjudges the
  lateral offset by a Gaussian error of ``perception_noise`` m;
- **preview**: they judge where the car will be ``preview`` s ahead (1 s),
  from its offset, its heading and how fast it turns relative to the road;
- **presses**: every ``decision_interval`` s (0.15 s) they press the key
  towards the lane centre if that predicted offset exceeds ``deadband``
  (0.1 m), for ``press_gain`` s per metre beyond it (at least ``min_press``,
  at most one interval): short taps for small errors, a held key for large
  ones.

:func:`drive_with_keyboard` drives one run with a calibration and such a
person; :func:`ramp_table` compares calibrations over tracks, speeds, seeds
and reaction times, and also measures an accidental 0.8 s press (uncorrected:
when the car leaves the road; corrected by the person: the largest offset).
``python -m hasa_env.session.keyboard_person`` prints the table for the
shipped ramp and the one it replaced (docs/design.md §11, decision 23).
"""

from __future__ import annotations

import math
import os
import warnings
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hasa_env.devices.calibration import KeyboardCalibration, shipped_calibration
from hasa_env.devices.sources import KeyboardSource
from hasa_env.envs.lane_keeping import LaneKeepingEnv

__all__ = [
    "PREVIOUS_RAMP",
    "KeyboardDrive",
    "KeyboardPerson",
    "drive_with_keyboard",
    "ramp_table",
]

PREVIOUS_RAMP = KeyboardCalibration(
    name="keyboard (before issue 15)",
    max_road_wheel_angle_deg=3.0,
    ramp_time=0.5,
    return_time_constant=0.25,
)
"""The keyboard ramp shipped before issue 15 (3 deg in 0.5 s, 0.25 s return): too touchy."""

IN_LANE = 0.9
"""|y| (m) below which the car stays inside its own 3.6 m lane (its half width is 0.9 m)."""


@dataclass
class KeyboardPerson:
    """A person who steers with two keys (see the module docstring; units s, m).

    Call :meth:`reset` before a run and :meth:`key` once per simulation step
    with the env's latest ``info``; it returns the steering key held over the
    next step: ``"left"``, ``"right"`` or None.
    """

    reaction_time: float = 0.25
    decision_interval: float = 0.15
    preview: float = 1.0
    deadband: float = 0.1
    press_gain: float = 0.4
    min_press: float = 0.05
    perception_noise: float = 0.05
    wheelbase: float = 2.8
    _history: deque[dict[str, Any]] = field(default_factory=deque, init=False, repr=False)
    _rng: np.random.Generator = field(
        default_factory=lambda: np.random.default_rng(0), init=False, repr=False
    )

    def __post_init__(self) -> None:
        for name in ("reaction_time", "preview", "deadband", "press_gain", "perception_noise"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"KeyboardPerson.{name} must be >= 0, got {value!r}")
        for name in ("decision_interval", "min_press", "wheelbase"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"KeyboardPerson.{name} must be > 0, got {value!r}")

    def reset(self, seed: int, dt: float) -> None:
        """Start a run sampled every ``dt`` s; ``seed`` seeds the perception errors."""
        self._rng = np.random.default_rng(seed)
        self._dt = float(dt)
        self._lag = int(round(self.reaction_time / dt))
        self._history = deque(maxlen=self._lag + 1)
        self._held: str | None = None
        self._release_at = 0.0
        self._next_decision = 0.0

    def predicted_offset(self, info: dict[str, Any]) -> float:
        """Where the person judges the car will be (m, lateral) ``preview`` s ahead."""
        v, heading, y = float(info["speed"]), float(info["heading"]), float(info["lateral_offset"])
        turning = math.tan(float(info["steering"])) / self.wheelbase - float(info["road_curvature"])
        t = self.preview
        return y + v * math.sin(heading) * t + 0.5 * v * v * turning * t * t

    def key(self, info: dict[str, Any]) -> str | None:
        """The steering key held over the next step, given the env's latest ``info``."""
        self._history.append(info)
        t = float(info["time"])
        if t >= self._next_decision - 1e-9:
            self._next_decision = t + self.decision_interval
            seen = self._history[0]  # what the car did reaction_time s ago
            error = self.predicted_offset(seen) + self._rng.normal(0.0, self.perception_noise)
            if abs(error) > self.deadband:
                self._held = "left" if error < 0 else "right"
                press = self.press_gain * (abs(error) - self.deadband)
                self._release_at = t + min(self.decision_interval, max(self.min_press, press))
            else:
                self._held = None
        elif self._held is not None and t >= self._release_at - 1e-9:
            self._held = None
        return self._held


@dataclass(frozen=True)
class KeyboardDrive:
    """One run steered with keys: did the car stay on the road, and how well (m, s)."""

    left_road: bool
    seconds: float
    rms_offset: float
    max_offset: float
    """Largest |y| after the first 2 s (the start at y = -0.5 m is the protocol's)."""
    presses_per_second: float

    @property
    def in_lane(self) -> bool:
        """On the road and never further than :data:`IN_LANE` from the lane centre."""
        return not self.left_road and self.max_offset < IN_LANE


def drive_with_keyboard(
    calibration: KeyboardCalibration,
    person: KeyboardPerson | None = None,
    *,
    track: str = "straight",
    speed: float = 15.0,
    seconds: float = 30.0,
    seed: int = 0,
    mistake: float = 0.0,
) -> KeyboardDrive:
    """One run from y = -0.5 m at ``speed`` m/s, steered by ``person`` through ``calibration``.

    ``mistake`` > 0 holds the left key for that many seconds at the start
    before the person takes over; with ``person=None`` nobody corrects it
    (the car runs on with the steering released).
    """
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    import pygame  # pygame: only to resolve the calibration's key names

    env = LaneKeepingEnv(
        config={"track": track, "time_limit": seconds, "action": {"type": "physical"}}
    )
    _, info = env.reset(
        seed=seed,
        options={"lateral_offset": -0.5, "heading": 0.0, "speed": speed, "steering": 0.0},
    )
    dt = env.setup.dt
    keyboard = KeyboardSource(calibration, pygame)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # key_code warns before pygame.init(); names resolve
        codes = {side: pygame.key.key_code(calibration.keys[side][0]) for side in ("left", "right")}
    if person is not None:
        person.reset(seed, dt)
    held: str | None = None
    presses = 0
    offsets: list[float] = []
    left_road = False
    steps = int(round(seconds / dt))
    for k in range(steps):
        if k * dt < mistake:
            wanted: str | None = "left"
        else:
            wanted = person.key(info) if person is not None else None
        if wanted != held:
            if held is not None:
                keyboard.key_up(codes[held])
            if wanted is not None:
                keyboard.key_down(codes[wanted])
                presses += 1
            held = wanted
        reading = keyboard.read(dt)
        _, _, terminated, truncated, info = env.step([reading.road_wheel_angle, 0.0])
        offsets.append(float(info["lateral_offset"]))
        if terminated:
            left_road = True
        if terminated or truncated:
            break
    env.close()
    y = np.asarray(offsets)
    driven = len(y) * dt
    settled = y[int(round(2.0 / dt)) :]
    return KeyboardDrive(
        left_road=left_road,
        seconds=driven,
        rms_offset=float(np.sqrt(np.mean(y**2))),
        max_offset=float(np.max(np.abs(settled))) if settled.size else math.nan,
        presses_per_second=presses / driven if driven > 0 else 0.0,
    )


def ramp_table(
    calibrations: Sequence[KeyboardCalibration],
    *,
    tracks: Sequence[str] = ("straight", "curved"),
    speeds: Sequence[float] = (15.0, 20.0),
    seeds: Sequence[int] = (0, 1, 2, 3, 4),
    reaction_times: Sequence[float] = (0.2, 0.25, 0.3),
    seconds: float = 30.0,
) -> list[dict[str, Any]]:
    """Per calibration and speed: runs in lane, RMS and largest offset (m), and the
    accidental 0.8 s press (uncorrected: when the car leaves the road; corrected
    by the person: the largest offset), over tracks, seeds and reaction times."""
    rows = []
    for cal in calibrations:
        uncorrected = drive_with_keyboard(cal, None, seconds=20.0, mistake=0.8)
        corrected = drive_with_keyboard(cal, KeyboardPerson(), seconds=10.0, mistake=0.8)
        for speed in speeds:
            drives = [
                drive_with_keyboard(
                    cal,
                    KeyboardPerson(reaction_time=reaction),
                    track=track,
                    speed=speed,
                    seconds=seconds,
                    seed=seed,
                )
                for track in tracks
                for seed in seeds
                for reaction in reaction_times
            ]
            rows.append(
                {
                    "calibration": cal.name,
                    "ramp": f"{cal.max_road_wheel_angle_deg:g} deg in {cal.ramp_time:g} s, "
                    f"return {cal.return_time_constant:g} s",
                    "speed": speed,
                    "runs": len(drives),
                    "in_lane": sum(d.in_lane for d in drives),
                    "left_road": sum(d.left_road for d in drives),
                    "rms_offset": float(np.mean([d.rms_offset for d in drives])),
                    "max_offset": float(np.max([d.max_offset for d in drives])),
                    "presses_per_second": float(np.mean([d.presses_per_second for d in drives])),
                    "mistake_off_road_at": uncorrected.seconds if uncorrected.left_road else None,
                    "mistake_corrected_max_offset": corrected.max_offset,
                }
            )
    return rows


def main() -> None:
    """Print :func:`ramp_table` for the shipped ramp and the one it replaced."""
    shipped = shipped_calibration("keyboard")
    assert isinstance(shipped, KeyboardCalibration)
    print(
        f"{'ramp':38s} {'v (m/s)':>7s} {'in lane':>8s} {'off road':>8s} {'RMS y':>6s} "
        f"{'max |y|':>7s} {'presses/s':>9s}  0.8 s press: off road at / corrected max |y|"
    )
    for row in ramp_table([PREVIOUS_RAMP, shipped]):
        off = row["mistake_off_road_at"]
        print(
            f"{row['ramp']:38s} {row['speed']:7.0f} {row['in_lane']:4d}/{row['runs']:<3d} "
            f"{row['left_road']:8d} {row['rms_offset']:6.3f} {row['max_offset']:7.2f} "
            f"{row['presses_per_second']:9.2f}  "
            f"{'never' if off is None else f'{off:.2f} s'} / "
            f"{row['mistake_corrected_max_offset']:.2f} m"
        )


if __name__ == "__main__":
    main()
