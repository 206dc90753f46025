"""The drive loop: people drive the lane-keeping env with a wheel, a joystick or the keyboard.

:class:`DriveSession` follows the paper's protocol: every run lasts 30 s,
starts at 15 m/s and y = -0.5 m in the right lane; a countdown precedes it.
Each run is recorded with :class:`hasa_env.recording.RecordingWrapper`
under ``<output>/<participant>/run_NNN.csv`` (+ ``.json`` sidecar), every
step flushed at once (crash-safe: a killed process keeps every completed
step). Next to each run, ``run_NNN.inputs.tsv`` holds the raw input per step
(:mod:`hasa_env.recording.raw_inputs`).

The simulation clock drives the physics: each frame the loop runs as many
100 Hz steps as the wall clock is due (never more than a quarter second's
worth: after a stall it re-anchors instead of sprinting), then draws one
frame, capped at ``fps`` (60). A pause (P, or the wheel unplugged) freezes
the simulation clock; nothing is recorded while paused. Without
``realtime`` the same loop runs headless and as fast as possible, with a
scripted driver turning a virtual wheel (:class:`hasa_env.session.scripted.VirtualWheelDriver`).
The command line is ``hasa-drive`` (the command-line layer above this package).

Besides :meth:`DriveSession.run` (the plain session of ``hasa-drive``),
:meth:`DriveSession.show` (a message screen until the driver confirms) and
:meth:`DriveSession.drive` (one :class:`RunSpec`: its seed, start state,
bias and file prefix) are the pieces a study session
(:mod:`hasa_env.session.study_session`) is made of. A ``status`` callback
lets the experimenter follow a run (run, time, speed, estimator weights) in
the terminal while the participant's window stays clean
(:class:`hasa_env.render.ViewOptions`).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hasa_env.devices.sources import InputManager, Notice
from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.recording.format import RecordingError
from hasa_env.recording.raw_inputs import (
    RAW_INPUT_HEADER,
    RAW_INPUT_UNITS,
    RAW_INPUTS_SUFFIX,
    RawInputWriter,
    raw_inputs_path,
)
from hasa_env.recording.writer import RecordingWrapper
from hasa_env.render import ViewOptions, make_renderer
from hasa_env.session.settings import DriveSettings
from hasa_env.session.study import seed_from_entropy
from hasa_env.sim.config import deep_merge, make_config

__all__ = ["DriveSession", "MAX_CATCH_UP", "RunResult", "RunSpec", "WAITING_STATES"]

WAITING_STATES = ("idle", "between_runs", "break", "end")
CONFIRM_HINT = "Press a wheel button or SPACE to start."
"""States in which the session shows a message and waits for the driver to confirm."""

MAX_CATCH_UP = 0.25
"""Seconds of simulation the real-time loop runs at most to catch up after a stall."""


@dataclass
class RunResult:
    """What one run produced.

    ``end_reason``: ``"truncated"`` (the run's full length), ``"terminated"``
    (the car left the road) or ``"stopped"`` (the driver quit, or an error).
    """

    path: Path
    steps: int
    end_reason: str


@dataclass(frozen=True)
class RunSpec:
    """One run to drive (:meth:`DriveSession.drive`).

    Attributes:
        index: 0-based index of the run in its session (unique; a scripted
            driver re-seeds when it changes).
        seed: the env seed.
        reset_options: ``reset`` options (start state, bias).
        prefix: recording file prefix: the run goes to ``<prefix>_NNN.csv``, NNN
            the first number not used yet (nothing is overwritten).
        label: shown under the countdown (``"run 3 of 10"``) and in the status.
        metadata: extra sidecar metadata, deep-merged over the session's.
    """

    index: int
    seed: int
    reset_options: Mapping[str, Any]
    prefix: str = "run"
    label: str = ""
    metadata: Mapping[str, Any] = field(default_factory=dict)


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
        weights: hypothesis weights for the HUD (:data:`hasa_env.render.WeightSource`).
        env_wrapper: wraps each run's env before recording (e.g. an estimator
            that adds weights to ``info``); None: no wrapper.
        log: where messages go (default ``print``).
        max_idle_iterations: without ``realtime``, give up (RuntimeError) after
            this many iterations without a step (a scripted drive stuck in a pause).
        view_options: what the window shows (:class:`hasa_env.render.ViewOptions`;
            default: everything, the developer's view).
        status: called with the session every ``status_every`` s of driving
            (simulated time) and whenever its state changes: the
            experimenter's status line.
        status_every: see ``status`` (s).
        on_recording: called with the path of each run's recording as soon as
            the file exists (a study's session file notes it before the run).
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
        view_options: ViewOptions | None = None,
        status: Callable[[DriveSession], None] | None = None,
        status_every: float = 0.5,
        on_recording: Callable[[Path], None] | None = None,
    ) -> None:
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
        self.view_options = view_options if view_options is not None else ViewOptions()
        self.status = status
        self.status_every = float(status_every)
        self.on_recording = on_recording
        self._status_state: str | None = None
        self._status_step = 0
        self.config = settings.env_config()
        self._preview_env = LaneKeepingEnv(config=self.config)
        self.setup = self._preview_env.setup
        self.road = self.setup.road
        self.dt = self.setup.dt * self.setup.action_repeat
        self.renderer = None
        if display is not None:
            size = display.get_size()
            self.config = deep_merge(
                self.config,
                {"render": {"width": size[0], "height": size[1], "show_points": show_points}},
            )
            self.config = make_config(self.config)
            self._preview_env = LaneKeepingEnv(config=self.config)
            self.setup = self._preview_env.setup
            self.renderer = make_renderer(
                self.setup, "rgb_array", view=view, options=self.view_options
            )
        self.state = "idle"
        """One of ``idle``, ``countdown``, ``driving``, ``paused``, ``between_runs``, ``quit``."""
        self.message: str | None = None
        self.info: dict[str, Any] | None = None
        self.run_index = -1
        """0-based index of the current run."""
        self.run_seed: int | None = None
        self.run_label = ""
        """The current run's label (:attr:`RunSpec.label`)."""
        self.steps = 0
        """Env steps taken in the current run."""
        self.results: list[RunResult] = []
        self._frame_clock: Any = None  # a pygame.time.Clock once ticking
        self._root_seed = settings.seed if settings.seed is not None else seed_from_entropy()

    # ---------------------------------------------------------- helpers
    def run_seeds(self) -> list[int]:
        """The env seed of every run, derived from the root seed (recorded in the metadata)."""
        state = np.random.SeedSequence(self._root_seed).generate_state(
            2 * self.settings.runs, np.uint32
        )
        return [int(state[2 * i]) << 21 ^ int(state[2 * i + 1]) for i in range(self.settings.runs)]

    def run_spec(self, run_index: int, seeds: Sequence[int] | None = None) -> RunSpec:
        """Run ``run_index`` of a plain session (:meth:`run`): its seed, the settings' start."""
        seeds = self.run_seeds() if seeds is None else seeds
        return RunSpec(
            index=run_index,
            seed=int(seeds[run_index]),
            reset_options=self.settings.reset_options(),
            label=f"run {run_index + 1} of {self.settings.runs}",
        )

    def preview(self, seed: int, options: Mapping[str, Any]) -> dict[str, Any]:
        """The ``info`` at the start of a run (the road shown behind a message screen)."""
        _, info = self._preview_env.reset(seed=int(seed), options=dict(options))
        self.info = info
        return info

    def poll_devices(self) -> None:
        """Handle pending input events now (e.g. joysticks plugged in before the session)."""
        self._handle(self.inputs.poll())

    def _call_hook(self) -> None:
        if self.hook is not None:
            self.hook(self)

    def _report(self, force: bool = False) -> None:
        """Call ``status`` when the state changed, or every ``status_every`` s of driving."""
        if self.status is None:
            return
        every = max(1, int(round(self.status_every / self.dt)))
        if (
            force
            or self.state != self._status_state
            or (self.state == "driving" and self.steps - self._status_step >= every)
        ):
            self._status_state = self.state
            self._status_step = self.steps
            self.status(self)

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
                if self.state in WAITING_STATES:  # the screen's text stays, under the notice
                    self.message = f"{n.message}\n{self.message or CONFIRM_HINT}"
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
                elif self.state in WAITING_STATES:
                    self.state = "confirmed"

    def _resume(self) -> None:
        self.state = "driving"
        self.message = None
        self._anchor = time.perf_counter() - self.steps * self.dt
        self.log(f"hasa-drive: driving on with {self.inputs.source_name}")

    def _idle(self) -> None:
        self._call_hook()
        self._handle(self.inputs.poll())
        self._report()

    def _wait_for_confirm(
        self, info: Mapping[str, Any], message: str, state: str, min_seconds: float = 0.0
    ) -> bool:
        """Show ``message`` until the driver confirms (True) or quits (False).

        A confirmation within ``min_seconds`` (a break's minimum length) is ignored.
        """
        if not self.realtime:
            if self.state != "quit":
                self.state, self.message = state, message
                self._call_hook()
                self._report()
            return self.state != "quit"
        self.state, self.message = state, message
        shown = time.perf_counter()
        while True:
            self._idle()
            if self.state == "confirmed" and time.perf_counter() - shown < min_seconds:
                self.state = state  # too early: the break goes on
            if self.state != state:
                break
            left = min_seconds - (time.perf_counter() - shown)
            text = self.message or message
            if left > 0:
                text += f"\n(you can go on in {math.ceil(left):d} s)"
            self._draw(info, text)
            self._tick()
        return self.state != "quit"

    def show(
        self,
        message: str,
        *,
        state: str = "idle",
        info: Mapping[str, Any] | None = None,
        min_seconds: float = 0.0,
    ) -> bool:
        """Show ``message`` over the road until the driver confirms; False if they quit.

        ``state`` is one of :data:`WAITING_STATES` (instructions before a block:
        ``"idle"``; between runs; a ``"break"``; the ``"end"`` screen). The road
        behind is ``info`` (default: the start of the next run). Without
        ``realtime`` it returns at once.
        """
        if state not in WAITING_STATES:
            raise ValueError(f"state must be one of {', '.join(WAITING_STATES)}, got {state!r}")
        if info is None:
            info = self.info
        if info is None:
            _, info = self._preview_env.reset(
                seed=self.run_seeds()[0], options=self.settings.reset_options()
            )
            self.info = info
        return self._wait_for_confirm(info, message, state, min_seconds)

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
            self._draw(info, f"{math.ceil(left):d}\n{self.run_label}")
            self._tick()
        if self.state == "paused":  # the wheel went away during the countdown
            ok = self._wait_for_confirm(info, self.message or "paused", "paused")
            return ok and self._countdown(info)
        return self.state != "quit"

    # -------------------------------------------------------------- runs
    def input_description(self) -> dict[str, Any]:
        """The input devices in use: active source, joystick profiles, keyboard calibration."""
        inputs = self.inputs
        return {
            "source_at_start": inputs.source_name,
            "joystick_profiles": [p.to_dict() | {"source": p.source} for p in inputs.profiles],
            "keyboard": inputs.keyboard.calibration.to_dict()
            | {"source": inputs.keyboard.calibration.source},
        }

    def _run_metadata(self, run_index: int, seed: int) -> dict[str, Any]:
        s = self.settings
        start = self.config["initial_state"]
        meta: dict[str, Any] = {
            "tool": "hasa-drive",
            "participant": s.participant,
            "run": run_index + 1,
            "runs": s.runs,
            "root_seed": self._root_seed,
            "protocol": {
                "track": s.track,
                "seconds": s.seconds,
                "scenario": s.scenario,
                "speed": start["speed"],
                "lateral_offset": start["lateral_offset"],
                **{key: start[key] for key in ("between_hypotheses", "heading_toward_other")},
                "bias": "random" if s.bias is None else s.bias,
                "speed_control": s.speed_control,
                "min_speed": s.min_speed,
            },
            "input": {
                **self.input_description(),
                "raw_inputs": {
                    "file": f"<recording stem>{RAW_INPUTS_SUFFIX}",
                    "columns": list(RAW_INPUT_HEADER),
                    "units": RAW_INPUT_UNITS,
                },
            },
            "realtime": self.realtime,
            "synthetic": False,
            "view": self.view_options.to_dict(),
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
            result = self.drive(self.run_spec(r, seeds))
            if self.state == "quit" and result is None:
                break
            if result is not None:
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

    def drive(self, spec: RunSpec) -> RunResult | None:
        """Count down and drive one run; what it recorded (None: quit before it started).

        The result is also appended to :attr:`results`. Afterwards ``state`` is
        ``"between_runs"``, or ``"quit"`` if the driver stopped the session.
        """
        self.run_index = spec.index
        self.run_seed = spec.seed
        self.run_label = spec.label
        _, preview = self._preview_env.reset(seed=spec.seed, options=dict(spec.reset_options))
        self.info = preview
        if not self._countdown(preview):
            return None
        return self._drive_run(spec)

    def _recorder(self, spec: RunSpec) -> RecordingWrapper:
        """A new env (wrapped by ``env_wrapper`` if set) recording the run ``spec``."""
        s = self.settings
        env: Any = LaneKeepingEnv(config=self.config)
        if self.env_wrapper is not None:
            env = self.env_wrapper(env)
        env_id = (
            "hasa_env/LaneKeepingCurved-v0" if s.track == "curved" else "hasa_env/LaneKeeping-v0"
        )
        return RecordingWrapper(
            env,
            s.directory,
            prefix=spec.prefix,
            metadata=deep_merge(self._run_metadata(spec.index, spec.seed), dict(spec.metadata)),
            env_id=env_id,
            fsync=s.fsync,
        )

    def _steps_due(self) -> int:
        """Env steps to take now: 1 per loop without ``realtime``; with it, the steps the wall
        clock is due since the anchor (re-anchored to 1 step after a stall longer than
        :data:`MAX_CATCH_UP`); 0 unless driving."""
        if self.state != "driving":
            return 0
        if not self.realtime:
            return 1
        now = time.perf_counter()
        due = int((now - self._anchor) / self.dt) - self.steps
        if due * self.dt > MAX_CATCH_UP:
            self.log(f"hasa-drive: fell {due * self.dt:.2f} s behind real time; re-anchoring")
            self._anchor = now - (self.steps + 1) * self.dt
            due = 1
        return due

    def _take_steps(
        self, recorder: RecordingWrapper, raw: RawInputWriter, due: int, wall0: float
    ) -> tuple[bool, str | None]:
        """Up to ``due`` env steps of the driver's inputs, each recorded with its raw inputs
        (``wall0``: the run's start on ``time.perf_counter``); stops early when the state
        leaves "driving". Returns (whether a step was taken, "terminated" / "truncated" if the
        episode ended, else None)."""
        stepped = False
        for _ in range(max(due, 0)):
            self._call_hook()
            self._handle(self.inputs.poll())
            if self.state != "driving":
                break
            reading = self.inputs.read(self.dt)
            assert self.info is not None  # the run's reset set it
            acceleration = self.settings.applied_acceleration(
                reading.acceleration, float(self.info["speed"]), self.dt
            )
            action = [reading.road_wheel_angle, acceleration]
            _, _, terminated, truncated, info = recorder.step(action)
            self.steps += 1
            self.info = info
            raw.write(self.steps, info["time"], time.perf_counter() - wall0, reading)
            self._report()
            stepped = True
            if terminated or truncated:
                return stepped, "terminated" if terminated else "truncated"
        return stepped, None

    def _drive_run(self, spec: RunSpec) -> RunResult | None:
        s = self.settings
        recorder = self._recorder(spec)
        raw: RawInputWriter | None = None
        end_reason = "stopped"
        self.steps = 0
        try:
            _, info = recorder.reset(seed=spec.seed, options=dict(spec.reset_options))
            self.info = info
            assert recorder.path is not None
            if self.on_recording is not None:
                self.on_recording(recorder.path)
            raw = RawInputWriter(raw_inputs_path(recorder.path), fsync=s.fsync)
            self.state, self.message = "driving", None
            wall0 = time.perf_counter()
            self._anchor = wall0
            idle = 0
            last_frame_step = -1
            while self.state != "quit":
                due = self._steps_due()
                if due <= 0:
                    self._idle()
                    idle += 1
                    if not self.realtime and idle > self.max_idle_iterations:
                        raise RuntimeError(
                            f"scripted drive stuck in state {self.state!r} for {idle} iterations "
                            f"(message: {self.message!r})"
                        )
                stepped, ended = self._take_steps(recorder, raw, due, wall0)
                if stepped:
                    idle = 0
                if ended is not None:
                    end_reason = ended
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
        except BaseException:  # close quietly: report the first error, not its consequences
            with contextlib.suppress(OSError, RecordingError):
                recorder.close()
            if raw is not None:
                with contextlib.suppress(OSError):
                    raw.close()
            raise
        try:
            recorder.close()
        finally:
            if raw is not None:
                raw.close()
        if recorder.path is None:
            return None
        if self.state != "quit":
            self.state = "between_runs"
        result = RunResult(recorder.path, self.steps, end_reason)
        self.results.append(result)
        self._report(force=True)
        return result

    def close(self) -> None:
        self._preview_env.close()
        if self.renderer is not None:
            self.renderer.close()
