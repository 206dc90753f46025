"""Is an estimator's output to be believed: calibration of its lane probabilities, and how
much of the time the human's steering counted as lane evidence (docs/design.md §8.14)."""

from __future__ import annotations

import math

import numpy as np

from estimators.evidence import MODEL_MISMATCH
from estimators.offline import EstimationResult

__all__ = [
    "CALIBRATION_BINS",
    "expected_calibration_error",
    "STEERING_CHANNEL_STATES",
    "lane_calibration_bins",
    "steering_channel_shares",
    "steering_live_share",
]

STEERING_CHANNEL_STATES = (
    "live",
    "off",
    "unused",
    "mismatch",
    "tempered_model_error",
    "tempered_autocorrelation",
)
"""What the steering channel was at a valid step, one state each, in the order they are
checked (:func:`steering_channel_shares`)."""

CALIBRATION_BINS = 10
"""Bins of equal width on [0, 1] of the reliability diagram and the ECE."""


def lane_calibration_bins(result: EstimationResult, n_bins: int = CALIBRATION_BINS) -> np.ndarray:
    """(R, 3, n_bins) what a reliability diagram of the lane probabilities needs, per run:
    every (valid step, hypothesis) pair's weight ``w`` goes into the bin
    ``min(floor(w n_bins), n_bins - 1)`` of equal width on [0, 1]; per bin the number of
    pairs, the sum of their weights (predicted) and the number whose hypothesis is the true
    lane (observed). Summed over runs, :func:`expected_calibration_error` reads it."""
    truth = np.broadcast_to(result.true_lane_mask()[:, None, :], result.weights.shape)
    w = np.clip(result.weights, 0.0, 1.0)
    index = np.minimum((w * n_bins).astype(np.int64), n_bins - 1)
    keep = np.broadcast_to(result.valid[:, :, None], w.shape) & np.isfinite(result.weights)
    out = np.zeros((result.num_runs, 3, n_bins))
    flat = (np.arange(result.num_runs)[:, None, None] * n_bins + index)[keep]
    size = result.num_runs * n_bins
    out[:, 0] = np.bincount(flat, minlength=size).reshape(result.num_runs, n_bins)
    out[:, 1] = np.bincount(flat, weights=w[keep], minlength=size).reshape(-1, n_bins)
    out[:, 2] = np.bincount(flat, weights=truth[keep], minlength=size).reshape(-1, n_bins)
    return out


def expected_calibration_error(bins: np.ndarray) -> float:
    """Expected calibration error of lane probabilities from summed reliability bins (3, B)
    (:func:`lane_calibration_bins` summed over runs)::

        ECE = sum_b (n_b / N) |predicted_b / n_b - observed_b / n_b|
            = sum_b |predicted_b - observed_b| / N

    NaN without any pair. 0: the probabilities mean what they say (of the pairs given
    probability p, a share p was the true lane)."""
    bins = np.asarray(bins, dtype=np.float64)
    total = bins[0].sum()
    if total <= 0:
        return math.nan
    return float(np.abs(bins[1] - bins[2]).sum() / total)


def steering_live_share(result: EstimationResult, max_scale: float = 2.0) -> np.ndarray:
    """(R,) share of each run's valid steps at which the steering channel counted as lane
    evidence at no less than ``1 / max_scale`` of its weight: the channel was used (on,
    observed, not gated: a finite steering NIS), the run was not in ``model_mismatch``
    and the evidence scale tau was at most ``max_scale`` (NaN for an estimator that
    reports no steering channel). The ``live`` share of :func:`steering_channel_shares`."""
    return steering_channel_shares(result, max_scale)["live"]


def steering_channel_shares(
    result: EstimationResult, max_scale: float = 2.0, *, refused: bool = False
) -> dict[str, np.ndarray]:
    """Why the steering was or was not lane evidence: per state of
    :data:`STEERING_CHANNEL_STATES`, the (R,) share of each run's steps (of its length; the
    states of a run's valid steps sum to its valid share) at which the channel was, checked in
    this order (docs/design.md §8.14):

    - ``off``: switched off by the speed or curvature rule (``low_speed``);
    - ``unused``: on, but no steering entered the update (missing or gated: no finite NIS);
    - ``mismatch``: used, the run in ``model_mismatch`` (its weights frozen);
    - ``tempered_model_error``: the evidence scale tau above ``max_scale`` with the model-error
      ratio max(1, lambda) alone above it (the model mispredicts here);
    - ``tempered_autocorrelation``: tau above ``max_scale`` otherwise (the innovations'
      autocorrelation, alone or with lambda);
    - ``live``: the rest, counted at ``1 / max_scale`` of its weight or more.

    ``refused``: the result is a steering model's that the trust rule gave no lane evidence
    at all (:func:`estimators.trust.trusted_filter` without an ARX form: it failed the
    lane-keeping or the prediction check, or has none), filtered by the no-steering
    estimator; its channel is ``off`` at every valid step, not ``unused``.

    Every state is NaN for an estimator that reports no steering channel."""
    if result.channel_nis is None or result.low_speed is None:
        return {name: np.full(result.num_runs, np.nan) for name in STEERING_CHANNEL_STATES}
    valid = result.valid
    scale = np.ones_like(valid, dtype=np.float64)
    if result.evidence_scale is not None:
        scale = np.where(np.isnan(result.evidence_scale), np.inf, result.evidence_scale)
    error = np.ones_like(scale)
    if result.model_error is not None:
        error = np.maximum(1.0, np.nan_to_num(result.model_error, nan=1.0))
    off = valid.copy() if refused else valid & result.low_speed
    used = valid & ~off & np.isfinite(result.channel_nis[..., 2])
    mismatch = np.zeros_like(valid)
    if result.decision is not None:
        mismatch = used & (result.decision == MODEL_MISMATCH)
    counted = used & ~mismatch
    tempered = counted & (scale > max_scale)
    states = {
        "live": counted & ~tempered,
        "off": off,
        "unused": valid & ~off & ~used,
        "mismatch": mismatch,
        "tempered_model_error": tempered & (error > max_scale),
        "tempered_autocorrelation": tempered & ~(error > max_scale),
    }
    length = np.maximum(result.lengths, 1)
    return {name: states[name].sum(axis=1) / length for name in STEERING_CHANNEL_STATES}
