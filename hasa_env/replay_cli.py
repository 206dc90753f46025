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
   ``generalized``), a saved model file, or, with ``--fit``, the model fitted
   on the first recording and scored on all of them (the paper's protocol);
3. optionally (``--estimator``) runs the Gaussian-mixture EKF with that
   steering model over the recorded sensors and prints its lateral RMSE, the
   final weight of the true lane hypothesis and when it was first trusted;
4. optionally writes PNG frames (``--frames DIR``) of the driver's or the
   top-down view, with the estimator's live weights in the HUD when it ran,
   and a video (``--video FILE.mp4``) if ``imageio`` with ffmpeg is
   installed (skipped with a message otherwise).

Exit status: 0 if every recording replays as recorded, 1 if any diverges,
2 if a recording could not be loaded or an argument is wrong.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ReplayCheck",
    "check_replay",
    "collect_recordings",
    "estimate_recording",
    "default_steering_ratio",
    "in_model_units",
    "make_model",
    "write_frames",
    "main",
]


@dataclass(frozen=True)
class ReplayCheck:
    """Result of replaying one recording.

    Attributes:
        rows: rows in the recording (row 0 = the reset state).
        replayed_rows: rows the replay produced.
        divergence: None if they match, else (row, column, recorded value, replayed value).
        time: simulated time (s) of the divergent row (NaN if they match).
    """

    rows: int
    replayed_rows: int
    divergence: tuple[int, str, Any, Any] | None
    time: float = math.nan

    @property
    def matches(self) -> bool:
        return self.divergence is None

    def describe(self, atol: float = 0.0) -> str:
        if self.divergence is None:
            how = "bit for bit" if atol == 0.0 else f"within {atol:g}"
            return f"replay matches the recording {how} ({self.rows} rows)"
        row, column, a, b = self.divergence
        if column == "step" and (a is None or b is None):
            shorter = "replay" if b is None else "recording"
            return (
                f"DIVERGES: the {shorter} ends at row {row} (recording {self.rows} rows, "
                f"replay {self.replayed_rows} rows)"
            )
        return (
            f"DIVERGES at row {row} (t = {self.time:.2f} s), column {column!r}: "
            f"recorded {a!r}, replayed {b!r}"
        )


def check_replay(recording: Any, atol: float = 0.0) -> ReplayCheck:
    """Replay ``recording`` (a :class:`hasa_env.recording.Recording`) and compare."""
    from hasa_env.recording import compare_recordings, replay

    replayed = replay(recording)
    first = compare_recordings(recording, replayed, atol=atol)
    n, m = len(recording.data), len(replayed)
    if first is None:
        return ReplayCheck(n, m, None)
    row, column = first
    a = recording.data[column].iloc[row].item() if row < n else None
    b = replayed[column].iloc[row].item() if row < m else None
    t = float(recording.data["time"].iloc[row]) if row < n else math.nan
    return ReplayCheck(n, m, (row, column, a, b), t)


def collect_recordings(paths: Sequence[str | os.PathLike[str]]) -> tuple[list[Any], list[str]]:
    """Load the recordings named by ``paths`` (files, or directories searched recursively).

    Returns:
        (recordings, problems): the loaded recordings in path order and one
        message per file that could not be loaded.
    """
    from hasa_env.recording import RecordingError, RecordingWarning, load_recording, load_recordings

    recordings: list[Any] = []
    problems: list[str] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            dirs = sorted(
                {p.parent for p in path.rglob("*.csv")} | {p.parent for p in path.rglob("*.json")}
            )
            if not dirs:
                problems.append(f"{path}: no recordings (no *.csv files) here or below")
            for d in dirs:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RecordingWarning)
                    loaded = load_recordings(d)
                recordings.extend(loaded)
                problems.extend(str(e) for e in loaded.errors)
        else:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RecordingWarning)
                    recordings.append(load_recording(path))
            except (RecordingError, FileNotFoundError) as exc:
                problems.append(str(exc))
    return recordings, problems


# ------------------------------------------------------------ steering model
PAPER_PRESETS = ("two-point", "generalized")
PAPER_STEERING_RATIO = 15.0
"""Model units per road-wheel radian of the paper's presets: their coefficients describe the
G29's steering-wheel angle (DESIGN.md section 4: the generalized preset centres the car at
15-45 m/s only with a steering ratio of 15)."""


def default_steering_ratio(spec: str, fitted: bool) -> float:
    """Steering ratio (model units per recorded road-wheel radian) for a model given by ``spec``.

    The paper's presets (not refitted) work in steering-wheel units: 15; a model
    fitted on recordings, or loaded from a file, is taken to work in road-wheel units: 1.
    """
    return PAPER_STEERING_RATIO if spec in PAPER_PRESETS and not fitted else 1.0


def in_model_units(frame: Any, steering_ratio: float) -> Any:
    """A copy of a recording frame with ``steering`` and ``sensor_steering`` times the ratio."""
    if steering_ratio == 1.0:
        return frame
    out = frame.copy()
    for column in ("steering", "sensor_steering"):
        out[column] = frame[column] * steering_ratio
    return out


def make_model(spec: str, dt: float) -> Any:
    """A steering model: ``two-point`` / ``generalized`` (paper presets) or a saved model file."""
    from hasa_env.steering import GeneralizedModel, SteeringModel, TwoPointModel

    if spec == "two-point":
        return TwoPointModel.paper(dt=dt)
    if spec == "generalized":
        return GeneralizedModel.paper()
    if os.path.exists(spec):
        return SteeringModel.load(spec)
    raise ValueError(
        f"unknown model {spec!r}: use 'two-point', 'generalized' or the path of a saved model file"
    )


def _road(recording: Any) -> Any:
    from hasa_env.core import build_setup

    return build_setup(recording.config).road


def _dt(recording: Any) -> float:
    cfg = recording.config
    return cfg["action_repeat"] / cfg["sim_frequency"]


# ----------------------------------------------------------------- estimator
@dataclass(frozen=True)
class EstimatorRun:
    """The mixture estimator over one recording.

    Attributes:
        weights: (rows, C) hypothesis weights per row.
        hypotheses: (C,) camera biases b (m).
        lateral_offset: (rows,) mixture estimate of y (m).
        lateral_rmse: RMS of estimate - true y over all rows (m).
        true_index: index of the recording's true hypothesis (-1 if it is none of them).
        final_true_weight: weight of the true hypothesis at the end (NaN if not among them).
        trusted_from: first time (s) from which the true hypothesis' weight stays above 0.9
            (NaN if never).
    """

    weights: np.ndarray
    hypotheses: np.ndarray
    lateral_offset: np.ndarray
    lateral_rmse: float
    true_index: int
    final_true_weight: float
    trusted_from: float


def estimate_recording(
    recording: Any, steering_model: Any, steering_ratio: float = 1.0
) -> EstimatorRun:
    """Run the mixture EKF (:class:`estimators.gm_ekf.GaussianMixtureEKF`) over a recording.

    Through :func:`estimators.offline.run_estimator`: it sees what the car's
    sensors recorded (speed, biased camera, steering, IMU), with the
    hypotheses of the recording's config and filter settings from that
    config; the steering model enters through its ARX form, and
    ``steering_ratio`` (model units per recorded road-wheel radian) goes to
    the filter settings.
    """
    from estimators.gm_ekf import FilterSettings, GaussianMixtureEKF
    from estimators.offline import run_estimator

    data = recording.data
    cfg = recording.config
    hypotheses = np.asarray(cfg["markings"]["hypotheses"], dtype=np.float64)
    estimator = GaussianMixtureEKF(
        steering_model.arx(),
        FilterSettings.from_env_config(cfg, steering_ratio=steering_ratio),
        dt=_dt(recording),
    )
    result = run_estimator(estimator, data, hypotheses=hypotheses)
    n = len(data)
    weights = result.weights[0, :n]
    lateral = result.mean[0, :n, result.state_names.index("lateral_offset")]
    true_y = data["lateral_offset"].to_numpy(dtype=np.float64)
    rmse = float(np.sqrt(np.mean((lateral - true_y) ** 2)))
    true_index = int(data["bias_index"].iloc[0])
    if not 0 <= true_index < hypotheses.size:
        matches = np.flatnonzero(np.isclose(hypotheses, float(data["bias"].iloc[0])))
        true_index = int(matches[0]) if matches.size else -1
    if true_index < 0:
        return EstimatorRun(weights, hypotheses, lateral, rmse, -1, math.nan, math.nan)
    w_true = weights[:, true_index]
    below = np.flatnonzero(w_true <= 0.9)
    if below.size == 0:
        trusted = 0.0
    elif below[-1] + 1 < n:
        trusted = float(data["time"].iloc[below[-1] + 1])
    else:
        trusted = math.nan
    return EstimatorRun(weights, hypotheses, lateral, rmse, true_index, float(w_true[-1]), trusted)


# -------------------------------------------------------------------- frames
def write_frames(
    recording: Any,
    directory: str | os.PathLike[str] | None,
    *,
    every: int = 10,
    view: str = "driver",
    size: tuple[int, int] = (1280, 720),
    show_points: bool = False,
    weights: np.ndarray | None = None,
    video: str | os.PathLike[str] | None = None,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Render every ``every``-th row of a recording as PNG frames and/or a video.

    The frames are drawn from the recorded rows themselves (the row's info
    keys), headless. ``weights`` (rows, C) puts an estimator's hypothesis
    weights into the HUD. The video (``.mp4``, ``.gif``, ...; frame rate
    ``100 / every`` for 100 Hz recordings, i.e. real time) needs ``imageio``
    (and ``imageio-ffmpeg`` for mp4); without them it is skipped with a message.

    Returns:
        The PNG files written.
    """
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    import pygame

    from hasa_env.config import deep_merge
    from hasa_env.core import INFO_KEYS, build_setup
    from hasa_env.rendering import make_renderer

    config = deep_merge(
        recording.config,
        {"render": {"width": size[0], "height": size[1], "show_points": show_points}},
    )
    setup = build_setup(config)
    renderer = make_renderer(setup, "rgb_array", view=view)
    data = recording.data
    out = Path(directory) if directory is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    writer = None
    if video is not None:
        try:
            import imageio.v2 as imageio

            fps = 1.0 / (_dt(recording) * every)
            writer = imageio.get_writer(str(video), fps=fps)
        except Exception as exc:  # noqa: BLE001 - missing imageio / ffmpeg plugin: skip cleanly
            log(
                f"hasa-replay: no video ({exc.__class__.__name__}: {exc}); "
                "install imageio and imageio-ffmpeg"
            )
            writer = None
    written: list[Path] = []
    columns = {k: data[k].to_numpy() for k in INFO_KEYS}
    try:
        for row in range(0, len(data), every):
            info = {k: columns[k][row].item() for k in INFO_KEYS}
            w = None if weights is None else list(weights[row])
            surface = renderer.draw(info, w)
            if out is not None:
                path = out / f"frame_{row:05d}.png"
                pygame.image.save(surface, str(path))
                written.append(path)
            if writer is not None:
                from hasa_env.rendering import surface_to_array

                writer.append_data(surface_to_array(surface))
    finally:
        if writer is not None:
            writer.close()
            log(f"hasa-replay: wrote {video}")
        renderer.close()
    return written


# ----------------------------------------------------------------------- CLI
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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-replay`` (see the module docstring)."""
    p = argparse.ArgumentParser(
        prog="hasa-replay",
        description="Replay recordings headlessly, check that they reproduce, "
        "score a steering model "
        "and the estimator on them, render frames.",
    )
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
        help="score a steering model: 'two-point', 'generalized' (paper presets) or a model file",
    )
    p.add_argument(
        "--fit", action="store_true", help="fit --model on the first recording, score on all"
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
        p.error("--fit needs --model (two-point or generalized)")

    recordings, problems = collect_recordings(args.paths)
    for msg in problems:
        print(f"hasa-replay: cannot load: {msg}", file=sys.stderr)
    if not recordings:
        print("hasa-replay: no recordings to replay", file=sys.stderr)
        return 2

    diverged = 0
    for rec in recordings:
        label = "synthetic" if rec.meta.get("metadata", {}).get("synthetic") else "recorded"
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
        try:
            model = make_model(spec, _dt(recordings[0]))
        except (ValueError, OSError) as exc:
            print(f"hasa-replay: {exc}", file=sys.stderr)
            return 2
        road = _road(recordings[0])
        if args.fit:
            model = model.fit(recordings[0].data, road)
            print(f"model {spec}: fitted on {recordings[0].path}")
        ratio = args.steering_ratio
        if ratio is None:
            ratio = default_steering_ratio(spec, args.fit)
        print(f"model {spec}: steering ratio {ratio:g} (model units per recorded road-wheel rad)")
        if args.model is not None:
            from hasa_env.steering import score

            for rec in recordings:
                scores = score(model, in_model_units(rec.data, ratio), _road(rec))
                shown = ", ".join(
                    f"{k} {_fmt(v)}"
                    for k, v in scores.items()
                    if k in ("rmse", "r2", "r2_increments", "ljung_box_p")
                )
                print(f"{rec.path}: model {spec}: {shown}")

    runs: dict[int, EstimatorRun] = {}
    if args.estimator:
        for i, rec in enumerate(recordings):
            try:
                result = estimate_recording(rec, model, ratio)
            except ValueError as exc:  # e.g. sampled at another rate than the model
                print(f"hasa-replay: {rec.path}: cannot run the estimator: {exc}", file=sys.stderr)
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
            if written:
                print(f"{rec.path}: wrote {len(written)} frames to {frames_dir}")
    if problems:
        return 2
    return 1 if diverged else 0


if __name__ == "__main__":
    raise SystemExit(main())
