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
   model fitted on the first recording and scored on all of them (the
   paper's protocol);
3. optionally (``--estimator``) runs the Gaussian-mixture EKF with that
   steering model over the recorded sensors and prints its lateral RMSE, the
   final weight of the true lane hypothesis and when it was first trusted
   (:func:`estimators.offline.estimate_recording`);
4. optionally writes PNG frames (``--frames DIR``) of the driver's or the
   top-down view, with the estimator's live weights in the HUD when it ran,
   and a video (``--video FILE.mp4``) if ``imageio`` with ffmpeg is
   installed (skipped with a message otherwise).

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

from estimators.offline import EstimatorRun, estimate_recording
from estimators.settings import model_curvature_limit, model_speed_limits
from hasa_cli import (
    EXIT_ENVIRONMENT,
    EXIT_OK,
    EXIT_PARTIAL,
    EXIT_USAGE,
    add_version,
    console_script,
    error,
)
from hasa_env.drivers import require_lane_keeping
from hasa_env.recording import check_replay
from hasa_env.recording.reader import load_paths
from hasa_env.render.frames import write_frames
from hasa_env.steering import score
from hasa_env.steering.loading import default_steering_ratio, in_model_units, load_model

__all__ = ["main"]


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


@console_script(PROG)
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-replay`` (see the module docstring)."""
    p = argparse.ArgumentParser(
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
    p.add_argument(
        "--fit", action="store_true", help="fit --model on the first recording, score on all"
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
        help="model units per recorded road-wheel rad (default: 15 for the paper's presets, "
        "which describe the steering-wheel angle; 1 for fitted or saved models)",
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
    p.add_argument("--view", choices=("driver", "top_down"), default="driver")
    p.add_argument(
        "--size", type=_size, default=(1280, 720), help="frame size WIDTHxHEIGHT (default 1280x720)"
    )
    p.add_argument("--show-points", action="store_true", help="draw the near and far points")
    args = p.parse_args(argv)
    if args.frame_every < 1:
        p.error("--frame-every must be >= 1")
    if args.fit and args.model is None:
        p.error(
            "--fit needs --model (two-point, generalized, a model file or package.module:Class)"
        )
    if not (math.isfinite(args.atol) and args.atol >= 0):
        p.error(f"--atol must be a finite tolerance >= 0, got {args.atol!r}")
    if args.video is not None:
        missing = _video_unavailable(args.video)
        if missing is not None:
            error(PROG, missing)
            return EXIT_ENVIRONMENT

    recordings = load_paths(args.paths)
    problems = [str(e) for e in recordings.errors]
    for msg in problems:
        error(PROG, f"cannot load: {msg}")
    if not recordings:
        error(PROG, "no recordings to replay")
        return EXIT_USAGE

    diverged = 0
    for rec in recordings:
        label = "synthetic" if (rec.meta.get("metadata") or {}).get("synthetic") else "recorded"
        complete = "" if rec.complete else " (incomplete: its writer stopped early)"
        try:
            check = check_replay(rec, args.atol)
            text = check.describe(args.atol)
        except ValueError as exc:
            check, text = None, f"cannot replay: {exc}"
        print(f"{rec.path}: {label}, {rec.steps} steps{complete}: {text}")
        if check is None or not check.matches:
            diverged += 1

    model = None
    if args.model is not None or args.estimator:
        spec = args.model or "generalized"
        if ":" in spec and os.getcwd() not in sys.path:
            sys.path.insert(0, os.getcwd())  # user models in the working directory
        try:
            model = load_model(spec, recordings[0].dt)
        except (ValueError, OSError) as exc:
            error(PROG, str(exc))
            return EXIT_USAGE
        if not model.is_fitted and not args.fit:
            error(
                PROG,
                f"model {spec!r} has no parameters: add --fit to fit it on the first "
                "recording, or give a saved model file (model.save('model.json'))",
            )
            return EXIT_USAGE
        road = recordings[0].road
        if args.steering is not None:
            model.steering_signal = args.steering
        if args.fit:
            model = model.fit(recordings[0].data, road)
            print(f"model {spec}: fitted on {recordings[0].path}")
        curvature_limit = model_curvature_limit(model)  # the roads it was fitted on
        ratio = args.steering_ratio
        if ratio is None:
            ratio = default_steering_ratio(spec, args.fit)
        print(f"model {spec}: steering ratio {ratio:g} (model units per recorded road-wheel rad)")
        if args.estimator and not args.no_lane_check:
            try:  # a model that cannot keep a lane would give the estimator wrong evidence
                require_lane_keeping(model, steering_ratio=ratio, what=f"model {spec!r}")
            except ValueError as exc:
                error(PROG, f"--estimator: {exc}; --no-lane-check runs it anyway")
                return EXIT_USAGE
        if args.model is not None:
            for rec in recordings:
                scores = score(model, in_model_units(rec.data, ratio), rec.road)
                shown = ", ".join(
                    f"{k} {_fmt(v)}"
                    for k, v in scores.items()
                    if k in ("rmse", "r2", "r2_increments", "ljung_box_p")
                )
                print(f"{rec.path}: model {spec}: {shown}")

    runs: dict[int, EstimatorRun] = {}
    if args.estimator and model is not None:  # (loaded above with --estimator)
        for i, rec in enumerate(recordings):
            try:
                result = estimate_recording(
                    rec,
                    model,
                    ratio,
                    steering_curvature_limit=curvature_limit,
                    speed_limits=model_speed_limits(model),
                )
            except ValueError as exc:  # e.g. sampled at another rate than the model
                error(PROG, f"{rec.path}: cannot run the estimator: {exc}")
                problems.append(str(exc))
                continue
            runs[i] = result
            hyp = ", ".join(
                f"{b:+g} m: {w:.3f}"
                for b, w in zip(result.hypotheses, result.weights[-1], strict=True)
            )
            trusted = "never" if math.isnan(result.trusted_from) else f"{result.trusted_from:.2f} s"
            print(
                f"{rec.path}: estimator: lateral RMSE {result.lateral_rmse:.3f} m, "
                f"final weights [{hyp}], "
                f"true lane trusted (> 0.9) from {trusted}"
            )

    if args.frames is not None or args.video is not None:
        for i, rec in enumerate(recordings):
            frames_dir = None
            if args.frames is not None:
                frames_dir = (
                    args.frames / Path(rec.path).stem if len(recordings) > 1 else args.frames
                )
            video = args.video
            if video is not None and len(recordings) > 1:
                video = video.with_name(f"{video.stem}_{Path(rec.path).stem}{video.suffix}")
            try:
                written = write_frames(
                    rec,
                    frames_dir,
                    every=args.frame_every,
                    view=args.view,
                    size=args.size,
                    show_points=args.show_points,
                    weights=runs[i].weights if i in runs else None,
                    video=video,
                )
            except OSError as exc:  # a read-only or full output folder
                error(PROG, f"{rec.path}: cannot write frames: {exc}")
                problems.append(str(exc))
                continue
            if written:
                print(f"{rec.path}: wrote {len(written)} frames to {frames_dir}")
    return EXIT_PARTIAL if problems or diverged else EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
