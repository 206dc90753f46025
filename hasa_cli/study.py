"""``hasa-drive study STUDY.toml --participant P07``: one participant's session of a study.

The session (:class:`hasa_env.session.StudySession`) shows the instructions,
the practice and measured runs with the study's bias schedule, breaks and an
end screen in a participant's view without cues (no ghost markings, no HUD,
unless the study asks for them), while the terminal shows the experimenter
a status line (:class:`StatusLine`: run, true bias, time, speed, lateral
offset, estimator weights). It writes ``<output>/<participant>/session.json``
beside the recordings; the same command resumes an interrupted session at
the next run (:mod:`hasa_env.session.session_file`). The study's questions
are asked in the terminal (or given with ``--meta KEY=VALUE``); ``--check``
prints the participant's schedule and drives nothing. ``--synthetic DRIVER``
lets a synthetic driver take part through a virtual G29 (headless and as
fast as possible, or in a window in real time with ``--realtime``).

Exit status: 0 complete (or already complete), 1 stopped before the end
(resume it), 2 bad input, 3 no screen or no virtual wheel.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import signal
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hasa_cli import (
    EXIT_ENVIRONMENT,
    EXIT_INTERRUPTED,
    EXIT_PARTIAL,
    EXIT_USAGE,
    ArgumentParser,
    add_trust_model_option,
    error,
    report_write_failure,
)
from hasa_env.devices.calibration import (
    CalibrationError,
    JoystickCalibration,
    KeyboardCalibration,
    load_calibration,
    shipped_calibration,
)
from hasa_env.devices.sources import InputManager, init_pygame_input, no_screen_reason
from hasa_env.devices.virtual import VirtualJoystick, VirtualJoystickUnavailable

# The steering models, estimators and synthetic drivers are imported where the session needs
# them: '--check' and an error in the study file answer at once.
from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.recording import RecordingError
from hasa_env.scenarios import scenario_spec
from hasa_env.session import (
    DriveSession,
    DriveSettings,
    SessionError,
    Study,
    StudyError,
    StudySession,
    VirtualWheelDriver,
)
from hasa_env.session.scripted import WheelButtonPresser
from hasa_env.session.session_file import SESSION_FILE
from hasa_env.sim.config import ConfigError
from hasa_env.validation import did_you_mean

__all__ = ["EXIT_NO_SCREEN", "StatusLine", "build_parser", "main"]

EXIT_NO_SCREEN = EXIT_ENVIRONMENT
"""Exit status when there is no screen to drive on."""


def _raise_exit(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)  # SIGTERM: the session's cleanup runs, the run is aborted


class StatusLine:
    """The experimenter's status line: run, true bias, time, speed, y, estimator weights.

    On a terminal it is one line rewritten in place (messages are printed
    above it); otherwise a line is printed when the state changes and every
    ``every`` s of driving, so a log file stays readable.
    """

    def __init__(self, stream: Any = None, every: float = 5.0) -> None:
        self.stream = stream if stream is not None else sys.stdout
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.every = every
        self._shown = ""
        self._last: tuple[str, str] | None = None
        self._last_time = -math.inf

    @staticmethod
    def text(study: StudySession, drive: DriveSession) -> str:
        """One status line."""
        run = study.current
        parts = [study.participant]
        if run is not None:
            total = sum(1 for r in (study.record.schedule if study.record else []) if
                        r.block == run.block)  # fmt: skip
            parts.append(f"{run.block} run {run.number}/{total}")
            parts.append(f"true b {run.bias:+.2f} m")
        info = drive.info
        if drive.state == "driving" and info is not None:
            parts.append(f"t {float(info['time']):5.1f}/{drive.settings.seconds:g} s")
            parts.append(f"v {float(info['speed']):4.1f} m/s")
            parts.append(f"y {float(info['lateral_offset']):+5.2f} m")
            weights = info.get("estimate_weights")
            if weights is not None:
                hyps = info.get("estimator_hypotheses", drive.setup.hypotheses)
                shown = ", ".join(f"{float(b):+.1f}: {float(w):.2f}" for b, w in
                                  zip(np.ravel(hyps), np.ravel(weights), strict=False))  # fmt: skip
                parts.append(f"weights {shown}")
        else:
            parts.append(drive.state.replace("_", " "))
        return " | ".join(parts)

    def __call__(self, study: StudySession, drive: DriveSession) -> None:
        line = self.text(study, drive)
        if self.tty:
            self.stream.write("\r\x1b[K" + line)
            self.stream.flush()
            self._shown = line
            return
        key = (drive.state, study.current.prefix if study.current else "")
        t = float(drive.info["time"]) if drive.info is not None else 0.0
        if key != self._last or t - self._last_time >= self.every:
            self._last, self._last_time = key, t
            print(line, file=self.stream, flush=True)

    def log(self, message: str) -> None:
        """Print a message without garbling the status line."""
        if self.tty and self._shown:
            self.stream.write("\r\x1b[K")
        print(message, file=self.stream, flush=True)
        if self.tty and self._shown:
            self.stream.write(self._shown)
            self.stream.flush()

    def close(self) -> None:
        if self.tty and self._shown:
            self.stream.write("\n")
            self.stream.flush()
            self._shown = ""


def _meta(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"--meta takes KEY=VALUE, got {text!r}")
    return key.strip(), value.strip()


def _answers(study: Study, given: dict[str, str], interactive: bool) -> dict[str, Any]:
    """The participant's metadata: ``--meta`` answers, the rest asked in the terminal."""
    answers: dict[str, Any] = dict(given)
    for f in study.participant_fields:
        if f.key in answers or not interactive:
            continue
        while True:
            reply = input(f.question())
            try:
                f.parse(reply)
            except ValueError as exc:
                print(f"  {exc}")
                continue
            answers[f.key] = reply
            break
    return study.check_metadata(answers)


def _scenario_lines(study: Study) -> list[str]:
    """What ``--check`` says of the study's scenario: its name and summary, the start state
    and hypotheses the runs get, the scenario's keys the study file overrides."""
    spec = scenario_spec(study.scenario)
    config = study.env_config(study.document["measured"]["track"])
    init = config["initial_state"]
    where = (
        "halfway between the true lane's centre and the nearest other hypothesis's "
        "(initial_state.between_hypotheses)"
        if init["between_hypotheses"]
        else f"y = {init['lateral_offset']:+.2f} m"
    )
    if init["lateral_offset_std"] > 0.0:
        where += f" (+ a Gaussian of std {init['lateral_offset_std']:g} m)"
    heading = f"heading {init['heading']:g} rad"
    if init["heading_toward_other"]:
        heading += (
            f" + {init['heading_toward_other']:g} rad toward the other hypothesis's centre "
            "(initial_state.heading_toward_other)"
        )
    lines = [
        f"scenario {spec.name!r}: {spec.summary}",
        f"  start: {init['speed']:g} m/s, {where}, {heading}; lane "
        f"hypotheses {config['markings']['hypotheses']} m",
    ]
    if config["road"]["lane_shifts"]:
        lines.append(
            f"  the driven lane moves: {config['road']['lane_shifts']} (drawn in yellow over "
            "the white markings, which the camera keeps reading)"
        )
    for key, mine, theirs in study.scenario_overrides():
        lines.append(f"  the study file's {key} = {mine!r} overrides the scenario's {theirs!r}")
    if spec.preferred_offset[1] > 0.0:
        low, high = spec.preferred_offset
        lines.append(
            f"  the scenario's preferred offset ({low:g}-{high:g} m) is a synthetic driver's "
            "(--synthetic); a human keeps their own"
        )
    return lines


def _print_schedule(study: Study, participant: str, slot: int | None) -> None:
    for line in _scenario_lines(study):
        print(f"{study.source}: {line}" if not line.startswith(" ") else line)
    seed = study.seed
    if seed is None:
        print(f"{study.source}: no study seed: each session draws one (recorded)")
        return
    runs = study.schedule_for(participant, slot, seed)
    print(f"{study.source}: study {study.name!r}, {len(runs)} runs for {participant}:")
    for r in runs:
        print(
            f"  {r.position:3d}  {r.block:8s} {r.number:3d}  {r.track:8s}  b = {r.bias:+.2f} m  "
            f"seed {r.seed}  -> {r.prefix}_NNN.csv"
        )


PROG = "hasa-drive study"


class _Exit(Exception):
    """Leave :func:`run` with this exit status (the message is already printed)."""

    def __init__(self, status: int) -> None:
        super().__init__(status)
        self.status = status


@dataclass
class _Setup:
    """What the session needs, read and checked before any window or device opens."""

    study: Study
    synthetic: bool
    headless: bool
    keyboard: KeyboardCalibration
    env_wrapper: Any
    answers: dict[str, Any]


def _setup(args: argparse.Namespace) -> _Setup:
    """Read the study, the keyboard calibration and the estimator, check the screen and ask
    the participant's questions. Raises the input errors (exit 2), :class:`_Exit` without a
    screen."""
    study = Study.load(args.study)
    synthetic = args.synthetic is not None
    headless = synthetic and not args.realtime
    DriveSettings(participant=args.participant, output=args.output)  # a usable id
    keyboard = load_calibration(args.keyboard) if args.keyboard else shipped_calibration("keyboard")
    if not isinstance(keyboard, KeyboardCalibration):
        raise CalibrationError(str(args.keyboard), "device", "must be 'keyboard' for --keyboard")
    env_wrapper = None
    if args.estimator is not None:
        track = study.document["measured"]["track"]
        from hasa_cli.inputs import estimator_for  # start-up: only where needed

        env_wrapper = estimator_for(
            args.estimator,
            LaneKeepingEnv(config=study.env_config(track)),
            log=print,  # where the filter does not listen to the model's steering, and why
            trust_module=args.trust_model_module,
        )
    # the input is checked first: a bad file is exit 2 with or without a screen
    if not headless:
        reason = no_screen_reason()
        if reason is not None:
            error(
                PROG,
                f"no screen to drive on: {reason}; a study session shows the road to its "
                "participant and needs a display (for a test without one: xvfb-run hasa-drive "
                "study ...; a synthetic participant drives headless: --synthetic DRIVER "
                "without --realtime)",
            )
            raise _Exit(EXIT_NO_SCREEN)
    folder = Path(args.output) / args.participant
    resuming = (folder / SESSION_FILE).exists()
    answers: dict[str, Any] = {}
    if not resuming:
        answers = _answers(study, dict(args.meta), not synthetic and sys.stdin.isatty())
    return _Setup(study, synthetic, headless, keyboard, env_wrapper, answers)


def _open_window(pg: Any, args: argparse.Namespace, study: Study) -> Any:
    """The participant's window; :class:`_Exit` if pygame cannot open one."""
    try:
        flags = pg.FULLSCREEN if args.fullscreen else 0
        display = pg.display.set_mode((args.width, args.height), flags)
    except Exception as exc:  # noqa: BLE001 - pygame.error and friends: no usable screen
        error(PROG, f"no screen to drive on: pygame could not open a window ({exc})")
        raise _Exit(EXIT_NO_SCREEN) from None
    pg.display.set_caption(study.document["study"]["title"] or f"hasa-drive: {study.name}")
    return display


@dataclass
class _Participant:
    """Who drives: the input profiles, and for a synthetic participant its virtual wheel,
    the hook that steers and presses its button, and what the recordings say about it."""

    profiles: list[Any]
    wheel: Any = None
    hook: Callable[[DriveSession], None] | None = None
    metadata: dict[str, Any] = field(default_factory=dict)


def _synthetic_participant(args: argparse.Namespace, scenario: str) -> _Participant:
    """A synthetic driver of ``--population`` turning a virtual G29 and pressing its button
    through the screens, as it drives in the study's ``scenario`` (its preferred offset:
    :func:`hasa_env.scenarios.scenario_drivers`, from ``--population-seed``);
    :class:`_Exit` for an unknown driver (2) or no virtual wheel (3)."""
    from hasa_env.drivers import SyntheticDriver, population  # start-up: only where needed

    drivers = {
        p.name: p for p in population(args.population, seed=args.population_seed, scenario=scenario)
    }
    if args.synthetic not in drivers:
        error(PROG, f"unknown driver {args.synthetic!r}; this population has "
                    f"{', '.join(drivers)}" + did_you_mean(args.synthetic, drivers))  # fmt: skip
        raise _Exit(EXIT_USAGE)
    try:
        wheel = VirtualJoystick.g29()
    except VirtualJoystickUnavailable as exc:
        error(PROG, f"cannot create the virtual wheel: {exc}")
        raise _Exit(EXIT_ENVIRONMENT) from None
    try:
        g29 = shipped_calibration("g29")
        assert isinstance(g29, JoystickCalibration)
        profile = dataclasses.replace(g29, match_names=(wheel.name,))
        params = drivers[args.synthetic]
        steering = VirtualWheelDriver(wheel, SyntheticDriver(params), profile)
        presser = WheelButtonPresser(wheel, after=0.2)
    except BaseException:
        wheel.detach()
        raise

    def hook(session: DriveSession) -> None:
        steering(session)
        presser(session)

    metadata = {
        "synthetic": True,
        "synthetic_driver": {
            "description": "Not a human: a synthetic driver (hasa_env.drivers."
            "SyntheticDriver) turned an SDL virtual joystick laid out like a G29 and "
            "pressed its button to go on through the study's screens.",
            "population": args.population,
            "population_seed": args.population_seed,
            "driver": params.name,
            "params": params.to_dict(),
        },
    }
    return _Participant([profile], wheel, hook, metadata)


def _print_outcome(outcome: Any) -> int:
    """Say what the session recorded; the exit status (1 if it stopped before the end)."""
    summary = outcome.session.summary()
    print(
        f"{PROG}: {summary['participant']}: {summary['practice_completed']} practice and "
        f"{summary['measured_completed']}/{summary['measured_scheduled']} measured runs "
        f"recorded ({summary['left_road']} left the road), {summary['aborted']} aborted; "
        f"session file {outcome.session.path}"
    )
    if outcome.state == "quit":
        print(f"{PROG}: stopped with {summary['remaining']} run(s) to go; the same command "
              "resumes the session at the next run")  # fmt: skip
        return EXIT_PARTIAL
    return 0


def run(args: argparse.Namespace) -> int:
    """Run ``hasa-drive study`` with parsed arguments; returns the exit status."""
    status = StatusLine()
    log = status.log
    try:
        if args.check:
            _print_schedule(Study.load(args.study), args.participant, args.slot)
            return 0
        setup = _setup(args)
    except (StudyError, SessionError, ValueError, ConfigError, ImportError, OSError) as exc:
        error(PROG, str(exc))
        return EXIT_USAGE
    except _Exit as exit_:
        return exit_.status
    if setup.headless:
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    from hasa_cli.inputs import joystick_profiles  # start-up: only where needed

    pg = init_pygame_input()
    try:
        display = None if setup.headless else _open_window(pg, args, setup.study)
        who = (
            _synthetic_participant(args, setup.study.scenario)
            if setup.synthetic
            else _Participant(joystick_profiles(args.calibration, log))
        )
    except _Exit as exit_:
        return exit_.status
    except (StudyError, SessionError, ValueError, OSError) as exc:
        error(PROG, str(exc))
        return EXIT_USAGE
    try:
        inputs = InputManager(setup.keyboard, who.profiles, use_joystick=not args.keyboard_only,
                              pygame_module=pg)  # fmt: skip
        session = StudySession(
            setup.study,
            args.participant,
            inputs,
            output=args.output,
            metadata=setup.answers,
            slot=args.slot,
            display=display,
            realtime=not setup.headless,
            hook=who.hook,
            env_wrapper=setup.env_wrapper,
            status=None if args.no_status else status,
            fps=args.fps,
            log=log,
            run_metadata={"estimator_shown": args.estimator} | who.metadata,
            fsync=args.fsync,
        )
    except (StudyError, SessionError, ValueError, OSError) as exc:
        error(PROG, str(exc))
        if who.wheel is not None:
            who.wheel.detach()
        return EXIT_USAGE
    return _drive_session(args, session, inputs, status, who.wheel, display, pg)


def _drive_session(
    args: argparse.Namespace,
    session: StudySession,
    inputs: InputManager,
    status: StatusLine,
    wheel: Any,
    display: Any,
    pg: Any,
) -> int:
    """Run the session (SIGTERM aborts the run in progress, cleanly) and close everything."""
    previous = signal.signal(signal.SIGTERM, _raise_exit)
    autocentre = None
    try:
        if args.autocentre is not None and args.synthetic is None:
            from hasa_cli.inputs import start_autocentre  # start-up: only where needed

            autocentre = start_autocentre(inputs, args.autocentre, status.log)
        outcome = session.run()
    except (StudyError, SessionError) as exc:
        status.close()
        error(PROG, str(exc))
        return EXIT_USAGE
    except (OSError, RecordingError) as exc:  # a full disk: name it, keep what was written
        status.close()
        recorded = session.record is not None and bool(session.record.attempts)
        kept = (
            "every completed run and the session file as last written are kept (the next start "
            "resumes)"
            if recorded
            else "nothing was recorded"
        )
        code = report_write_failure(PROG, exc, session.directory, kept)
        if code is None:
            raise
        return code if recorded or code == EXIT_ENVIRONMENT else EXIT_USAGE
    except (KeyboardInterrupt, SystemExit) as exc:  # Ctrl-C, SIGTERM: the run is aborted, kept
        status.close()
        how = "interrupted" if isinstance(exc, KeyboardInterrupt) else "stopped by a signal"
        kept = (
            "the run in progress is kept as aborted, every completed run and the session file "
            "are kept (the same command resumes)"
            if session.record is not None
            else "nothing was recorded"
        )
        error(PROG, f"{how}; {kept}")
        if isinstance(exc, SystemExit):
            raise
        return EXIT_INTERRUPTED
    finally:
        signal.signal(signal.SIGTERM, previous)
        status.close()
        if autocentre is not None:
            autocentre.close()
        session.close()
        inputs.close()
        if wheel is not None:
            wheel.detach()
        if display is not None:
            pg.display.quit()
    return _print_outcome(outcome)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hasa-drive study``."""
    p = ArgumentParser(
        prog="hasa-drive study",
        description="Run one participant's session of a study file (e.g. "
        "studies/paper.toml): instructions, practice and measured runs with the study's "
        "bias schedule, breaks, an end screen; a session file beside the recordings; "
        "running it again resumes at the next run.",
    )
    p.add_argument("study", type=Path, help="the study file (.toml or .json)")
    p.add_argument("--participant", required=True, help="participant id, e.g. P07 (no names)")
    p.add_argument(
        "--slot",
        type=int,
        default=None,
        help="the participant's number for a latin_square or counterbalanced schedule "
        "(default: the digits that end the id, P07 -> 7)",
    )
    p.add_argument(
        "--meta",
        type=_meta,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an answer to the study's participant questions (the rest are asked in the "
        "terminal); repeatable",
    )
    p.add_argument(
        "--output", type=Path, default=Path("recordings"), help="root folder (recordings)"
    )
    p.add_argument(
        "--check",
        action="store_true",
        help="check the study file and print this participant's schedule; drive nothing",
    )
    p.add_argument("--calibration", type=Path, default=None, help="joystick calibration file")
    p.add_argument("--keyboard", type=Path, default=None, help="keyboard calibration file")
    p.add_argument("--keyboard-only", action="store_true", help="ignore joysticks")
    p.add_argument(
        "--estimator",
        nargs="?",
        const="generalized",
        default=None,
        metavar="MODEL",
        help="run the Gaussian-mixture EKF alongside; its lane weights go to the status "
        "line (model: two-point, generalized (default), a saved model file or "
        "package.module:Class)",
    )
    p.add_argument("--no-status", action="store_true", help="no status line in the terminal")
    add_trust_model_option(p, "--estimator's model file")
    p.add_argument("--width", type=int, default=1280, help="window width in pixels (default 1280)")
    p.add_argument("--height", type=int, default=720, help="window height in pixels (default 720)")
    p.add_argument(
        "--fps", type=int, default=60, help="frame-rate cap (default 60; physics: 100 Hz)"
    )
    p.add_argument("--fullscreen", action="store_true")
    p.add_argument("--autocentre", type=float, default=None, metavar="STRENGTH",
                   help="force feedback: autocentre spring 0..1 (Linux, evdev)")  # fmt: skip
    p.add_argument(
        "--fsync", action="store_true", help="fsync every recorded step (survives power loss)"
    )
    p.add_argument(
        "--synthetic",
        default=None,
        metavar="DRIVER",
        help="a synthetic participant (a driver of --population) turns a virtual G29 and "
        "presses its button through the screens; headless and as fast as possible unless "
        "--realtime; recordings labelled synthetic",
    )
    p.add_argument(
        "--population", default="paper", help="population of --synthetic (default paper)"
    )
    p.add_argument("--population-seed", type=int, default=0, help="its seed (0)")
    p.add_argument(
        "--realtime",
        action="store_true",
        help="with --synthetic: in a window, in real time, through every screen",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-drive study`` (``argv`` without the ``study`` word)."""
    return run(build_parser().parse_args(sys.argv[2:] if argv is None else list(argv)))
