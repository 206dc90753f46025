"""Why the steering was or was not lane evidence: every valid step of a run in one state of
``estimators.calibration.STEERING_CHANNEL_STATES`` (docs/design.md §8.14), the per-run
columns of ``runs_estimation`` and the report's table of them."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from benchmarks.protocol.config import ProtocolConfig
from benchmarks.protocol.plan import load_frames, synthetic_plan
from benchmarks.report_sections import channel_rows, least_live_share
from estimators import FilterSettings, GaussianMixtureEKF, NoSteeringEKF
from estimators.calibration import (
    STEERING_CHANNEL_STATES,
    steering_channel_shares,
    steering_live_share,
)
from estimators.evidence import MODEL_MISMATCH
from estimators.offline import run_estimator
from hasa_env.steering.models import GeneralizedModel


@pytest.fixture(scope="module")
def frames():
    """Two 15 s runs of the paper scenario, and the second again with 0.02 rad of extra noise on
    its steering readings from 5 s on (gated, then the mismatch test)."""
    config = ProtocolConfig(seeds=(5132,), drivers=2, runs=1, ill_runs=1, duration=15.0,
                            curved_runs=0)  # fmt: skip
    plan = synthetic_plan(config, 5132)
    runs = load_frames(plan.main, "straight", plan.env_config, plan.params)
    noisy = runs[1].copy()
    noise = np.random.default_rng(5132).standard_normal(len(noisy)) * 0.02
    noise[:500] = 0.0
    noisy["sensor_steering"] = noisy["sensor_steering"] + noise
    return [runs[0], runs[1], noisy]


def _old_live_share(result, max_scale: float = 2.0) -> np.ndarray:
    """The live share as it was defined before the states (its docstring's rule)."""
    scale = np.where(np.isnan(result.evidence_scale), np.inf, result.evidence_scale)
    live = result.valid & np.isfinite(result.channel_nis[..., 2]) & (scale <= max_scale)
    live &= result.decision != MODEL_MISMATCH
    return live.sum(axis=1) / np.maximum(result.lengths, 1)


def test_every_valid_step_is_in_one_state_and_live_is_unchanged(frames):
    settings = FilterSettings.from_env_config(
        frames[0].attrs["config"], steering_ratio=15.0, steering_max_speed=15.1
    )
    result = run_estimator(GaussianMixtureEKF(GeneralizedModel.paper().arx(), settings), frames)
    shares = steering_channel_shares(result)
    assert tuple(shares) == STEERING_CHANNEL_STATES
    total = sum(shares.values())
    np.testing.assert_allclose(total, result.valid.sum(axis=1) / result.lengths, rtol=1e-12)
    np.testing.assert_array_equal(shares["live"], _old_live_share(result))
    np.testing.assert_array_equal(steering_live_share(result), shares["live"])
    # the speed rule (off above 15.1 m/s) and the misfit readings each show where they act
    off = result.low_speed & result.valid
    np.testing.assert_allclose(shares["off"], off.sum(axis=1) / result.lengths, rtol=1e-12)
    assert shares["off"].max() > 0
    refused = shares["unused"] + shares["mismatch"]
    assert refused[2] > 0.5 and refused[1] < 0.1  # the noisy copy against its clean run
    without = run_estimator(NoSteeringEKF(settings), frames)
    none = steering_channel_shares(without)  # no steering model: never used
    assert np.all(none["live"] == 0) and np.all(none["mismatch"] == 0)
    np.testing.assert_allclose(none["unused"] + none["off"], total, rtol=1e-12)


def test_the_report_table_averages_the_main_tracks_runs_of_each_steering_estimator() -> None:
    rows = [
        {"model": "generalized", "track": "straight", "steering_live_share": 0.5,
         "steering_off_share": 0.0, "steering_unused_share": 0.1, "steering_mismatch_share": 0.0,
         "steering_tempered_model_error_share": 0.1,
         "steering_tempered_autocorrelation_share": 0.3},
        {"model": "generalized", "track": "straight", "steering_live_share": 0.7,
         "steering_off_share": 0.0, "steering_unused_share": 0.1, "steering_mismatch_share": 0.0,
         "steering_tempered_model_error_share": 0.1,
         "steering_tempered_autocorrelation_share": 0.1},
        {"model": "generalized", "track": "curved", "steering_live_share": 0.0,
         "steering_off_share": 1.0, "steering_unused_share": 0.0, "steering_mismatch_share": 0.0,
         "steering_tempered_model_error_share": 0.0,
         "steering_tempered_autocorrelation_share": 0.0},
        {"model": "lane_centring", "track": "straight", "steering_live_share": np.nan,
         "steering_off_share": 0.0, "steering_unused_share": np.nan,
         "steering_mismatch_share": np.nan, "steering_tempered_model_error_share": np.nan,
         "steering_tempered_autocorrelation_share": np.nan},
    ]  # fmt: skip
    result = SimpleNamespace(runs_estimation=rows, config={"track": "straight"})
    (row,) = channel_rows(result)
    assert row["model"] == "generalized" and row["runs"] == 2
    assert row["steering_live_share"] == pytest.approx(0.6)
    assert row["steering_tempered_autocorrelation_share"] == pytest.approx(0.2)
    assert channel_rows(SimpleNamespace(runs_estimation=[], config={})) == []


def test_channel_rows_say_how_few_drivers_hold_the_time_not_live() -> None:
    """The report's last channel column: the share of the time not live (summed over runs)
    held by the 5 drivers with the most of it (docs/design.md §8.35); NaN without drivers."""
    shares = [0.0, 0.5, 0.9, 0.95, 0.96, 0.97, 0.98]  # live, one run per driver of seed 3
    rows = [
        {"seed": 3, "driver": str(i), "model": "generalized", "track": "straight",
         "steering_live_share": live, "steering_off_share": 0.0, "steering_unused_share": 0.0,
         "steering_mismatch_share": 0.0, "steering_tempered_model_error_share": 1.0 - live,
         "steering_tempered_autocorrelation_share": 0.0}
        for i, live in enumerate(shares)
    ]  # fmt: skip
    (row,) = channel_rows(SimpleNamespace(runs_estimation=rows, config={}))
    not_live = [1.0 - live for live in shares]
    assert row["least_live_share"] == pytest.approx(sum(not_live[:5]) / sum(not_live))
    frame = pd.DataFrame(rows)
    assert least_live_share(frame, 1) == pytest.approx(1.0 / sum(not_live))
    # a recorded study's runs have no seed: they count all the same (the groupby dropped them)
    assert least_live_share(frame.assign(seed=None), 1) == pytest.approx(1.0 / sum(not_live))
    assert np.isnan(least_live_share(frame.drop(columns="driver")))
    assert np.isnan(least_live_share(frame.assign(steering_live_share=1.0)))  # nothing to hold
