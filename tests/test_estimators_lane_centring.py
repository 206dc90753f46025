"""The steering-free lane-centring baseline (:mod:`estimators.lane_centring`).

Synthetic runs: an ARX driver keeping the lane (:func:`estimators._testing.drive_arx`),
trained on one run and scored on others with each lane hypothesis true; an "offset
driver" is the same runs with the car (truth and camera) moved sideways.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

import estimators
from estimators._testing import drive_arx
from estimators.base import LaneEstimator
from estimators.lane_centring import LaneCentringEKF, LaneCentringParams, fit_lane_centring
from estimators.offline import hypotheses_of, run_estimator
from hasa_env.steering.arx import ARXForm

PAPER = ARXForm(a=(1.47, -0.51), b=(-5.73, 17.32, -17.65, 6.12), c=(0.11,), d=(-0.02, 0.02))
RATIO = 15.0


@pytest.fixture(scope="module")
def training() -> pd.DataFrame:
    return drive_arx(PAPER, runs=1, seed=7, steering_ratio=RATIO)[0]


@pytest.fixture(scope="module")
def params(training: pd.DataFrame) -> LaneCentringParams:
    return fit_lane_centring(training)


@pytest.fixture(scope="module")
def runs() -> list[pd.DataFrame]:
    """Four 30 s runs with the nominal lane true, then four with the other one."""
    return [
        frame
        for b in (0, 1)
        for frame in drive_arx(PAPER, runs=4, seed=3, bias_index=b, steering_ratio=RATIO)
    ]


def shifted(frames: list[pd.DataFrame], offset: float) -> list[pd.DataFrame]:
    """The runs with the car ``offset`` (m) further left: a driver who keeps that offset."""
    out = []
    for frame in frames:
        moved = frame.copy()
        moved.attrs = frame.attrs
        moved["lateral_offset"] += offset
        moved["sensor_camera_lateral"] += offset
        out.append(moved)
    return out


def test_public_names():
    assert estimators.LaneCentringEKF is LaneCentringEKF
    assert estimators.fit_lane_centring is fit_lane_centring
    assert isinstance(LaneCentringEKF(fit_lane_centring_params()), LaneEstimator)


def fit_lane_centring_params() -> LaneCentringParams:
    return LaneCentringParams(0.1, 0.9, 1e-4, 1e-4, 100.0, 1e-3)


def test_fit_recovers_an_ar1_process():
    """An AR(1) sampled at 100 Hz with phi = 0.95 per 0.1 s: the fit finds phi and q."""
    rng = np.random.default_rng(0)
    dt, lag, n = 0.01, 10, 60_000
    phi, q = 0.95, 4e-4
    y = np.zeros(n)
    for k in range(lag, n):  # ten interleaved AR(1) chains, each at the 0.1 s lag
        y[k] = phi * y[k - lag] + math.sqrt(q) * rng.standard_normal()
    frame = pd.DataFrame({"time": np.arange(n) * dt, "lateral_offset": y})
    fit = fit_lane_centring(frame, decimation_time=0.1)
    assert fit.autoregression == pytest.approx(phi, abs=0.01)
    assert fit.fitted_innovation_variance == pytest.approx(q, rel=0.05)
    assert fit.samples == pytest.approx((n - lag) / lag)
    # inflated by its uncertainty: a little, with 6000 samples
    assert 1.0 < fit.innovation_variance / fit.fitted_innovation_variance < 1.1
    assert fit.stationary_variance == pytest.approx(
        fit.innovation_variance / (1 - fit.autoregression**2)
    )
    assert set(fit.to_dict()) >= {"autoregression", "innovation_variance", "stationary_std"}
    assert fit.level_variance == pytest.approx(
        np.mean(y**2) * fit.innovation_variance / fit.fitted_innovation_variance
    )
    # a list of runs fits like their union of pairs
    halves = [frame.iloc[: n // 2], frame.iloc[n // 2 :].reset_index(drop=True)]
    assert fit_lane_centring(halves, decimation_time=0.1).autoregression == pytest.approx(
        phi, abs=0.01
    )


def test_fit_refuses_what_it_cannot_fit():
    flat = pd.DataFrame({"time": np.arange(100) * 0.01, "lateral_offset": np.zeros(100)})
    with pytest.raises(ValueError, match="never varies"):
        fit_lane_centring(flat)
    with pytest.raises(ValueError, match="longer than"):
        fit_lane_centring(flat.iloc[:5])
    with pytest.raises(ValueError, match="at least one"):
        fit_lane_centring([])


def test_fit_on_a_training_run(params: LaneCentringParams):
    assert params.decimation_time == 0.5
    assert 0.0 <= params.autoregression <= 0.99
    assert 0.005 < math.sqrt(params.stationary_variance) < 0.2  # a driver near the centre


def test_a_centred_driver_decides_the_true_lane(params, runs):
    """Without any steering model, the lane-centring prior picks the true lane of every
    run, early: lateral RMSE far below the no-steering filter's 0.9 m."""
    res = run_estimator(LaneCentringEKF(params), runs)
    assert res.picked_true_lane().all()
    np.testing.assert_array_less(0.95, res.true_lane_weight()[:, -1])
    assert (res.final_decision() == "decided").all()
    assert np.all(res.lateral_rmse() < 0.1), res.lateral_rmse()
    assert not res.wrong_lane_confident(0.95).any()


@pytest.mark.parametrize("offset", [0.6, -0.6])
def test_an_offset_driver_is_not_confidently_wrong(params, runs, offset):
    """A driver who keeps 0.6 m off the lane centre (towards either side) violates the
    prior far beyond the training driver's sway: never above 0.95 on the wrong lane."""
    res = run_estimator(LaneCentringEKF(params), shifted(runs, offset))
    assert not res.wrong_lane_confident(0.95).any()
    assert np.all(1.0 - res.true_lane_weight()[:, -1] <= 0.95)
    assert (res.final_decision() == "model_mismatch").all()


def test_batch_and_single_runs_agree(params, runs):
    batch = run_estimator(LaneCentringEKF(params), runs[:2])
    one = run_estimator(LaneCentringEKF(params), runs[1])
    np.testing.assert_allclose(one.weights[0], batch.weights[1], atol=1e-9)
    np.testing.assert_allclose(one.mean[0], batch.mean[1], atol=1e-9)


def test_a_car_that_moves_onto_the_other_centre_has_its_wrong_decision_withheld(params, runs):
    """A lane shift without a shift in the markings: from 3 s the car moves, over 4 s, onto the
    centre the other hypothesis puts the lane at. The prior decides the true lane at once, then
    the other one; the reversal rule withholds the second (the run ends as a model mismatch,
    the reported weights never show it) and names it, and it counts as a wrong decision."""
    moved = []
    for frame in runs[:2] + runs[4:6]:
        hyps = np.asarray(hypotheses_of(frame), dtype=float)
        true = float(frame["bias"].iloc[0])
        other = float(hyps[~np.isclose(hyps, true)][0])
        ramp = np.clip((frame["time"].to_numpy() - 3.0) / 4.0, 0.0, 1.0)
        shift = (other - true) * (1.0 - np.cos(np.pi * ramp)) / 2.0
        out = frame.copy()
        out.attrs = frame.attrs
        out["lateral_offset"] += shift
        out["sensor_camera_lateral"] += shift
        moved.append(out)
    ekf = LaneCentringEKF(params)
    res = run_estimator(ekf, moved)
    wrong = ~res.true_lane_mask()
    assert (res.final_decision() == "model_mismatch").all()
    assert res.withheld is not None and (res.withheld >= 0).all()
    assert wrong[np.arange(4), res.withheld].all()  # each withheld decision was for the wrong lane
    np.testing.assert_array_equal(ekf.withheld_decisions, res.withheld)
    assert (res.wrong_lane_confident_share() == 0).all()  # never reported
    assert res.wrong_decision_ever().all()
    assert not run_estimator(LaneCentringEKF(params), runs[:2]).wrong_decision_ever().any()
