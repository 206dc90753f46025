"""``hasa-drive``: people drive the lane-keeping env with a wheel, a joystick or the keyboard.

Commands::

    hasa-drive --participant P07 [--track straight|curved] [--bias random|B] [--runs 10]
    hasa-drive calibrate [--output FILE]
    hasa-drive synthetic --driver Ill [--population paper] [--participant NAME]

The drive follows the paper's protocol: every run lasts 30 s, starts at
15 m/s and y = -0.5 m in the right lane; a countdown precedes it. Each run is
recorded with :class:`hasa_env.recording.RecordingWrapper` under
``recordings/<participant>/run_NNN.csv`` (+ ``.json`` sidecar), every step
flushed at once (crash-safe: a killed process keeps every completed step).
Next to each run, ``run_NNN.inputs.tsv`` holds the raw input per step
(:func:`load_raw_inputs`): the raw axis values of the steering wheel and
pedals as pygame reported them, the mapped angles and pedal travels, the
source (keyboard or joystick) and the wall-clock time; the recording CSV
keeps its standard columns.

The simulation clock drives the physics: each frame the loop runs as many
100 Hz steps as the wall clock is due (never more than a quarter second's
worth: after a stall it re-anchors instead of sprinting), then draws one
frame, capped at ``--fps`` (60). A pause (P, or the wheel unplugged) freezes
the simulation clock; nothing is recorded while paused.

``hasa-drive synthetic`` drives through the same loop, headless and as fast
as possible, with a synthetic driver (:mod:`hasa_env.drivers`) turning an SDL
virtual G29 (:mod:`hasa_env.devices.virtual`); its recordings are labelled
``"synthetic": true`` in the sidecar metadata. ``recordings/sample`` was made
that way.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import os
import re
import signal
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hasa_env.config import ConfigError, deep_merge, make_config
from hasa_env.devices.calibration import (
    CalibrationError,
    JoystickCalibration,
    KeyboardCalibration,
    PedalAxis,
    SteeringAxis,
    load_calibration,
    save_calibration,
    shipped_calibration,
    user_calibration_path,
)
from hasa_env.devices.sources import RAW_INPUT_COLUMNS, InputManager, InputReading, Notice

__all__ = [
    "DriveSettings",
    "DriveSession",
    "RawInputWriter",
    "VirtualWheelDriver",
    "estimator_wrapper",
    "Calibrator",
    "load_raw_inputs",
    "raw_inputs_path",
    "no_screen_reason",
    "main",
    "EXIT_NO_SCREEN",
]

EXIT_NO_SCREEN = 3
"""Exit status of ``hasa-drive`` when there is no screen to drive on."""
RAW_INPUTS_SUFFIX = ".inputs.tsv"
MAX_CATCH_UP = 0.25
"""Seconds of simulation the real-time loop runs at most to catch up after a stall."""
_PARTICIPANT_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]*")


# ------------------------------------------------------------------ settings
@dataclass
class DriveSettings:
    """One session of runs (units: s, m/s, m).

    Attributes:
        participant: participant id; recordings go to ``output / participant``.
        track: ``"straight"`` or ``"curved"``.
        bias: camera bias b (m) of every run, or None to draw it per run
            (equally likely hypotheses, from the run's seed).
        runs: number of runs.
        seconds: length of a run (the paper: 30 s).
        speed: initial speed (15 m/s).
        lateral_offset: initial lateral offset y (-0.5 m).
        output: root directory of the recordings.
        seed: root seed of the runs' seeds (None: fresh entropy, recorded).
        countdown: seconds of countdown before each run (real time only).
        config: extra env configuration deep-merged onto the defaults.
        fsync: also fsync every recorded row (survives power loss).
    """

    participant: str
    track: str = "straight"
    bias: float | None = None
    runs: int = 10
    seconds: float = 30.0
    speed: float = 15.0
    lateral_offset: float = -0.5
    output: Path = Path("recordings")
    seed: int | None = None
    countdown: float = 3.0
    config: Mapping[str, Any] = field(default_factory=dict)
    fsync: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.participant, str) or not _PARTICIPANT_RE.fullmatch(self.participant):
            raise ValueError(
                "participant id must be letters, digits, '_', '-', '.' "
                "(starting with a letter or digit), "
                f"got {self.participant!r}"
            )
        if isinstance(self.runs, bool) or not isinstance(self.runs, int) or self.runs < 1:
            raise ValueError(f"runs must be a positive integer, got {self.runs!r}")
        if not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"seconds must be > 0, got {self.seconds!r}")
        if self.seed is not None and (isinstance(self.seed, bool) or self.seed < 0):
            raise ValueError(f"seed must be a non-negative integer or None, got {self.seed!r}")
        self.output = Path(self.output)

    def env_config(self) -> dict[str, Any]:
        """The env configuration of every run (validated)."""
        base = {"track": self.track, "time_limit": self.seconds, "action": {"type": "physical"}}
        return make_config(deep_merge(base, self.config))

    def reset_options(self) -> dict[str, Any]:
        """``reset`` options of every run: the protocol's initial state and, if fixed, the bias."""
        options: dict[str, Any] = {
            "lateral_offset": float(self.lateral_offset),
            "heading": 0.0,
            "speed": float(self.speed),
            "steering": 0.0,
        }
        if self.bias is not None:
            options["bias"] = float(self.bias)
        return options

    @property
    def directory(self) -> Path:
        return self.output / self.participant


# ---------------------------------------------------------------- raw inputs
def raw_inputs_path(recording_csv: str | os.PathLike[str]) -> Path:
    """The raw-input side file of a recording: ``run_000.csv`` -> ``run_000.inputs.tsv``."""
    p = Path(recording_csv)
    return p.with_name(p.stem + RAW_INPUTS_SUFFIX)


RAW_INPUT_HEADER = ("step", "time", "wall_time", *RAW_INPUT_COLUMNS)
RAW_INPUT_UNITS = {
    "step": "1",
    "time": "s (simulation)",
    "wall_time": "s since the run started (wall clock, includes pauses)",
    "source": "keyboard | joystick:<device name>",
    "raw_steering": "raw axis value as pygame reports it (about -1..1); NaN for the keyboard",
    "raw_throttle": "raw axis value; NaN for the keyboard",
    "raw_brake": "raw axis value; NaN for the keyboard",
    "steering_wheel_angle": "rad (left positive)",
    "road_wheel_angle": "rad (left positive; the commanded steering)",
    "throttle": "pedal travel 0..1",
    "brake": "pedal travel 0..1",
    "acceleration": "m/s^2 (commanded)",
}


class RawInputWriter:
    """Writes the raw-input side file, one tab-separated line per env step, flushed at once.

    Row k (k >= 1) is the input applied over the step that ended at recording row k.
    """

    def __init__(self, path: str | os.PathLike[str], fsync: bool = False) -> None:
        self.path = Path(path)
        if self.path.exists():
            # left over from a recording whose CSV and sidecar were removed: keep it, aside
            self.path.rename(self.path.with_name(f"{self.path.name}.orphaned-{time.time_ns()}"))
        self._file = open(self.path, "x", encoding="utf-8", newline="\n")  # noqa: SIM115
        self.fsync = fsync
        self._file.write("\t".join(RAW_INPUT_HEADER) + "\n")
        self._file.flush()

    def write(self, step: int, sim_time: float, wall_time: float, reading: InputReading) -> None:
        fields = [str(int(step)), repr(float(sim_time)), repr(float(wall_time))]
        for name, value in zip(RAW_INPUT_COLUMNS, reading.as_row(), strict=True):
            if name == "source":
                fields.append(str(value).replace("\t", " ").replace("\n", " "))
            else:
                fields.append(repr(float(value)))
        self._file.write("\t".join(fields) + "\n")
        self._file.flush()
        if self.fsync:
            os.fsync(self._file.fileno())

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


def load_raw_inputs(path: str | os.PathLike[str]) -> Any:
    """Read a raw-input side file (or the one next to a recording CSV) as a pandas DataFrame."""
    import pandas as pd

    p = Path(path)
    if p.suffix == ".csv":
        p = raw_inputs_path(p)
    frame = pd.read_csv(
        p, sep="\t", dtype={"source": str}, keep_default_na=False, na_values=["nan"]
    )
    missing = [c for c in RAW_INPUT_HEADER if c not in frame.columns]
    if missing:
        raise ValueError(f"{p}: not a raw-input file, missing column(s) {', '.join(missing)}")
    return frame


# ------------------------------------------------------------------- screen
def no_screen_reason() -> str | None:
    """Why there is no screen to drive on (None if there seems to be one)."""
    driver = os.environ.get("SDL_VIDEODRIVER", "").lower()
    if driver in ("dummy", "offscreen", "evdev"):
        return f"SDL_VIDEODRIVER={driver} (a video driver without a screen)"
    if sys.platform.startswith("linux") and not driver:
        if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
            return "neither DISPLAY nor WAYLAND_DISPLAY is set (no X11 or Wayland session)"
    return None


# ------------------------------------------------------------------ session
@dataclass
class RunResult:
    """What one run produced."""

    path: Path
    steps: int
    end_reason: str


class DriveSession:
    """The drive loop: countdown, real-time simulation, input, recording, pauses, hot-plug.

    Args:
        settings: the session (participant, track, runs, ...).
        inputs: the input layer (keyboard + joysticks).
        display: a pygame display surface to draw on, or None (no window).
        realtime: True: the wall clock paces the simulation (a human drives);
            False: one step per loop iteration, as fast as possible (scripted
            drives, tests), no countdown and no waiting between runs.
        hook: called with the session before every simulation step and on
            every idle iteration (paused, between runs); a scripted driver
            turns a virtual wheel here.
        view: ``"driver"`` or ``"top_down"`` (when ``display`` is given).
        fps: frame-rate cap of the window (Hz).
        frame_every: without ``realtime``, draw every this many steps.
        show_points: draw the near and far points in the driver's view.
        metadata: extra JSON-serializable fields for every recording's sidecar metadata.
        weights: hypothesis weights for the HUD (:data:`hasa_env.rendering.WeightSource`).
        env_wrapper: wraps each run's env before recording (e.g. an estimator
            that adds weights to ``info``); None: no wrapper.
        log: where messages go (default ``print``).
        max_idle_iterations: without ``realtime``, give up (RuntimeError) after
            this many iterations without a step (a scripted drive stuck in a pause).
    """

    def __init__(
        self,
        settings: DriveSettings,
        inputs: InputManager,
        *,
        display: Any = None,
        realtime: bool = True,
        hook: Callable[[DriveSession], None] | None = None,
        view: str = "driver",
        fps: int = 60,
        frame_every: int = 1,
        show_points: bool = False,
        metadata: Mapping[str, Any] | None = None,
        weights: Any = None,
        env_wrapper: Callable[[Any], Any] | None = None,
        log: Callable[[str], None] = print,
        max_idle_iterations: int = 100_000,
    ) -> None:
        from hasa_env.lane_keeping import LaneKeepingEnv

        self.settings = settings
        self.inputs = inputs
        self.display = display
        self.realtime = realtime
        self.hook = hook
        self.fps = int(fps)
        self.frame_every = max(1, int(frame_every))
        self.metadata = dict(metadata or {})
        self.weights = weights
        self.env_wrapper = env_wrapper
        self.log = log
        self.max_idle_iterations = max_idle_iterations
        self.config = settings.env_config()
        self._preview_env = LaneKeepingEnv(config=self.config)
        self.setup = self._preview_env.setup
        self.road = self.setup.road
        self.dt = self.setup.dt * self.setup.action_repeat
        self.renderer = None
        if display is not None:
            from hasa_env.rendering import make_renderer

            size = display.get_size()
            self.config = deep_merge(
                self.config,
                {"render": {"width": size[0], "height": size[1], "show_points": show_points}},
            )
            self.config = make_config(self.config)
            self._preview_env = LaneKeepingEnv(config=self.config)
            self.setup = self._preview_env.setup
            self.renderer = make_renderer(self.setup, "rgb_array", view=view)
        self.state = "idle"
        """One of ``idle``, ``countdown``, ``driving``, ``paused``, ``between_runs``, ``quit``."""
        self.message: str | None = None
        self.info: dict[str, Any] | None = None
        self.run_index = -1
        """0-based index of the current run."""
        self.run_seed: int | None = None
        self.steps = 0
        """Env steps taken in the current run."""
        self.results: list[RunResult] = []
        self._frame_clock = None
        self._root_seed = (
            settings.seed
            if settings.seed is not None
            else int(np.random.SeedSequence().entropy % 2**63)
        )

    # ---------------------------------------------------------- helpers
    def run_seeds(self) -> list[int]:
        """The env seed of every run, derived from the root seed (recorded in the metadata)."""
        state = np.random.SeedSequence(self._root_seed).generate_state(
            2 * self.settings.runs, np.uint32
        )
        return [int(state[2 * i]) << 21 ^ int(state[2 * i + 1]) for i in range(self.settings.runs)]

    def _call_hook(self) -> None:
        if self.hook is not None:
            self.hook(self)

    def _draw(self, info: Mapping[str, Any] | None, message: str | None = None) -> None:
        if self.display is None or self.renderer is None or info is None:
            return
        self.renderer.hud.steering_ratio = self.inputs.steering_ratio
        self.renderer.draw(info, self.weights, message, target=self.display)
        self._pg().display.flip()

    def _pg(self) -> Any:
        return self.inputs.pygame

    def _tick(self) -> None:
        if not self.realtime:
            return
        if self._frame_clock is None:
            self._frame_clock = self._pg().time.Clock()
        self._frame_clock.tick(self.fps)

    def _handle(self, notices: Sequence[Notice]) -> None:
        for n in notices:
            if n.kind == "quit":
                self.state = "quit"
                self.log(f"hasa-drive: stopping ({n.message})")
            elif n.kind == "disconnected":
                if self.state in ("driving", "countdown"):
                    self.state = "paused"
                self.message = n.message
                self.log(f"hasa-drive: {n.message}")
            elif n.kind == "connected":
                self.log(f"hasa-drive: {n.message}")
                if self.state in ("idle", "between_runs"):
                    self.message = f"{n.message}\nPress a wheel button or SPACE to start."
                elif self.state == "driving" and self.steps > 0:
                    self.state = "paused"
                    self.message = f"{n.message}\nPress a wheel button or SPACE to drive on."
                elif self.state == "paused":
                    self.message = f"{n.message}\nPress a wheel button or SPACE to drive on."
            elif n.kind == "ignored_device":
                self.log(f"hasa-drive: {n.message}")
            elif n.kind == "pause":
                if self.state == "driving":
                    self.state = "paused"
                    self.message = "PAUSED\nPress P, SPACE or a wheel button to drive on."
                elif self.state == "paused":
                    self._resume()
            elif n.kind == "confirm":
                if self.state == "paused":
                    self._resume()
                elif self.state in ("idle", "between_runs"):
                    self.state = "confirmed"

    def _resume(self) -> None:
        self.state = "driving"
        self.message = None
        self._anchor = time.perf_counter() - self.steps * self.dt
        self.log(f"hasa-drive: driving on with {self.inputs.source_name}")

    def _idle(self) -> None:
        self._call_hook()
        self._handle(self.inputs.poll())

    def _wait_for_confirm(self, info: Mapping[str, Any], message: str, state: str) -> bool:
        """Show ``message`` until the driver confirms (True) or quits (False)."""
        if not self.realtime:
            return self.state != "quit"
        self.state, self.message = state, message
        while self.state == state:
            self._idle()
            self._draw(info, self.message)
            self._tick()
        return self.state != "quit"

    def _countdown(self, info: Mapping[str, Any]) -> bool:
        if not self.realtime or self.settings.countdown <= 0:
            return True
        self.state = "countdown"
        end = time.perf_counter() + self.settings.countdown
        while self.state == "countdown":
            left = end - time.perf_counter()
            if left <= 0:
                break
            self._idle()
            self._draw(
                info, f"{math.ceil(left):d}\nrun {self.run_index + 1} of {self.settings.runs}"
            )
            self._tick()
        if self.state == "paused":  # the wheel went away during the countdown
            ok = self._wait_for_confirm(info, self.message or "paused", "paused")
            return ok and self._countdown(info)
        return self.state != "quit"

    # -------------------------------------------------------------- runs
    def _run_metadata(self, run_index: int, seed: int) -> dict[str, Any]:
        s = self.settings
        inputs = self.inputs
        meta: dict[str, Any] = {
            "tool": "hasa-drive",
            "participant": s.participant,
            "run": run_index + 1,
            "runs": s.runs,
            "root_seed": self._root_seed,
            "protocol": {
                "track": s.track,
                "seconds": s.seconds,
                "speed": s.speed,
                "lateral_offset": s.lateral_offset,
                "bias": "random" if s.bias is None else s.bias,
            },
            "input": {
                "source_at_start": inputs.source_name,
                "joystick_profiles": [p.to_dict() | {"source": p.source} for p in inputs.profiles],
                "keyboard": inputs.keyboard.calibration.to_dict()
                | {"source": inputs.keyboard.calibration.source},
                "raw_inputs": {
                    "file": f"<recording stem>{RAW_INPUTS_SUFFIX}",
                    "columns": list(RAW_INPUT_HEADER),
                    "units": RAW_INPUT_UNITS,
                },
            },
            "realtime": self.realtime,
            "synthetic": False,
        }
        return deep_merge(meta, self.metadata)

    def run(self) -> list[RunResult]:
        """Drive every run (or until the driver quits); return what was recorded."""
        seeds = self.run_seeds()
        _, preview = self._preview_env.reset(seed=seeds[0], options=self.settings.reset_options())
        self.info = preview
        self._handle(self.inputs.poll())  # devices already plugged in
        s = self.settings
        intro = (
            f"Participant {s.participant}: {s.runs} run(s) of {s.seconds:g} s "
            f"on the {s.track} track.\n"
            f"Driving with {self.inputs.source_name}.\n"
            "Press a wheel button or SPACE to start, Escape to stop."
        )
        if not self._wait_for_confirm(preview, intro, "idle"):
            return self.results
        for r in range(s.runs):
            self.run_index = r
            self.run_seed = seeds[r]
            _, preview = self._preview_env.reset(seed=seeds[r], options=s.reset_options())
            self.info = preview
            if not self._countdown(preview):
                break
            result = self._drive_run(r, seeds[r])
            if result is not None:
                self.results.append(result)
                self.log(
                    f"hasa-drive: run {r + 1}/{s.runs}: {result.steps} steps, "
                    f"{result.end_reason} -> {result.path}"
                )
            if self.state == "quit":
                break
            if r + 1 < s.runs:
                reason = (
                    "left the road"
                    if result is not None and result.end_reason == "terminated"
                    else "done"
                )
                msg = (
                    f"Run {r + 1} {reason}.\n"
                    f"Press a wheel button or SPACE for run {r + 2} of {s.runs}."
                )
                if not self._wait_for_confirm(self.info, msg, "between_runs"):
                    break
        return self.results

    def _drive_run(self, run_index: int, seed: int) -> RunResult | None:
        from hasa_env.lane_keeping import LaneKeepingEnv
        from hasa_env.recording import RecordingWrapper

        s = self.settings
        env: Any = LaneKeepingEnv(config=self.config)
        if self.env_wrapper is not None:
            env = self.env_wrapper(env)
        env_id = (
            "hasa_env/LaneKeepingCurved-v0" if s.track == "curved" else "hasa_env/LaneKeeping-v0"
        )
        recorder = RecordingWrapper(
            env,
            s.directory,
            prefix="run",
            metadata=self._run_metadata(run_index, seed),
            env_id=env_id,
            fsync=s.fsync,
        )
        raw: RawInputWriter | None = None
        end_reason = "stopped"
        self.steps = 0
        try:
            _, info = recorder.reset(seed=seed, options=s.reset_options())
            self.info = info
            assert recorder.path is not None
            raw = RawInputWriter(raw_inputs_path(recorder.path), fsync=s.fsync)
            self.state, self.message = "driving", None
            wall0 = time.perf_counter()
            self._anchor = wall0
            idle = 0
            last_frame_step = -1
            while True:
                if self.state == "quit":
                    break
                due = 0
                if self.state == "driving":
                    if self.realtime:
                        now = time.perf_counter()
                        due = int((now - self._anchor) / self.dt) - self.steps
                        if due * self.dt > MAX_CATCH_UP:
                            self.log(
                                f"hasa-drive: fell {due * self.dt:.2f} s behind real time; "
                                "re-anchoring"
                            )
                            self._anchor = now - (self.steps + 1) * self.dt
                            due = 1
                    else:
                        due = 1
                if due <= 0:
                    self._idle()
                    idle += 1
                    if not self.realtime and idle > self.max_idle_iterations:
                        raise RuntimeError(
                            f"scripted drive stuck in state {self.state!r} for {idle} iterations "
                            f"(message: {self.message!r})"
                        )
                done = False
                for _ in range(max(due, 0)):
                    self._call_hook()
                    self._handle(self.inputs.poll())
                    if self.state != "driving":
                        break
                    reading = self.inputs.read(self.dt)
                    _, _, terminated, truncated, info = recorder.step(reading.action())
                    self.steps += 1
                    self.info = info
                    raw.write(self.steps, info["time"], time.perf_counter() - wall0, reading)
                    idle = 0
                    if terminated or truncated:
                        end_reason = "terminated" if terminated else "truncated"
                        done = True
                        break
                if done:
                    break
                if self.display is not None:
                    if (
                        self.realtime
                        or self.state != "driving"
                        or self.steps - last_frame_step >= self.frame_every
                    ):
                        self._draw(self.info, self.message if self.state != "driving" else None)
                        last_frame_step = self.steps
                self._tick()
        finally:
            try:
                recorder.close()
            finally:
                if raw is not None:
                    raw.close()
        if recorder.path is None:
            return None
        if self.state != "quit":
            self.state = "between_runs"
        return RunResult(recorder.path, self.steps, end_reason)

    def close(self) -> None:
        self._preview_env.close()
        if self.renderer is not None:
            self.renderer.close()


# --------------------------------------------------------- scripted driving
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


# --------------------------------------------------------------- calibrate
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


def calibrate(
    output: Path,
    *,
    wheel_range_deg: float,
    steering_ratio: float,
    timeout: float,
    log: Callable[[str], None] = print,
    pygame_module: Any = None,
) -> int:
    """Run the calibration dialogue on the first joystick found; write ``output``; exit code."""
    from hasa_env.devices.sources import init_pygame_input

    if no_screen_reason() is not None:
        os.environ["SDL_VIDEODRIVER"] = (
            "dummy"  # the terminal is enough; pygame's event queue needs video
        )
    pg = pygame_module if pygame_module is not None else init_pygame_input()
    deadline = time.monotonic() + timeout
    joystick = None
    log("hasa-drive calibrate: waiting for a joystick or wheel (plug it in now) ...")
    while joystick is None:
        for e in pg.event.get():
            if e.type == pg.JOYDEVICEADDED:
                joystick = pg.joystick.Joystick(e.device_index)
                break
        if joystick is None:
            if time.monotonic() > deadline:
                log(
                    "hasa-drive calibrate: no joystick found; is the wheel plugged in "
                    "(and in PS3 mode for a G29)?"
                )
                return 1
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
        if any(e.type == pg.KEYDOWN and e.key == pg.K_ESCAPE for e in events) or any(
            e.type == pg.QUIT for e in events
        ):
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


# ---------------------------------------------------------------------- CLI
def _bias(text: str) -> float | None:
    if text == "random":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"bias must be 'random' or a number of metres, got {text!r}"
        ) from None


def _add_session_arguments(p: argparse.ArgumentParser, participant_required: bool) -> None:
    p.add_argument(
        "--participant", required=participant_required, help="participant id (folder name)"
    )
    p.add_argument("--track", choices=("straight", "curved"), default="straight")
    p.add_argument(
        "--bias",
        type=_bias,
        default=None,
        help="camera bias b in metres for every run, or 'random' (default: drawn per run)",
    )
    p.add_argument("--runs", type=int, default=10, help="number of runs (default 10)")
    p.add_argument("--seconds", type=float, default=30.0, help="length of a run in s (default 30)")
    p.add_argument("--speed", type=float, default=15.0, help="initial speed in m/s (default 15)")
    p.add_argument(
        "--lateral-offset", type=float, default=-0.5, help="initial y in m (default -0.5)"
    )
    p.add_argument(
        "--output",
        type=Path,
        default=Path("recordings"),
        help="root directory (default recordings)",
    )
    p.add_argument(
        "--seed", type=int, default=None, help="root seed of the runs (default: fresh, recorded)"
    )
    p.add_argument(
        "--fsync", action="store_true", help="fsync every recorded step (survives power loss)"
    )


def _joystick_profiles(path: Path | None, log: Callable[[str], None]) -> list[JoystickCalibration]:
    profiles: list[JoystickCalibration] = []
    if path is None and user_calibration_path().exists():
        path = user_calibration_path()
    if path is not None:
        cal = load_calibration(path)
        if not isinstance(cal, JoystickCalibration):
            raise CalibrationError(str(path), "device", "must be 'joystick' for --calibration")
        log(f"hasa-drive: using the calibration {path}")
        profiles.append(cal)
    profiles += [shipped_calibration("g29"), shipped_calibration("gamepad")]  # type: ignore[list-item]
    return profiles


def _drive(args: argparse.Namespace, log: Callable[[str], None]) -> int:
    reason = no_screen_reason()
    if reason is not None:
        print(
            f"hasa-drive: no screen to drive on: {reason}.\n"
            "hasa-drive shows the road to a human driver and needs a display. Run it in a desktop "
            "session (for a test without one: xvfb-run hasa-drive ...). Headless work: hasa-replay "
            "replays and checks recordings, and 'hasa-drive synthetic' drives a synthetic driver "
            "through a virtual wheel.",
            file=sys.stderr,
        )
        return EXIT_NO_SCREEN
    from hasa_env.devices.sources import init_pygame_input

    try:
        settings = DriveSettings(
            participant=args.participant,
            track=args.track,
            bias=args.bias,
            runs=args.runs,
            seconds=args.seconds,
            speed=args.speed,
            lateral_offset=args.lateral_offset,
            output=args.output,
            seed=args.seed,
            countdown=args.countdown,
            fsync=args.fsync,
        )
        settings.env_config()
        keyboard = (
            load_calibration(args.keyboard) if args.keyboard else shipped_calibration("keyboard")
        )
        if not isinstance(keyboard, KeyboardCalibration):
            raise CalibrationError(
                str(args.keyboard), "device", "must be 'keyboard' for --keyboard"
            )
        profiles = _joystick_profiles(args.calibration, log)
        env_wrapper = None
        if args.estimator is not None:
            env_wrapper = estimator_wrapper(args.estimator)
            env_wrapper(_probe_env(settings))  # fail now, not after the countdown
    except (ValueError, ConfigError, ImportError, OSError) as exc:
        print(f"hasa-drive: {exc}", file=sys.stderr)
        return 2
    try:
        pg = init_pygame_input()
        flags = pg.FULLSCREEN if args.fullscreen else 0
        display = pg.display.set_mode((args.width, args.height), flags)
    except Exception as exc:  # noqa: BLE001 - pygame.error and friends: no usable screen
        print(
            f"hasa-drive: no screen to drive on: pygame could not open a window ({exc})",
            file=sys.stderr,
        )
        return EXIT_NO_SCREEN
    pg.display.set_caption(f"hasa-drive: {settings.participant}")
    inputs = InputManager(keyboard, profiles, use_joystick=not args.keyboard_only, pygame_module=pg)
    autocentre = None
    session = DriveSession(
        settings,
        inputs,
        display=display,
        realtime=True,
        view=args.view,
        fps=args.fps,
        show_points=args.show_points,
        env_wrapper=env_wrapper,
        metadata={"estimator_shown": args.estimator},
    )
    previous = signal.signal(signal.SIGTERM, _raise_exit)
    try:
        if args.autocentre is not None:
            autocentre = _start_autocentre(inputs, args.autocentre, log)
        results = session.run()
    finally:
        signal.signal(signal.SIGTERM, previous)
        if autocentre is not None:
            autocentre.close()
        session.close()
        inputs.close()
        pg.display.quit()
    log(f"hasa-drive: {len(results)} run(s) recorded in {settings.directory}")
    return 0


def estimator_wrapper(
    model: str = "generalized", steering_ratio: float | None = None
) -> Callable[[Any], Any]:
    """An ``env_wrapper`` for :class:`DriveSession`: the Gaussian-mixture EKF runs alongside.

    Wraps each run's env in :class:`estimators.wrappers.EstimatorInfoWrapper`
    with :class:`estimators.gm_ekf.GaussianMixtureEKF` and the steering
    ``model`` (``"two-point"``, ``"generalized"``: the paper's presets, or a
    saved model file), so ``info["estimate_weights"]`` carries the live
    hypothesis weights the HUD shows (the recording keeps its standard columns).
    ``steering_ratio``: model units per road-wheel radian (default 15 for the
    paper's presets, 1 for a model file; :func:`hasa_env.replay_cli.default_steering_ratio`).
    """
    from estimators.gm_ekf import FilterSettings, GaussianMixtureEKF
    from estimators.wrappers import EstimatorInfoWrapper
    from hasa_env.replay_cli import default_steering_ratio, make_model

    ratio = (
        default_steering_ratio(model, fitted=False) if steering_ratio is None else steering_ratio
    )

    def wrap(env: Any) -> Any:
        config = env.unwrapped.config
        dt = config["action_repeat"] / config["sim_frequency"]
        steering = make_model(model, dt)
        settings = FilterSettings.from_env_config(config, steering_ratio=ratio)
        ekf = GaussianMixtureEKF(steering.arx(), settings, dt=dt)
        return EstimatorInfoWrapper(env, ekf)

    return wrap


def _probe_env(settings: DriveSettings) -> Any:
    from hasa_env.lane_keeping import LaneKeepingEnv

    return LaneKeepingEnv(config=settings.env_config())


def _raise_exit(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def _start_autocentre(inputs: InputManager, strength: float, log: Callable[[str], None]) -> Any:
    from hasa_env.devices.force_feedback import Autocentre, ForceFeedbackUnavailable

    inputs.poll()
    if inputs.active is None:
        log("hasa-drive: --autocentre: no wheel connected; driving without force feedback")
        return None
    try:
        return Autocentre(inputs.active.name, strength)
    except ForceFeedbackUnavailable as exc:
        log(f"hasa-drive: --autocentre: {exc}")
        return None


def _synthetic(args: argparse.Namespace, log: Callable[[str], None]) -> int:
    from hasa_env.devices.sources import init_pygame_input
    from hasa_env.devices.virtual import VirtualJoystick, VirtualJoystickUnavailable
    from hasa_env.drivers import SyntheticDriver, population

    drivers = {p.name: p for p in population(args.population, seed=args.population_seed)}
    if args.driver not in drivers:
        print(
            f"hasa-drive: unknown driver {args.driver!r}; this population has {', '.join(drivers)}",
            file=sys.stderr,
        )
        return 2
    params = drivers[args.driver]
    participant = (
        args.participant or f"synthetic-{args.population}-{args.population_seed}-{args.driver}"
    )
    try:
        settings = DriveSettings(
            participant=participant,
            track=args.track,
            bias=args.bias,
            runs=args.runs,
            seconds=args.seconds,
            speed=args.speed,
            lateral_offset=args.lateral_offset,
            output=args.output,
            seed=args.seed,
            countdown=0.0,
            fsync=args.fsync,
        )
        settings.env_config()
    except (ValueError, ConfigError) as exc:
        print(f"hasa-drive: {exc}", file=sys.stderr)
        return 2
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    pg = init_pygame_input()
    try:
        wheel = VirtualJoystick.g29()
    except VirtualJoystickUnavailable as exc:
        print(f"hasa-drive: cannot create the virtual wheel: {exc}", file=sys.stderr)
        return 1
    g29 = shipped_calibration("g29")
    assert isinstance(g29, JoystickCalibration)
    profile = JoystickCalibration(**{**_fields(g29), "match_names": (wheel.name,)})
    inputs = InputManager(shipped_calibration("keyboard"), [profile], pygame_module=pg)  # type: ignore[arg-type]
    hook = VirtualWheelDriver(wheel, SyntheticDriver(params), profile)
    metadata = {
        "synthetic": True,
        "synthetic_driver": {
            "description": (
                "Not a human: a synthetic driver (hasa_env.drivers.SyntheticDriver) turned an SDL "
                "virtual joystick laid out like a G29, read back through hasa-drive's input layer "
                "with the G29 profile."
            ),
            "population": args.population,
            "population_seed": args.population_seed,
            "driver": params.name,
            "params": params.to_dict(),
        },
    }
    session = DriveSession(settings, inputs, realtime=False, hook=hook, metadata=metadata, log=log)
    try:
        results = session.run()
    finally:
        session.close()
        inputs.close()
        wheel.detach()
    for r in results:
        log(f"hasa-drive synthetic: {r.path} ({r.steps} steps, {r.end_reason})")
    return 0 if len(results) == settings.runs else 1


def _fields(cal: JoystickCalibration) -> dict[str, Any]:
    return {k: getattr(cal, k) for k in cal.__dataclass_fields__ if k != "device"}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-drive`` (see the module docstring)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    log = print
    if argv and argv[0] == "calibrate":
        p = argparse.ArgumentParser(
            prog="hasa-drive calibrate",
            description="Measure a wheel's axes (centre, locks, pedals); write a calibration file.",
        )
        p.add_argument("--output", type=Path, default=user_calibration_path(), help="file to write")
        p.add_argument(
            "--wheel-range", type=float, default=900.0, help="lock-to-lock range in degrees"
        )
        p.add_argument(
            "--steering-ratio", type=float, default=15.0, help="steering ratio (default 15)"
        )
        p.add_argument(
            "--timeout", type=float, default=300.0, help="give up after this many seconds"
        )
        args = p.parse_args(argv[1:])
        return calibrate(
            args.output,
            wheel_range_deg=args.wheel_range,
            steering_ratio=args.steering_ratio,
            timeout=args.timeout,
        )
    if argv and argv[0] == "synthetic":
        p = argparse.ArgumentParser(
            prog="hasa-drive synthetic",
            description="Drive through hasa-drive's loop with a synthetic driver turning a "
            "virtual G29 "
            "(headless; the recordings are labelled synthetic).",
        )
        _add_session_arguments(p, participant_required=False)
        p.add_argument(
            "--driver", default="Ill", help="driver name in the population (default Ill)"
        )
        p.add_argument("--population", default="paper", help="population name (default paper)")
        p.add_argument("--population-seed", type=int, default=0, help="population seed (default 0)")
        p.set_defaults(runs=1)
        return _synthetic(p.parse_args(argv[1:]), log)
    p = argparse.ArgumentParser(
        prog="hasa-drive",
        description="Drive the lane-keeping env with a wheel (G29), a joystick or the keyboard; "
        "record each run. "
        "Subcommands: 'hasa-drive calibrate', 'hasa-drive synthetic' (see their --help).",
    )
    _add_session_arguments(p, participant_required=True)
    p.add_argument(
        "--countdown", type=float, default=3.0, help="countdown before each run in s (default 3)"
    )
    p.add_argument(
        "--calibration",
        type=Path,
        default=None,
        help="joystick calibration file (default: the one "
        f"written by 'hasa-drive calibrate' ({user_calibration_path()}) if present, "
        "else the shipped G29 and "
        "gamepad profiles)",
    )
    p.add_argument("--keyboard", type=Path, default=None, help="keyboard calibration file")
    p.add_argument("--keyboard-only", action="store_true", help="ignore joysticks")
    p.add_argument("--view", choices=("driver", "top_down"), default="driver")
    p.add_argument("--show-points", action="store_true", help="draw the near and far points")
    p.add_argument(
        "--estimator",
        nargs="?",
        const="generalized",
        default=None,
        metavar="MODEL",
        help="run the Gaussian-mixture EKF alongside; show its lane-hypothesis weights in the HUD "
        "(steering model: two-point, generalized (default) or a saved model file)",
    )
    p.add_argument("--width", type=int, default=1280)
    p.add_argument("--height", type=int, default=720)
    p.add_argument(
        "--fps", type=int, default=60, help="frame-rate cap (the physics runs at 100 Hz regardless)"
    )
    p.add_argument("--fullscreen", action="store_true")
    p.add_argument(
        "--autocentre",
        type=float,
        default=None,
        metavar="STRENGTH",
        help="force feedback: wheel autocentre spring strength 0..1 (Linux, needs evdev)",
    )
    return _drive(p.parse_args(argv), log)


if __name__ == "__main__":
    raise SystemExit(main())
