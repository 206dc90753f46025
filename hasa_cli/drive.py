"""``hasa-drive``: people drive the lane-keeping env with a wheel, a joystick or the keyboard.

Commands::

    hasa-drive --participant P07 [--track straight|curved] [--scenario NAME] [--bias random|B]
               [--runs 10]
    hasa-drive study STUDY.toml --participant P07 [--meta KEY=VALUE ...] [--check]
    hasa-drive calibrate [--output FILE]
    hasa-drive synthetic --driver Ill [--population paper] [--participant NAME]

The drive follows the paper's protocol (:class:`hasa_env.session.DriveSession`):
every run lasts 30 s, starts at 15 m/s and y = -0.5 m in the right lane; a
countdown precedes it. ``--scenario NAME`` (:mod:`hasa_env.scenarios`) drives
a named scenario instead: its env keys (road, markings, start) lie under the
options given (``--speed``, ``--lateral-offset``, ``--bias``, ...), so an option
left out takes the scenario's value; ``hasa-drive synthetic`` also gives its
driver the scenario's preferred offset (:func:`hasa_env.scenarios.scenario_drivers`). Each run is recorded under
``recordings/<participant>/run_NNN.csv`` (+ ``.json`` sidecar, + the raw
wheel and pedal values in ``run_NNN.inputs.tsv``), every step flushed at
once (a killed process keeps every completed step). ``--estimator`` runs the
Gaussian-mixture EKF alongside and shows its lane weights in the HUD.

``hasa-drive study`` (:mod:`hasa_cli.study`) runs one participant's session of
a study file (``studies/paper.toml``), with a session file that resumes it.

``hasa-drive synthetic`` drives through the same loop, headless and as fast
as possible, with a synthetic driver (:mod:`hasa_env.drivers`) turning an SDL
virtual G29 (:mod:`hasa_env.devices.virtual`); its recordings are labelled
``"synthetic": true`` in the sidecar metadata. ``recordings/sample`` was made
that way.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from hasa_cli import (
    EXIT_ENVIRONMENT,
    EXIT_USAGE,
    ArgumentParser,
    add_trust_model_option,
    add_version,
    console_script,
    error,
    report_write_failure,
)
from hasa_env.devices.calibration import (
    CalibrationError,
    JoystickCalibration,
    KeyboardCalibration,
    load_calibration,
    shipped_calibration,
    user_calibration_path,
)
from hasa_env.devices.sources import InputManager, init_pygame_input, no_screen_reason
from hasa_env.devices.virtual import VirtualJoystick, VirtualJoystickUnavailable
from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.recording import RecordingError
from hasa_env.scenarios import scenario_names
from hasa_env.session import (
    DriveSession,
    DriveSettings,
    VirtualWheelDriver,
)
from hasa_env.sim.config import ConfigError

# The steering models, estimators and synthetic drivers (statsmodels, scipy.stats: seconds to
# import) are imported where a command needs them, so that 'hasa-drive calibrate', a usage
# error and --help start at once.

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
    p.add_argument(
        "--track",
        choices=("straight", "curved"),
        default="straight",
        help="road (default straight)",
    )
    p.add_argument(
        "--bias",
        type=_bias,
        default=None,
        help="camera bias b in metres for every run, or 'random' (default: drawn per run)",
    )
    p.add_argument("--runs", type=int, default=10, help="number of runs (default %(default)s)")
    p.add_argument("--seconds", type=float, default=30.0, help="length of a run in s (default 30)")
    p.add_argument(
        "--scenario",
        choices=scenario_names(),
        default="paper",
        help="named scenario of every run (hasa_env.scenarios; default %(default)s); the "
        "options given here win over its values",
    )
    p.add_argument(
        "--speed",
        type=float,
        default=None,
        help="initial speed in m/s (default: the scenario's; paper 15)",
    )
    p.add_argument(
        "--lateral-offset",
        type=float,
        default=None,
        help="initial y in m (default: the scenario's; paper -0.5, late_ambiguity halfway "
        "between the hypotheses, turned 0.02 rad toward the other one's centre)",
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


def _drive(args: argparse.Namespace, log: Callable[[str], None]) -> int:
    reason = no_screen_reason()
    if reason is not None:
        error(
            "hasa-drive",
            f"no screen to drive on: {reason}; hasa-drive shows the road to a human driver and "
            "needs a display: run it in a desktop session (for a test without one: xvfb-run "
            "hasa-drive ...; headless work: hasa-replay replays and checks recordings, "
            "'hasa-drive synthetic' drives a synthetic driver through a virtual wheel)",
        )
        return EXIT_NO_SCREEN
    try:
        settings, keyboard, profiles, env_wrapper = _drive_setup(args, log)
    except (ValueError, ConfigError, ImportError, OSError) as exc:
        error("hasa-drive", str(exc))
        return EXIT_USAGE
    problem = _unwritable(settings.directory)
    if problem is not None:
        error("hasa-drive", problem)
        return EXIT_USAGE
    try:
        pg = init_pygame_input()
        flags = pg.FULLSCREEN if args.fullscreen else 0
        display = pg.display.set_mode((args.width, args.height), flags)
    except Exception as exc:  # noqa: BLE001 - pygame.error and friends: no usable screen
        error("hasa-drive", f"no screen to drive on: pygame could not open a window ({exc})")
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
            from hasa_cli.inputs import start_autocentre  # start-up: only where needed

            autocentre = start_autocentre(inputs, args.autocentre, log)
        results = session.run()
    except (OSError, RecordingError) as exc:  # a full disk: name it, keep what was written
        return _write_failed(exc, session, settings)
    finally:
        signal.signal(signal.SIGTERM, previous)
        if autocentre is not None:
            autocentre.close()
        session.close()
        inputs.close()
        pg.display.quit()
    log(f"hasa-drive: {len(results)} run(s) recorded in {settings.directory}")
    return 0


def _write_failed(exc: Exception, session: DriveSession, settings: DriveSettings) -> int:
    """One line for a drive that could not write (e.g. a full disk) and its exit status;
    re-raises ``exc`` if no operating-system error is behind it (a bug)."""
    kept = f"what was written before is kept ({len(session.results)} finished run(s))"
    status = report_write_failure("hasa-drive", exc, settings.directory, kept)
    if status is None:
        raise exc
    return status


def _drive_setup(
    args: argparse.Namespace, log: Callable[[str], None]
) -> tuple[DriveSettings, KeyboardCalibration, list[JoystickCalibration], Any]:
    """The drive's settings, keyboard calibration, joystick profiles and estimator wrapper
    (None without ``--estimator``), checked before any window opens; raises the input errors."""
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
        scenario=args.scenario,
    )
    settings.env_config()
    keyboard = load_calibration(args.keyboard) if args.keyboard else shipped_calibration("keyboard")
    if not isinstance(keyboard, KeyboardCalibration):
        raise CalibrationError(str(args.keyboard), "device", "must be 'keyboard' for --keyboard")
    from hasa_cli.inputs import estimator_for, joystick_profiles  # start-up: only where needed

    profiles = joystick_profiles(args.calibration, log)
    env_wrapper = None
    if args.estimator is not None:
        env_wrapper = estimator_for(
            args.estimator,
            _probe_env(settings),
            lane_check=not args.no_lane_check,
            log=log,
            trust_module=args.trust_model_module,
        )
    return settings, keyboard, profiles, env_wrapper


def _unwritable(directory: Path) -> str | None:
    """Why recordings cannot be written into ``directory`` (checked before any window opens)."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as exc:
        return f"cannot write recordings to {directory}: {exc.strerror or exc}"
    return None


def _probe_env(settings: DriveSettings) -> Any:
    return LaneKeepingEnv(config=settings.env_config())


def _raise_exit(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def _synthetic_driver(args: argparse.Namespace) -> tuple[Any, str]:
    """The driver ``--driver`` of the population as it drives in ``--scenario`` (its
    preferred offset: :func:`hasa_env.scenarios.scenario_drivers`) and the participant id
    (``--participant``, default ``synthetic-<population>-<seed>-<driver>[-<scenario>]``,
    the scenario named unless ``paper``); raises ValueError for an unknown driver."""
    from hasa_env.drivers import population  # start-up: only where needed

    seed = args.population_seed
    drivers = {p.name: p for p in population(args.population, seed=seed, scenario=args.scenario)}
    if args.driver not in drivers:
        raise ValueError(
            f"unknown driver {args.driver!r}; this population has {', '.join(drivers)}"
        )
    scenario = "" if args.scenario == "paper" else f"-{args.scenario}"
    default = f"synthetic-{args.population}-{seed}-{args.driver}{scenario}"
    return drivers[args.driver], args.participant or default


def _synthetic(args: argparse.Namespace, log: Callable[[str], None]) -> int:
    try:
        params, participant = _synthetic_driver(args)
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
            scenario=args.scenario,
        )
        settings.env_config()
    except (ValueError, ConfigError) as exc:
        error("hasa-drive", str(exc))
        return EXIT_USAGE
    problem = _unwritable(settings.directory)
    if problem is not None:
        error("hasa-drive", problem)
        return EXIT_USAGE
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    pg = init_pygame_input()
    try:
        wheel = VirtualJoystick.g29()
    except VirtualJoystickUnavailable as exc:
        error("hasa-drive", f"cannot create the virtual wheel: {exc}")
        return EXIT_ENVIRONMENT
    g29 = shipped_calibration("g29")
    assert isinstance(g29, JoystickCalibration)
    profile = JoystickCalibration(**{**_fields(g29), "match_names": (wheel.name,)})
    inputs = InputManager(shipped_calibration("keyboard"), [profile], pygame_module=pg)  # type: ignore[arg-type]
    from hasa_env.drivers import SyntheticDriver  # start-up: only where needed

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
    except (OSError, RecordingError) as exc:  # a full disk: name it, keep what was written
        return _write_failed(exc, session, settings)
    finally:
        session.close()
        inputs.close()
        wheel.detach()
    for r in results:
        log(f"hasa-drive synthetic: {r.path} ({r.steps} steps, {r.end_reason})")
    return 0 if len(results) == settings.runs else 1


def _fields(cal: JoystickCalibration) -> dict[str, Any]:
    return {k: getattr(cal, k) for k in cal.__dataclass_fields__ if k != "device"}


def _calibrate_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hasa-drive calibrate``."""
    p = ArgumentParser(
        prog="hasa-drive calibrate",
        description="Measure a wheel's axes (centre, locks, pedals); write a calibration file.",
    )
    add_version(p)
    p.add_argument(
        "--output",
        type=Path,
        default=user_calibration_path(),
        help="file to write (default %(default)s)",
    )
    p.add_argument(
        "--wheel-range",
        type=float,
        default=900.0,
        help="lock-to-lock range in degrees (default %(default)g)",
    )
    p.add_argument(
        "--steering-ratio", type=float, default=15.0, help="steering ratio (default %(default)g)"
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=300.0,
        help="give up after this many seconds (default %(default)g)",
    )
    return p


def _synthetic_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hasa-drive synthetic``."""
    p = ArgumentParser(
        prog="hasa-drive synthetic",
        description="Drive through hasa-drive's loop with a synthetic driver turning a "
        "virtual G29 "
        "(headless; the recordings are labelled synthetic).",
    )
    add_version(p)
    _add_session_arguments(p, participant_required=False)
    p.add_argument("--driver", default="Ill", help="driver name in the population (default Ill)")
    p.add_argument("--population", default="paper", help="population name (default paper)")
    p.add_argument("--population-seed", type=int, default=0, help="population seed (default 0)")
    p.set_defaults(runs=1)  # the help shows it: "(default %(default)s)"
    return p


def _drive_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hasa-drive`` (a human drive)."""
    p = ArgumentParser(
        prog="hasa-drive",
        description="Drive the lane-keeping env with a wheel (G29), a joystick or the keyboard; "
        "record each run. "
        "Subcommands: 'hasa-drive study', 'hasa-drive calibrate', 'hasa-drive synthetic' "
        "(see their --help).",
        epilog="Exit status: 0 ok, 1 fewer runs than asked, 2 usage or input error, "
        "3 no screen or no virtual wheel.",
    )
    add_version(p)
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
    p.add_argument(
        "--view",
        choices=("driver", "top_down"),
        default="driver",
        help="the driver's view or the top-down one (default driver)",
    )
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
    p.add_argument(
        "--no-lane-check",
        action="store_true",
        help="run --estimator even with a model that drives off the road when it steers "
        "itself (checked by default: 4 cars, 30 s, the straight track; the paper's two-point "
        "preset does)",
    )
    add_trust_model_option(p, "--estimator's model file")
    p.add_argument("--width", type=int, default=1280, help="window width in pixels (default 1280)")
    p.add_argument("--height", type=int, default=720, help="window height in pixels (default 720)")
    p.add_argument(
        "--fps",
        type=int,
        default=60,
        help="frame-rate cap (default 60; the physics runs at 100 Hz regardless)",
    )
    p.add_argument("--fullscreen", action="store_true")
    p.add_argument(
        "--autocentre",
        type=float,
        default=None,
        metavar="STRENGTH",
        help="force feedback: wheel autocentre spring strength 0..1 (Linux, needs evdev)",
    )
    return p


@console_script("hasa-drive")
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-drive`` (see the module docstring)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    log = print
    if argv and argv[0] == "calibrate":
        from hasa_env.devices.calibrator import calibrate  # start-up: only where needed

        args = _calibrate_parser().parse_args(argv[1:])
        return calibrate(
            args.output,
            wheel_range_deg=args.wheel_range,
            steering_ratio=args.steering_ratio,
            timeout=args.timeout,
        )
    if argv and argv[0] == "study":
        from hasa_cli.study import main as study_main  # start-up: only where needed

        return study_main(argv[1:])
    if argv and argv[0] == "synthetic":
        return _synthetic(_synthetic_parser().parse_args(argv[1:]), log)
    return _drive(_drive_parser().parse_args(argv), log)


if __name__ == "__main__":
    raise SystemExit(main())
