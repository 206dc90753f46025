"""``hasa-drive``: people drive the lane-keeping env with a wheel, a joystick or the keyboard.

Commands::

    hasa-drive --participant P07 [--track straight|curved] [--bias random|B] [--runs 10]
    hasa-drive study STUDY.toml --participant P07 [--meta KEY=VALUE ...] [--check]
    hasa-drive calibrate [--output FILE]
    hasa-drive synthetic --driver Ill [--population paper] [--participant NAME]

The drive follows the paper's protocol (:class:`hasa_env.session.DriveSession`):
every run lasts 30 s, starts at 15 m/s and y = -0.5 m in the right lane; a
countdown precedes it. Each run is recorded under
``recordings/<participant>/run_NNN.csv`` (+ ``.json`` sidecar, + the raw
wheel and pedal values in ``run_NNN.inputs.tsv``), every step flushed at
once (a killed process keeps every completed step). ``--estimator`` runs the
Gaussian-mixture EKF alongside and shows its lane weights in the HUD.

``hasa-drive study`` runs one participant's session of a study file
(:mod:`hasa_env.session.study`, e.g. ``studies/paper.toml``): instructions,
practice and measured runs with the study's bias schedule, breaks and an end
screen, in a participant's view without cues (no ghost markings, no HUD,
unless the study asks for them), while the terminal shows the experimenter a
status line (run, true bias, time, speed, lateral offset, estimator
weights). It writes ``<output>/<participant>/session.json`` beside the
recordings; running it again resumes the session at the next run
(:mod:`hasa_env.session.session_file`). ``--synthetic DRIVER`` lets a
synthetic driver take part through a virtual G29 (headless, or in a window
with ``--realtime``). Exit status: 0 complete, 1 stopped before the end
(resume it), 2 bad input, 3 no screen.

``hasa-drive synthetic`` drives through the same loop, headless and as fast
as possible, with a synthetic driver (:mod:`hasa_env.drivers`) turning an SDL
virtual G29 (:mod:`hasa_env.devices.virtual`); its recordings are labelled
``"synthetic": true`` in the sidecar metadata. ``recordings/sample`` was made
that way.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimators.wrappers import estimator_wrapper
from hasa_cli import EXIT_ENVIRONMENT, EXIT_PARTIAL
from hasa_env.devices.calibration import (
    CalibrationError,
    JoystickCalibration,
    KeyboardCalibration,
    load_calibration,
    shipped_calibration,
    user_calibration_path,
)
from hasa_env.devices.calibrator import calibrate
from hasa_env.devices.force_feedback import Autocentre, ForceFeedbackUnavailable
from hasa_env.devices.sources import InputManager, init_pygame_input, no_screen_reason
from hasa_env.devices.virtual import VirtualJoystick, VirtualJoystickUnavailable
from hasa_env.drivers import SyntheticDriver, population
from hasa_env.envs.lane_keeping import LaneKeepingEnv
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
from hasa_env.steering.base import SteeringModel
from hasa_env.steering.loading import default_steering_ratio, load_model

__all__ = ["EXIT_NO_SCREEN", "main"]

EXIT_NO_SCREEN = EXIT_ENVIRONMENT
"""Exit status of ``hasa-drive`` when there is no screen to drive on."""


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
            env_wrapper = _estimator(args.estimator, _probe_env(settings))
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


def _probe_env(settings: DriveSettings) -> Any:
    return LaneKeepingEnv(config=settings.env_config())


def _estimator_model(spec: str, dt: float) -> SteeringModel:
    """The steering model of ``--estimator``: fitted, with an ARX form (ValueError if not)."""
    if ":" in spec and os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())  # user models in the working directory
    model = load_model(spec, dt)
    if not model.is_fitted:
        raise ValueError(
            f"--estimator {spec}: the model has no parameters, and the estimator needs a fitted "
            "model: fit it and save it (model.fit(runs).save('model.json')), then pass that "
            "file, or name a function that returns a fitted model"
        )
    if model.arx() is None:
        raise ValueError(
            f"--estimator {spec}: {type(model).__name__}.arx() returns None: the estimator "
            "builds on a model's ARX form (README 'Write a steering model')"
        )
    return model


def _estimator(spec: str, probe: Any) -> Callable[[Any], Any]:
    """The env wrapper running the estimator with ``spec``'s model (checked on ``probe``)."""
    model = _estimator_model(spec, probe.setup.env_step_duration)
    wrapper = estimator_wrapper(model, default_steering_ratio(spec, fitted=False))
    wrapper(probe)  # fail now, not after the countdown
    return wrapper


def _raise_exit(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def _start_autocentre(inputs: InputManager, strength: float, log: Callable[[str], None]) -> Any:
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


# ------------------------------------------------------------------------- study
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


def _print_schedule(study: Study, participant: str, slot: int | None) -> None:
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


def _study(args: argparse.Namespace) -> int:
    prog = "hasa-drive study"
    status = StatusLine()
    log = status.log
    try:
        study = Study.load(args.study)
        if args.check:
            _print_schedule(study, args.participant, args.slot)
            return 0
        synthetic = args.synthetic is not None
        headless = synthetic and not args.realtime
        DriveSettings(participant=args.participant, output=args.output)  # a usable id
        keyboard = (
            load_calibration(args.keyboard) if args.keyboard else shipped_calibration("keyboard")
        )
        if not isinstance(keyboard, KeyboardCalibration):
            raise CalibrationError(
                str(args.keyboard), "device", "must be 'keyboard' for --keyboard"
            )
        env_wrapper = None
        if args.estimator is not None:
            track = study.document["measured"]["track"]
            env_wrapper = _estimator(args.estimator, LaneKeepingEnv(config=study.env_config(track)))
        # the input is checked first: a bad file is exit 2 with or without a screen
        if not headless:
            reason = no_screen_reason()
            if reason is not None:
                print(
                    f"{prog}: no screen to drive on: {reason}.\n"
                    "A study session shows the road to its participant and needs a display "
                    "(for a test without one: xvfb-run hasa-drive study ...; a synthetic "
                    "participant can drive headless: --synthetic DRIVER without --realtime).",
                    file=sys.stderr,
                )
                return EXIT_NO_SCREEN
        folder = Path(args.output) / args.participant
        resuming = (folder / SESSION_FILE).exists()
        answers: dict[str, Any] = {}
        if not resuming:
            answers = _answers(study, dict(args.meta), not synthetic and sys.stdin.isatty())
    except (StudyError, SessionError, ValueError, ConfigError, ImportError, OSError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    if headless:
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    pg = init_pygame_input()
    display = None
    if not headless:
        try:
            flags = pg.FULLSCREEN if args.fullscreen else 0
            display = pg.display.set_mode((args.width, args.height), flags)
        except Exception as exc:  # noqa: BLE001 - pygame.error and friends: no usable screen
            print(f"{prog}: no screen to drive on: pygame could not open a window ({exc})",
                  file=sys.stderr)  # fmt: skip
            return EXIT_NO_SCREEN
        pg.display.set_caption(study.document["study"]["title"] or f"hasa-drive: {study.name}")
    wheel = None
    hook = None
    run_metadata: dict[str, Any] = {"estimator_shown": args.estimator}
    try:
        if synthetic:
            drivers = {p.name: p for p in population(args.population, seed=args.population_seed)}
            if args.synthetic not in drivers:
                print(f"{prog}: unknown driver {args.synthetic!r}; this population has "
                      f"{', '.join(drivers)}", file=sys.stderr)  # fmt: skip
                return 2
            try:
                wheel = VirtualJoystick.g29()
            except VirtualJoystickUnavailable as exc:
                print(f"{prog}: cannot create the virtual wheel: {exc}", file=sys.stderr)
                return EXIT_ENVIRONMENT
            g29 = shipped_calibration("g29")
            assert isinstance(g29, JoystickCalibration)
            profile = JoystickCalibration(**{**_fields(g29), "match_names": (wheel.name,)})
            profiles = [profile]
            params = drivers[args.synthetic]
            steering = VirtualWheelDriver(wheel, SyntheticDriver(params), profile)
            presser = WheelButtonPresser(wheel, after=0.2)

            def hook(session: DriveSession) -> None:
                steering(session)
                presser(session)

            run_metadata |= {
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
        else:
            profiles = _joystick_profiles(args.calibration, log)
        inputs = InputManager(keyboard, profiles, use_joystick=not args.keyboard_only,
                              pygame_module=pg)  # fmt: skip
        session = StudySession(
            study,
            args.participant,
            inputs,
            output=args.output,
            metadata=answers,
            slot=args.slot,
            display=display,
            realtime=not headless,
            hook=hook,
            env_wrapper=env_wrapper,
            status=None if args.no_status else status,
            fps=args.fps,
            log=log,
            run_metadata=run_metadata,
            fsync=args.fsync,
        )
    except (StudyError, SessionError, ValueError, OSError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        if wheel is not None:
            wheel.detach()
        return 2
    previous = signal.signal(signal.SIGTERM, _raise_exit)
    autocentre = None
    try:
        if args.autocentre is not None and not synthetic:
            autocentre = _start_autocentre(inputs, args.autocentre, log)
        outcome = session.run()
    except (StudyError, SessionError) as exc:
        status.close()
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
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
    summary = outcome.session.summary()
    print(
        f"{prog}: {summary['participant']}: {summary['practice_completed']} practice and "
        f"{summary['measured_completed']}/{summary['measured_scheduled']} measured runs "
        f"recorded ({summary['left_road']} left the road), {summary['aborted']} aborted; "
        f"session file {outcome.session.path}"
    )
    if outcome.state == "quit":
        print(f"{prog}: stopped with {summary['remaining']} run(s) to go; the same command "
              "resumes the session at the next run")  # fmt: skip
        return EXIT_PARTIAL
    return 0


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
    if argv and argv[0] == "study":
        p = argparse.ArgumentParser(
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
        p.add_argument("--width", type=int, default=1280)
        p.add_argument("--height", type=int, default=720)
        p.add_argument("--fps", type=int, default=60, help="frame-rate cap (physics: 100 Hz)")
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
        p.add_argument("--population", default="paper", help="population of --synthetic")
        p.add_argument("--population-seed", type=int, default=0, help="its seed (0)")
        p.add_argument(
            "--realtime",
            action="store_true",
            help="with --synthetic: in a window, in real time, through every screen",
        )
        return _study(p.parse_args(argv[1:]))
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
        "Subcommands: 'hasa-drive study', 'hasa-drive calibrate', 'hasa-drive synthetic' "
        "(see their --help).",
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
        "(steering model: two-point, generalized (default), a saved model file or "
        "package.module:Class)",
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
