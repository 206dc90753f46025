"""Lane-probability calibration (ECE, reliability bins) and the steering-live share."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimators import (
    EstimationResult,
    expected_calibration_error,
    lane_calibration_bins,
    steering_live_share,
)


def _result(weights: np.ndarray, bias: np.ndarray, **extra: np.ndarray) -> EstimationResult:
    n_runs, n_steps, n_comp = weights.shape
    return EstimationResult(
        state_names=("longitudinal_velocity", "lateral_offset", "lateral_velocity", "bias"),
        hypotheses=np.tile([0.0, -1.8][:n_comp], (n_runs, 1)),
        time=np.tile(np.arange(n_steps) * 0.01, (n_runs, 1)),
        valid=np.ones((n_runs, n_steps), dtype=bool),
        lengths=np.full(n_runs, n_steps),
        mean=np.zeros((n_runs, n_steps, 4)),
        std=np.ones((n_runs, n_steps, 4)),
        weights=weights,
        most_likely=weights.argmax(axis=2),
        truth={"bias": np.tile(bias[:, None], (1, n_steps))},
        **extra,
    )


def test_bins_count_every_step_and_hypothesis() -> None:
    # run 0: true lane 0 at 0.75 then 0.95; run 1: true lane -1.8 at 0.25 (the wrong one at 0.75)
    weights = np.array([[[0.75, 0.25], [0.95, 0.05]], [[0.75, 0.25], [0.75, 0.25]]])
    bins = lane_calibration_bins(_result(weights, np.array([0.0, -1.8])), 10)
    assert bins.shape == (2, 3, 10)
    assert bins[:, 0].sum() == 8  # 2 runs x 2 steps x 2 hypotheses
    np.testing.assert_array_equal(bins[0, 0, [0, 2, 7, 9]], [1, 1, 1, 1])
    np.testing.assert_array_equal(bins[0, 2, [0, 2, 7, 9]], [0, 0, 1, 1])  # run 0's truth
    np.testing.assert_array_equal(bins[1, 0, [2, 7]], [2, 2])
    np.testing.assert_array_equal(bins[1, 2, [2, 7]], [2, 0])  # run 1: the 0.25 lane is true
    np.testing.assert_allclose(bins[1, 1, [2, 7]], [0.5, 1.5])
    # pooled: bin 0.2-0.3: 3 pairs given 0.25, 2 true; bin 0.7-0.8: 3 given 0.75, 1 true; ...
    ece = expected_calibration_error(bins.sum(axis=0))
    expected = (abs(0.75 - 2) + abs(2.25 - 1) + abs(0.05 - 0) + abs(0.95 - 1)) / 8
    assert ece == pytest.approx(expected)


def test_calibrated_probabilities_have_a_small_ece_and_overconfident_ones_not() -> None:
    rng = np.random.default_rng(3)
    n = 4000
    p = rng.uniform(0, 1, n)
    first_true = rng.uniform(0, 1, n) < p  # the first lane is true with probability p
    weights = np.stack([p, 1 - p], axis=1)[:, None, :]  # (runs, 1 step, 2)
    bias = np.where(first_true, 0.0, -1.8)
    assert expected_calibration_error(lane_calibration_bins(_result(weights, bias)).sum(0)) < 0.03
    sure = np.where(p > 0.5, 0.999, 0.001)  # the same guesses, stated as certainties
    over = np.stack([sure, 1 - sure], axis=1)[:, None, :]
    assert expected_calibration_error(lane_calibration_bins(_result(over, bias)).sum(0)) > 0.2


def test_ece_without_data_is_nan() -> None:
    assert math.isnan(expected_calibration_error(np.zeros((3, 10))))


def test_steering_live_share_counts_used_unmismatched_weakly_tempered_steps() -> None:
    weights = np.full((1, 5, 2), 0.5)
    nis = np.ones((1, 5, 3))
    nis[0, 1, 2] = np.nan  # channel not used (off, missing or gated)
    scale = np.array([[1.0, 1.0, 3.0, 1.5, 2.0]])  # step 2 tempered below half weight
    decision = np.array([[0, 0, 0, 1, 2]], dtype=np.int8)  # step 4: model mismatch
    result = _result(
        weights,
        np.array([0.0]),
        channel_nis=nis,
        low_speed=np.zeros((1, 5), dtype=bool),
        evidence_scale=scale,
        decision=decision,
    )
    assert steering_live_share(result)[0] == pytest.approx(2 / 5)  # steps 0 and 3
    assert math.isnan(steering_live_share(_result(weights, np.array([0.0])))[0])


def test_a_tie_at_the_end_is_not_the_true_lane() -> None:
    """A run refused back to a uniform prior ends at 0.5 / 0.5: the benchmark's "true lane at
    end" (EstimationResult.picked_true_lane) does not count it, whichever index is true (it
    used to take the argmax, index 0). A lean and a decision count as before."""
    weights = np.array(
        [
            [[0.9, 0.1], [0.5, 0.5]],  # true 0, refused to the prior at the end
            [[0.1, 0.9], [0.5, 0.5]],  # true -1.8, the same
            [[0.5, 0.5], [0.6, 0.4]],  # true 0, leaning right
            [[0.5, 0.5], [0.02, 0.98]],  # true 0, decided wrong
        ]
    )
    result = _result(weights, np.array([0.0, -1.8, 0.0, 0.0]))
    np.testing.assert_array_equal(result.picked_true_lane(), [False, False, True, False])
    np.testing.assert_array_equal(result.picked_true_lane(at=0), [True, True, False, False])
