"""``hasa-replay FILE|DIR ...``: replay recordings headlessly and check them.

For every recording (a ``run_NNN.csv`` with its ``.json`` sidecar, or every
recording in a directory and its subdirectories) it:

1. replays the recorded actions through the env (:func:`hasa_env.recording.replay`:
   same config, seed, initial state and bias) and checks that the replayed
   trajectory matches the recorded one, bit for bit by default
   (``--atol`` for a tolerance); if not, it says where it first diverges
   (row, time, column, both values);
2. optionally (``--model``) scores a steering model's prediction of the
   recorded steering (:func:`hasa_env.steering.score`: RMSE, R^2, R^2 of the
   increments, Ljung-Box p) -- a paper preset (``two-point``,
   ``generalized``), a saved model file (any registered type, user types
   included), a user model ``package.module:ClassName`` (imported from the
   working directory or the installed packages), or, with ``--fit``, the
   model fitted on the first recording (``--fit-on N``: the first N, each a run
   of its own) and scored on all of them (the paper's protocol); a generalized
   model so fitted is fitted as hasa-bench fits its built-in one: its equation error's
   autoregression of ``--equation-error-order`` lags (docs/design.md §8.32; default
   hasa-bench's, 2, for the ``generalized`` preset, a model file's own order for a file)
   and its speed-scaled equation error (docs/design.md §8.34;
   :func:`benchmarks.speed_scaled.add_speed_scaled_error`: on held-out residuals when
   N >= 2, in-sample on one recording; ``--no-speed-scaled-error``: not fitted, the filter
   whitens by the autoregression instead), and the log says the autoregression and its
   order, the speed-scaled error's numbers and whether held out, or that none was found;
3. optionally (``--estimator``) runs the Gaussian-mixture EKF with that
   steering model over the recorded sensors and prints its lateral RMSE, the
   final weight of the true lane hypothesis and when it was first trusted
   (:func:`estimators.offline.estimate_recording`), after one line saying where the
   filters of all the recordings do not listen to the model's steering, and why
   (:func:`estimators.trust.trusted_filter`: e.g. above its training speeds); what a
   recording's own filter adds to that line (whether a declared equation-error
   autoregression is taken, decided by that recording's data) is printed just before its
   result (:func:`benchmarks.recordings.describe_trust`);
4. optionally writes PNG frames (``--frames DIR``) of the driver's or the
   top-down view, with the estimator's live weights in the HUD when it ran,
   and a video (``--video FILE.mp4``) if ``imageio`` with ffmpeg is
   installed (skipped with a message otherwise).

What loading repaired or tolerated in a recording (e.g. the partly written last line of a
crashed recording, dropped) is printed on stderr first, a ``warning:`` line naming the file.

With ``--json FILE`` it also writes what it found as one JSON document
(:class:`benchmarks.replay_document.ReplayDocument`; ``"format": "hasa_replay.results"``):
``version`` and ``versions`` (as hasa-bench's results.json), ``arguments`` (paths, atol,
model, fit, fit_on, speed_scaled_error, equation_error_order: as given, null when not given or
without --fit; steering, steering_ratio, estimator, lane_check),
``model`` (spec, steering ratio used, ``fitted_on``: the first recording fitted on, a path or
null as before ``--fit-on``; ``fitted_on_recordings``: all of them, in order; and, as in
hasa-bench's results.json, ``speed_scaled_error`` (coloured_std, correlation, white_std,
reference_speed, or null), ``speed_scaled_held_out`` and ``speed_scaled_gain``, each null when
not fitted; ``equation_error_order``, the order used, and ``equation_error_ar``, its
autoregression, empty when white), ``estimator_trust``, ``load_errors`` (``path``, ``message``), per recording
(``recordings``) its ``path``, ``label``, ``steps``, ``complete``, ``study_role`` (what it
was in its study session: ``measured run 3``, ``practice run 1``, ``aborted measured run 2
(interrupted)``, ``unfinished ...``; null without a session file), its replay check
(``replay``: ``matches``, ``text``, ``divergence``: ``row``, ``time``, ``column``,
``recorded``, ``replayed`` or null) and, where those steps ran, ``model`` (``scores``),
``estimator`` (lateral_rmse, hypotheses, final_weights, true_index, true_lane_weight,
trusted_from, final_decision, refused_by, trust_reasons, ``steering``: the share of the
time per state of the steering channel, ``live``, ``off``, ``unused``, ``mismatch``,
``tempered_model_error``, ``tempered_autocorrelation``, or null without a steering channel, and
``lateral_nees``) and ``frames``, each ``{"error": ...}``
where the step failed; ``warnings``: each warning the run printed on stderr (still printed
there), as ``recording`` (the path of the recording it arose on, null when none: the
model's lane check, the trust lines, a fit on several recordings), ``step`` (``load``, ``replay``, ``model``,
``estimator``, ``frames``), ``category`` (e.g. ``IdentifiabilityWarning``, a fit on the
first recording that cannot tell the lanes apart; ``RecordingWarning``, step ``load``, what
loading repaired in that recording) and ``message``; then ``error`` (why the
run ended early, else null) and ``exit_status``. NaN and infinities are null. It is written
atomically after the run, also when the run ends early after loading (no recording loads,
the model is refused, Ctrl-C), so what was done is kept. A ``FILE`` whose folder is missing
or not writable is a usage error before any work; ``-`` is refused (standard output carries
the printed lines).

The work is done by :mod:`benchmarks.recordings`; this module parses the
arguments, calls it and prints.

Paths may be recording CSVs (or their sidecars), Parquet files written by
``hasa-rec convert``, or folders (searched recursively).

Exit status (:mod:`hasa_cli`): 0 if every recording loads and replays as
recorded; 1 (partial) if any diverges or could not be loaded or analysed
(each named on stderr, the rest done); 2 for a wrong argument or when no
recording loads; 3 when ``--video`` needs imageio (or its ffmpeg plugin)
and it is not installed.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from benchmarks.defaults import DEFAULT_EQUATION_ERROR_ORDER
from benchmarks.recordings import (
    MAX_STEERING_RATIO,
    LaneKeepingError,
    ModelSetupError,
    PreparedModel,
    check_recordings,
    describe_estimate,
    describe_trust,
    estimate_recordings,
    load_model_spec,
    prepare_model,
    render_recordings,
    score_recordings,
    warn_load_notes,
)
from benchmarks.replay_document import ReplayDocument
from hasa_cli import (
    EXIT_ENVIRONMENT,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_PARTIAL,
    EXIT_USAGE,
    ArgumentParser,
    add_equation_error_order_option,
    add_speed_scaled_error_option,
    add_trust_model_option,
    add_version,
    console_script,
    error,
    output_file_problem,
    printable,
    report_write_failure,
)
from hasa_env.recording.reader import load_paths
from hasa_env.session.session_file import study_roles
from hasa_env.steering.base import SteeringModel
from hasa_env.steering.loading import add_module_folders

__all__ = ["build_parser", "main"]


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"size must be WIDTHxHEIGHT, e.g. 1280x720, got {text!r}"
        ) from None
    if not (64 <= w <= 4096 and 64 <= h <= 4096):
        raise argparse.ArgumentTypeError(f"size {w}x{h} out of range: 64..4096 per side")
    return w, h


def _fmt(value: float) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


PROG = "hasa-replay"
_FFMPEG_SUFFIXES = (".mp4", ".mkv", ".avi", ".mov", ".webm", ".m4v", ".mpeg", ".mpg", ".wmv")


def _video_unavailable(video: Path) -> str | None:
    """Why ``--video`` cannot be written on this machine, or None."""
    if importlib.util.find_spec("imageio") is None:
        return "--video needs imageio: pip install imageio imageio-ffmpeg"
    if (
        video.suffix.lower() in _FFMPEG_SUFFIXES
        and importlib.util.find_spec("imageio_ffmpeg") is None
    ):
        return f"--video {video.name} needs imageio's ffmpeg plugin: pip install imageio-ffmpeg"
    return None


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hasa-replay``.

    Long because it is an argparse option list: one option per statement, each with its help.
    """
    p = ArgumentParser(
        prog=PROG,
        description="Replay recordings headlessly, check that they reproduce, "
        "score a steering model "
        "and the estimator on them, render frames.",
        epilog="Exit status: 0 ok, 1 some recordings diverged or failed (each named), "
        "2 usage error or nothing loaded, 3 a missing optional package (--video).",
    )
    add_version(p)
    p.add_argument(
        "paths", nargs="+", help="recording CSV files or directories (searched recursively)"
    )
    p.add_argument(
        "--atol",
        type=float,
        default=0.0,
        help="tolerance of the comparison (default 0: bit for bit)",
    )
    p.add_argument(
        "--model",
        default=None,
        help="score a steering model: 'two-point', 'generalized' (paper presets), a saved model "
        "file, or 'package.module:ClassName' (a SteeringModel subclass; with --fit if it has "
        "no parameters)",
    )
    add_trust_model_option(p, "a --model file")
    p.add_argument(
        "--fit",
        action="store_true",
        help="fit --model on the first recording (--fit-on: the first N), score on all",
    )
    p.add_argument(
        "--fit-on",
        type=int,
        default=None,
        metavar="N",
        help="with --fit, fit on the first N recordings loaded, each a run of its own (default "
        "1); with N >= 2 a generalized model's speed-scaled equation error is fitted on "
        "held-out residuals (each recording's from the model refitted on the others), as "
        "hasa-bench fits it",
    )
    add_speed_scaled_error_option(
        p, "with --fit, fit a generalized model's", "its AR/white level", "that level"
    )
    add_equation_error_order_option(
        p,
        "a generalized model's fit (--fit)",
        None,
        f"{DEFAULT_EQUATION_ERROR_ORDER}, hasa-bench's, for the generalized preset; a model "
        "file's own order for a file",
    )
    p.add_argument(
        "--steering",
        choices=("measured", "applied"),
        default=None,
        help="which steering --model is fitted and scored on: the steering sensor's reading "
        "(measured, what the estimator sees; the default of fitted models) or the applied "
        "road-wheel angle",
    )
    p.add_argument(
        "--steering-ratio",
        type=float,
        default=None,
        help="model units per recorded road-wheel rad, in (0, 10000] (default: 15 for the "
        "paper's presets, which describe the steering-wheel angle; 1 for fitted or saved models)",
    )
    p.add_argument(
        "--estimator",
        action="store_true",
        help="run the Gaussian-mixture EKF with --model (default generalized) on each recording",
    )
    p.add_argument(
        "--no-lane-check",
        action="store_true",
        help="run --estimator even with a model that drives off the road when it steers "
        "itself (checked by default: 4 cars, 30 s, the straight track)",
    )
    p.add_argument("--frames", type=Path, default=None, help="write PNG frames into this directory")
    p.add_argument(
        "--video", type=Path, default=None, help="write a video (needs imageio + imageio-ffmpeg)"
    )
    p.add_argument("--frame-every", type=int, default=10, help="render every N-th row (default 10)")
    p.add_argument(
        "--view",
        choices=("driver", "top_down"),
        default="driver",
        help="view of the frames: the driver's or the top-down one (default driver)",
    )
    p.add_argument(
        "--size", type=_size, default=(1280, 720), help="frame size WIDTHxHEIGHT (default 1280x720)"
    )
    p.add_argument("--show-points", action="store_true", help="draw the near and far points")
    p.add_argument(
        "--json",
        type=Path,
        default=None,
        metavar="FILE",
        help="also write the results as one JSON document to FILE (atomically; written too "
        "when the run ends early after loading)",
    )
    return p


def _arguments(args: argparse.Namespace) -> dict[str, Any]:
    """The arguments that shape the results, for the JSON document."""
    return {
        "paths": list(args.paths),
        "atol": args.atol,
        "model": args.model,
        "fit": args.fit,
        "fit_on": (args.fit_on or 1) if args.fit else None,
        "speed_scaled_error": args.speed_scaled_error if args.fit else None,
        "equation_error_order": args.equation_error_order if args.fit else None,
        "steering": args.steering,
        "steering_ratio": args.steering_ratio,
        "estimator": args.estimator,
        "lane_check": args.estimator and not args.no_lane_check,
    }


def _model_spec(args: argparse.Namespace) -> str:
    """The spec of ``--model`` (default generalized); a user model's module is imported
    from the working directory too (added to ``sys.path``, which a console script's lacks)."""
    spec = args.model or "generalized"
    if ":" in spec:
        add_module_folders(os.getcwd())  # user models in the working directory
    return spec


def _model_options(args: argparse.Namespace) -> dict[str, Any]:
    """The options that load the model and that :func:`load_model_spec` checks first."""
    return {
        "fit": args.fit,
        "fit_on": args.fit_on or 1,
        "equation_error_order": args.equation_error_order,
        "steering_ratio": args.steering_ratio,
        "trust_module": args.trust_model_module,
    }


def _fit_candidates(recordings: Sequence[Any], roles: dict[Path, str]) -> list[Any]:
    """The recordings ``--fit`` may fit on, in order: all but a study session's practice,
    aborted and unfinished runs (``roles``: :func:`hasa_env.session.session_file.study_roles`)."""

    def usable(rec: Any) -> bool:
        role = None if rec.path is None else roles.get(Path(rec.path).resolve())
        return role is None or role.startswith("measured run")

    return [rec for rec in recordings if usable(rec)]


def _prepare_and_score(
    args: argparse.Namespace,
    recordings: Sequence[Any],
    problems: list[str],
    report: ReplayDocument,
    fit_pool: Sequence[Any],
    loaded: SteeringModel | None,
) -> PreparedModel:
    """The model of ``--model`` (default generalized) prepared (fitted, with ``--fit``, on the
    first ``--fit-on`` of ``fit_pool``); with ``--model`` its scores on every recording printed
    (a recording it cannot score named on stderr and added to ``problems``). Both are added
    to ``report``.

    Raises:
        LaneKeepingError, ModelSetupError: as :func:`benchmarks.recordings.prepare_model`.
    """
    spec = _model_spec(args)
    prepared = prepare_model(
        spec,
        fit_pool,
        **_model_options(args),
        speed_scaled_error=args.speed_scaled_error,
        steering=args.steering,
        lane_check=args.estimator and not args.no_lane_check,
        say=lambda message: print(printable(message)),
        log=report.warnings,
        loaded=loaded,  # (load_model_spec's, checked before the replay)
    )
    report.add_model(prepared)
    if args.model is not None:
        outcomes = score_recordings(prepared, recordings, report.warnings)
        report.add_outcomes("model", outcomes)
        for outcome in outcomes:
            if outcome.error is not None:
                error(PROG, f"{outcome.path}: cannot score model {spec}: {outcome.error}")
                problems.append(outcome.error)
                continue
            shown = ", ".join(f"{k} {_fmt(v)}" for k, v in outcome.value.items())
            print(printable(f"{outcome.path}: model {spec}: {shown}"))
    return prepared


def _estimate(
    prepared: PreparedModel, recordings: Sequence[Any], problems: list[str], report: ReplayDocument
) -> dict[int, Any]:
    """Run the estimator over every recording and print where it trusted the model's
    steering (one line of what every recording's filter shares, then beside a recording's
    result what its own filter adds, e.g. whether a declared equation-error autoregression
    is taken there) and its result (a recording it cannot run on named on stderr and added
    to ``problems``); both added to ``report``. Returns the weights by recording index."""
    outcomes = estimate_recordings(prepared, recordings, report.warnings)
    report.add_outcomes("estimator", outcomes)
    trust = describe_trust(prepared, outcomes)
    report.estimator_trust = trust.model
    if trust.model is not None:
        print(printable(f"model {prepared.spec}: estimator trust: {trust.model}"))
    weights = {}
    for outcome in outcomes:
        if outcome.error is not None:
            error(PROG, f"{outcome.path}: cannot run the estimator: {outcome.error}")
            problems.append(outcome.error)
            continue
        weights[outcome.index] = outcome.value.weights
        own = trust.recordings.get(outcome.index)
        if own is not None:
            print(printable(f"{outcome.path}: estimator trust: {own}"))
        print(printable(f"{outcome.path}: estimator: {describe_estimate(outcome.value)}"))
    return weights


def _run(
    args: argparse.Namespace, recordings: Sequence[Any], problems: list[str], report: ReplayDocument
) -> int:
    """Every step after loading (module docstring), each recorded in ``report`` as it ends;
    a run that ends early says why in ``report.error``. Returns the exit status."""
    roles = study_roles(rec.path for rec in recordings if rec.path is not None)
    fit_pool = _fit_candidates(recordings, roles) if args.fit else recordings
    if not fit_pool:
        report.error = (
            "--fit: no recording to fit on: each is a study session's practice, aborted or "
            "unfinished run"
        )
        error(PROG, report.error)
        return EXIT_USAGE
    loaded = None
    if args.model is not None or args.estimator:
        try:  # a model that cannot be loaded refuses the run before anything is replayed
            loaded = load_model_spec(_model_spec(args), fit_pool, **_model_options(args))
        except ModelSetupError as exc:
            report.error = str(exc)
            error(PROG, report.error)
            return EXIT_USAGE
    checks = check_recordings(recordings, args.atol, report.warnings)
    report.add_checks(checks)
    for check, entry in zip(checks, report.recordings, strict=True):
        role = None if check.path is None else roles.get(Path(check.path).resolve())
        entry["study_role"] = role
        print(printable(check.describe() + ("" if role is None else f" [study: {role}]")))
    diverged = sum(not check.matches for check in checks)

    prepared = None
    if args.model is not None or args.estimator:
        if len(fit_pool) < len(recordings):
            print(
                f"--fit: on the study sessions' completed measured runs only ("
                f"{len(recordings) - len(fit_pool)} practice, aborted or unfinished run(s) left "
                "out, as hasa-bench leaves them out)"
            )
        try:
            with report.warnings.about(None, "model"):
                prepared = _prepare_and_score(args, recordings, problems, report, fit_pool, loaded)
        except LaneKeepingError as exc:
            report.error = f"--estimator: {exc}; --no-lane-check runs it anyway"
            error(PROG, report.error)
            return EXIT_USAGE
        except ModelSetupError as exc:
            report.error = str(exc)
            error(PROG, report.error)
            return EXIT_USAGE

    weights: dict[int, Any] = {}
    if args.estimator and prepared is not None:  # (loaded above with --estimator)
        with report.warnings.about(None, "estimator"):
            weights = _estimate(prepared, recordings, problems, report)

    if args.frames is not None or args.video is not None:
        options = {"every": args.frame_every, "view": args.view, "size": args.size,
                   "show_points": args.show_points}  # fmt: skip
        outcomes = render_recordings(
            recordings, args.frames, args.video, weights, report.warnings, **options
        )
        report.add_outcomes("frames", outcomes)
        for outcome in outcomes:
            if outcome.error is not None:
                error(PROG, f"{outcome.path}: cannot write frames: {outcome.error}")
                problems.append(outcome.error)
                continue
            written, frames_dir = outcome.value
            if written:
                print(printable(f"{outcome.path}: wrote {len(written)} frames to {frames_dir}"))
    return EXIT_PARTIAL if problems or diverged else EXIT_OK


def _write_report(path: Path | None, report: ReplayDocument, status: int) -> int:
    """Write ``report`` with ``status`` to ``path`` (None: not asked for). Returns ``status``,
    or that of the write failure (named on stderr)."""
    if path is None:
        return status
    report.exit_status = status
    try:
        report.write(path)
    except OSError as exc:
        failed = report_write_failure(PROG, exc, path, "the results are printed above")
        return status if failed is None else max(status, failed)
    return status


def _load_and_run(args: argparse.Namespace, report: ReplayDocument) -> int:
    """Load the recordings, run every step (:func:`_run`) and write ``report`` (also when
    the run ends early after loading). Returns the exit status."""
    with report.warnings.about(None, "load"):
        recordings = load_paths(args.paths)
        warn_load_notes(recordings, report.warnings)  # e.g. a crashed recording's cut line
    report.add_load_errors(recordings.errors)
    problems = [str(e) for e in recordings.errors]
    for msg in problems:
        error(PROG, f"cannot load: {msg}")
    if not recordings:
        report.error = "no recordings to replay"
        error(PROG, report.error)
        return _write_report(args.json, report, EXIT_USAGE)
    try:
        status = _run(args, recordings, problems, report)
    except KeyboardInterrupt:  # keep what was done (console_script says "interrupted")
        report.error = "interrupted"
        _write_report(args.json, report, EXIT_INTERRUPTED)
        raise
    return _write_report(args.json, report, status)


@console_script(PROG)
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-replay`` (see the module docstring)."""
    p = build_parser()
    args = p.parse_args(argv)
    if args.frame_every < 1:
        p.error("--frame-every must be >= 1")
    if args.fit and args.model is None:
        p.error(
            "--fit needs --model (two-point, generalized, a model file or package.module:Class)"
        )
    if args.fit_on is not None and not args.fit:
        p.error("--fit-on needs --fit")
    if args.equation_error_order is not None and not args.fit:
        p.error("--equation-error-order needs --fit")
    if args.fit_on is not None and args.fit_on < 1:
        p.error(
            "--fit-on must be an integer from 1 to the number of recordings loaded, "
            f"got {args.fit_on!r}"
        )
    if not (math.isfinite(args.atol) and args.atol >= 0):
        p.error(f"--atol must be a finite tolerance >= 0, got {args.atol!r}")
    ratio = args.steering_ratio
    if ratio is not None and not (0 < ratio <= MAX_STEERING_RATIO):
        p.error(
            f"--steering-ratio must be a number in (0, {MAX_STEERING_RATIO:g}] (model units per "
            f"road-wheel rad), got {ratio!r}"
        )
    unwritable = None if args.json is None else output_file_problem("--json", args.json)
    if unwritable is not None:
        p.error(unwritable)
    if args.video is not None:
        missing = _video_unavailable(args.video)
        if missing is not None:
            error(PROG, missing)
            return EXIT_ENVIRONMENT

    report = ReplayDocument(_arguments(args))
    with report.warnings.listen():  # each kept in the document, shown as before
        return _load_and_run(args, report)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
