"""Tuning helpers: the steering channel's noise level from data.

The steering measurement's noise in the filter is dominated by the steering
model's own prediction error, so ``FilterSettings.steering_residual_std``
should be the model's one-step-ahead residual level on representative runs
(for the paper preset of the generalized model on the default synthetic
population it is 1.7e-3 to 2.8e-3 rad, hence the default 2e-3 rad).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from hasa_env.steering.arx import ARXForm
from hasa_env.steering.features import steering_features

__all__ = ["steering_residual_std", "steering_residuals"]


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
    features = steering_features(
        frame,
        near=arx.near_distance,
        far=arx.far_distance,
        decision_lag=decision_lag,
        exact=False,
        steering="applied",
    )
    delta = features["delta"].to_numpy() * steering_ratio
    predicted = arx.predict(
        delta,
        features["phi"].to_numpy(),
        features["omega"].to_numpy(),
        features["lateral_velocity"].to_numpy(),
    )
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
