"""Tuning helpers: the steering channel's noise level from data.

The steering measurement's noise in the filter is dominated by the steering
model's own prediction error, so ``FilterSettings.steering_residual_std``
should be the model's one-step-ahead residual level on representative runs
(for the paper preset of the generalized model on the default synthetic
population it is 1.7e-3 to 2.8e-3 rad, hence the default 2e-3 rad).

:func:`prediction_check` asks whether the model describes the driver at all
(:mod:`estimators.trust`, docs/design.md §8.13.1): its one-step residual level on the recorded
steering against that of the best predictor of the steering from its own past alone (an
autoregression of the model's own order, least squares, cross-validated over contiguous
blocks), on the same recordings. A model that predicts the steering no better than that has
learned nothing of the lane that holds on these data.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from hasa_env.steering.arx import ARXForm
from hasa_env.steering.equation_error import (
    SpeedScaledError,
    check_equation_error_ar,
    speed_scaled_error,
    speed_scaled_log_likelihood,
    whitened_arx,
)
from hasa_env.steering.features import steering_features

__all__ = [
    "LANE_FREE_FOLDS",
    "PredictionCheck",
    "prediction_check",
    "steering_residual_std",
    "steering_residuals",
    "steering_residuals_by_speed",
    "held_out_speed_scaled_error",
    "residuals_and_speeds",
    "speed_scaled_equation_error",
    "speed_scaled_gain",
    "whitened_residual_std",
]

SPEED_BIN_WIDTH = 5.0
"""Width (m/s) of :func:`steering_residuals_by_speed`'s speed bins."""

SPEED_BIN_MIN_SAMPLES = 200
"""Fewest residuals a speed bin of :func:`steering_residuals_by_speed` reports (2 s at 100 Hz)."""

LANE_FREE_FOLDS = 5
"""Contiguous blocks of :func:`prediction_check`'s cross-validation."""


def steering_residuals(
    arx: ARXForm,
    frame: pd.DataFrame,
    *,
    decision_lag: int = 1,
    steering_ratio: float = 1.0,
) -> np.ndarray:
    """One-step-ahead residuals ``ratio * delta(k) - delta_hat(k)`` (rad, model units) of one run.

    Uses the recorded applied steering (the filter's model: the equation
    error e(k) is on the applied steering, and the steering sensor's noise is
    a separate term of R_33) and the straight-road bearings of the true state,
    as the filter's model does (:mod:`estimators.arx_state_space`); rows
    without a full history are dropped.
    """
    delta, predicted = _predicted(arx, frame, decision_lag, steering_ratio, "applied")
    residual = delta - predicted
    return residual[np.isfinite(residual)]


def steering_residual_std(
    arx: ARXForm,
    frames: pd.DataFrame | Sequence[pd.DataFrame],
    *,
    decision_lag: int = 1,
    steering_ratio: float = 1.0,
) -> float:
    """Root-mean-square one-step-ahead residual of ``arx`` on recordings (rad, model units).

    Pass it as ``FilterSettings(steering_residual_std=...)``.
    """
    if isinstance(frames, pd.DataFrame):
        frames = [frames]
    residuals = [
        steering_residuals(arx, f, decision_lag=decision_lag, steering_ratio=steering_ratio)
        for f in frames
    ]
    values = np.concatenate(residuals) if residuals else np.zeros(0)
    if values.size == 0:
        raise ValueError("no residuals: the recordings are shorter than the model's memory")
    return float(np.sqrt(np.mean(values * values)))


def steering_residuals_by_speed(
    arx: ARXForm,
    frames: pd.DataFrame | Sequence[pd.DataFrame],
    *,
    decision_lag: int = 1,
    steering_ratio: float = 1.0,
    bin_width: float = SPEED_BIN_WIDTH,
    min_samples: int = SPEED_BIN_MIN_SAMPLES,
) -> list[dict[str, float | int]]:
    """The one-step residuals of :func:`steering_residuals` by the car's speed (the runs'
    ``speed`` column, m/s) in bins ``[k w, (k + 1) w)`` of width ``w`` = ``bin_width``: per bin
    with at least ``min_samples`` residuals, ``speed_low`` and ``speed_high`` (m/s),
    ``samples``, ``residual_rms`` (rad, model units; the filter's one level is the RMS over
    every bin) and ``lag1_autocorrelation``, ``sum e(k) e(k-1) / sum e(k)^2`` over the pairs
    of consecutive samples of one run that are both in the bin (NaN without any). Whether a
    model's error changes with speed, which one level and one equation-error autoregression
    cannot follow (docs/design.md §8.33)."""
    if not (math.isfinite(bin_width) and bin_width > 0):
        raise ValueError(f"bin_width must be a finite number > 0 m/s, got {bin_width!r}")
    if isinstance(frames, pd.DataFrame):
        frames = [frames]
    parts = []
    for run, frame in enumerate(frames):
        if "speed" not in frame:
            raise ValueError(f"run {run} has no 'speed' column")
        delta, predicted = _predicted(arx, frame, decision_lag, steering_ratio, "applied")
        residual = delta - predicted
        speed_bin = np.floor(frame["speed"].to_numpy(dtype=np.float64) / bin_width)
        previous = np.concatenate([[np.nan], residual[:-1]])
        same_bin = np.concatenate([[False], speed_bin[1:] == speed_bin[:-1]])
        product = np.where(same_bin, residual * previous, np.nan)  # NaN: no pair
        square = residual * residual
        parts.append(
            pd.DataFrame(
                {
                    "bin": speed_bin,
                    "square": square,
                    "product": product,
                    "pair_square": np.where(np.isfinite(product), square, np.nan),
                }
            )
        )
    if not parts:
        return []
    table = pd.concat(parts, ignore_index=True)
    table = table[np.isfinite(table["square"]) & np.isfinite(table["bin"])]
    rows: list[dict[str, float | int]] = []
    if table.empty:
        return rows
    grouped = table.groupby("bin").agg(
        samples=("square", "size"),
        mean_square=("square", "mean"),
        products=("product", "sum"),
        pair_squares=("pair_square", "sum"),
    )
    lows = grouped.index.to_numpy(dtype=np.float64) * bin_width
    for low, row in zip(lows.tolist(), grouped.itertuples(index=False), strict=True):
        if row.samples < min_samples:
            continue
        rows.append(
            {
                "speed_low": low,
                "speed_high": low + bin_width,
                "samples": int(row.samples),
                "residual_rms": math.sqrt(float(row.mean_square)),
                "lag1_autocorrelation": float(row.products / row.pair_squares)
                if row.pair_squares > 0
                else math.nan,
            }
        )
    return rows


def whitened_residual_std(
    model: Any,
    frames: pd.DataFrame | Sequence[pd.DataFrame],
    *,
    steering_ratio: float = 1.0,
) -> float | None:
    """:func:`steering_residual_std` of the model's ARX form whitened by its declared
    equation-error autoregression (``model.equation_error_ar``,
    :func:`hasa_env.steering.equation_error.whitened_arx`): what the trust rule compares with
    the model's own level before it believes the declaration (docs/design.md §8.32). None: the
    model has no ARX form or declares no autoregression.

    Raises:
        ValueError: the declaration is not a stationary autoregression
            (:func:`hasa_env.steering.equation_error.check_equation_error_ar`).
    """
    arx = model.arx() if model is not None else None
    noise = check_equation_error_ar(getattr(model, "equation_error_ar", ()) or ())
    if arx is None or not noise:
        return None
    return steering_residual_std(
        whitened_arx(arx, noise),
        frames,
        decision_lag=int(getattr(model, "decision_lag", 1)),
        steering_ratio=steering_ratio,
    )


def residuals_and_speeds(
    model: Any, frames: pd.DataFrame | Sequence[pd.DataFrame], steering_ratio: float
) -> tuple[list[np.ndarray], list[np.ndarray]] | None:
    """The model's one-step residuals (rad, model units; ``steering_ratio`` times the applied
    steering less the model's prediction from the true states) and the speeds (m/s) per run;
    None without an ARX form or a ``speed`` column."""
    arx = model.arx() if model is not None else None
    runs = [frames] if isinstance(frames, pd.DataFrame) else list(frames)
    if arx is None or not runs or any("speed" not in run for run in runs):
        return None
    lag = int(getattr(model, "decision_lag", 1))
    residuals = []
    for run in runs:
        delta, predicted = _predicted(arx, run, lag, steering_ratio, "applied")
        residuals.append(delta - predicted)
    return residuals, [run["speed"].to_numpy(dtype=np.float64) for run in runs]


def speed_scaled_equation_error(
    model: Any,
    frames: pd.DataFrame | Sequence[pd.DataFrame],
    *,
    steering_ratio: float = 1.0,
) -> SpeedScaledError | None:
    """The :class:`~hasa_env.steering.equation_error.SpeedScaledError` of the model's one-step
    residuals on ``frames`` (the runs' ``speed`` column; maximum likelihood,
    :func:`hasa_env.steering.equation_error.speed_scaled_error`; docs/design.md §8.34). None:
    no ARX form, no ``speed`` column, too few residuals, or no convergence."""
    found = residuals_and_speeds(model, frames, steering_ratio)
    return None if found is None else speed_scaled_error(*found)


def held_out_speed_scaled_error(
    fitted: Any,
    runs: Sequence[pd.DataFrame],
    refit: Callable[[list[pd.DataFrame]], Any],
) -> tuple[SpeedScaledError | None, bool]:
    """The speed-scaled equation error of a model fitted on ``runs`` (docs/design.md §8.34),
    estimated on held-out residuals: each run's residuals from ``refit(the other runs)`` (the
    model's own fit), so that its levels are those of a driver the fit has not seen, not its
    in-sample ones. With one run: ``fitted``'s in-sample residuals on it. Returns the error
    (None: none found) and whether it was held out."""
    runs = list(runs)
    if len(runs) < 2:
        return speed_scaled_equation_error(fitted, runs), False
    residuals: list[np.ndarray] = []
    speeds: list[np.ndarray] = []
    for j, run in enumerate(runs):
        found = residuals_and_speeds(refit(runs[:j] + runs[j + 1 :]), run, 1.0)
        if found is None:
            return None, True
        residuals += found[0]
        speeds += found[1]
    return speed_scaled_error(residuals, speeds), True


def speed_scaled_gain(
    model: Any,
    frames: pd.DataFrame | Sequence[pd.DataFrame],
    *,
    steering_ratio: float = 1.0,
) -> float | None:
    """How much better the model's declared speed-scaled equation error
    (``model.equation_error_speed_scaled``) describes its one-step residuals on ``frames``
    than one white level does: the Gaussian log-likelihood per residual under the declaration
    less that under N(0, RMS^2) of the same residuals (nats per sample). What the trust rule
    reads before it believes the declaration (docs/design.md §8.34). None: no declaration, no
    ARX form, no ``speed`` column or no residuals."""
    declared = getattr(model, "equation_error_speed_scaled", None)
    found = None if declared is None else residuals_and_speeds(model, frames, steering_ratio)
    if declared is None or found is None:
        return None
    log_likelihood, count = speed_scaled_log_likelihood(declared, *found)
    if not count:
        return None
    values = np.concatenate(
        [e[np.isfinite(e) & np.isfinite(v)] for e, v in zip(*found, strict=True)]
    )  # the residuals scored above
    variance = float(np.mean(values * values))
    white = -0.5 * count * (math.log(2.0 * math.pi * variance) + 1.0)
    return (log_likelihood - white) / count


@dataclass(frozen=True)
class PredictionCheck:
    """Does a steering model predict the recorded steering better than its own past does?

    Attributes:
        residual_std: the model's RMS one-step residual on the steering sensor's readings
            (rad, model units).
        lane_free_residual_std: on the same readings and rows, the cross-validated RMS
            one-step residual of a lane-free autoregression of the model's order (rad,
            model units; :func:`prediction_check`).
    """

    residual_std: float
    lane_free_residual_std: float

    @property
    def passed(self) -> bool:
        """True when the model's residual is below the lane-free one."""
        return self.residual_std < self.lane_free_residual_std

    def describe(self) -> str:
        """The two levels in one phrase."""
        return (
            f"one-step residual {self.residual_std:.3g} rad, a lane-free autoregression of "
            f"its order {self.lane_free_residual_std:.3g} rad on the same data"
        )


def prediction_check(
    arx: ARXForm,
    frames: pd.DataFrame | Sequence[pd.DataFrame],
    *,
    decision_lag: int = 1,
    steering_ratio: float = 1.0,
    folds: int = LANE_FREE_FOLDS,
) -> PredictionCheck:
    """The model's one-step residual level on the recorded steering, and that of the steering
    predicted from its own past alone.

    Both read the steering sensor (``sensor_steering``, else ``steering``: what a predictor,
    and the filter, see; a fit on noisy readings is not compared with a predictor of the
    noise-free steering) times ``steering_ratio``. The lane-free predictor has the model's
    autoregressive order n = ``len(arx.a)`` and no lane input::

        delta(k) = sum_{j=1}^{n} alpha_j delta(k - j) + e(k)      (n = 0: delta_hat = 0)

    Its rows are the model's (those with the model's full history; lags never cross from one
    recording to the next), cut into ``folds`` contiguous blocks: each block is predicted
    by alpha fitted by least squares on the others, and the level is the RMS of those
    held-out residuals. Holding the autoregression out while the model is scored in-sample
    (where it was fitted on these recordings) favours the model: a fitted model that fails
    is not a close call.

    Raises:
        ValueError: fewer rows than ``folds`` (recordings shorter than the model's memory).
    """
    if isinstance(frames, pd.DataFrame):
        frames = [frames]
    order = len(arx.a)
    targets, lagged, residuals = [], [], []
    for frame in frames:
        delta, predicted = _predicted(arx, frame, decision_lag, steering_ratio, "measured")
        rows = np.flatnonzero(np.isfinite(delta - predicted))
        lags = np.empty((rows.size, order))
        for j in range(1, order + 1):
            lags[:, j - 1] = delta[rows - j]
        keep = np.all(np.isfinite(lags), axis=1)
        rows = rows[keep]
        residuals.append(delta[rows] - predicted[rows])
        targets.append(delta[rows])
        lagged.append(lags[keep])
    target = np.concatenate(targets)
    design = np.concatenate(lagged)
    if target.size < max(folds, 2 * order + 1):
        raise ValueError("no residuals: the recordings are shorter than the model's memory")
    errors = []
    for block in np.array_split(np.arange(target.size), folds):
        train = np.ones(target.size, dtype=bool)
        train[block] = False
        alpha = (
            np.linalg.lstsq(design[train], target[train], rcond=None)[0] if order else np.zeros(0)
        )
        errors.append(target[block] - design[block] @ alpha)
    model, lane_free = np.concatenate(residuals), np.concatenate(errors)
    return PredictionCheck(
        float(np.sqrt(np.mean(model * model))), float(np.sqrt(np.mean(lane_free * lane_free)))
    )


def _predicted(
    arx: ARXForm, frame: pd.DataFrame, decision_lag: int, steering_ratio: float, steering: str
) -> tuple[np.ndarray, np.ndarray]:
    """(``ratio * delta``, the model's one-step prediction of it) over one run's rows (NaN
    where the history is short), from the features the filter's model reads: straight-road
    bearings of the true state and the ``steering`` ("applied" or "measured") of
    :func:`steering_features`."""
    features = steering_features(
        frame,
        near=arx.near_distance,
        far=arx.far_distance,
        decision_lag=decision_lag,
        exact=False,
        steering=steering,
    )
    delta = features["delta"].to_numpy() * steering_ratio
    predicted = arx.predict(
        delta,
        features["phi"].to_numpy(),
        features["omega"].to_numpy(),
        features["lateral_velocity"].to_numpy(),
    )
    return delta, predicted
