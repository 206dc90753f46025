"""Sample-rate checks: recordings, envs and hasa-replay refuse a model of another rate."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

import hasa_env  # noqa: F401  (registers the env ids)
from estimators.baselines import NoSteeringEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.offline import run_estimator
from estimators.timing import check_sample_time, recording_sample_time
from estimators.wrappers import EstimatorInfoWrapper
from hasa_cli.replay import main as replay_main
from hasa_env.drivers import SyntheticDriver, population, run_driver, save_runs
from hasa_env.steering import GeneralizedModel, TwoPointModel

ENV_ID = "hasa_env/LaneKeeping-v0"
TEN = {"action_repeat": 10}
RATE_MESSAGE = (
    r"the recording is sampled every 0\.1 s \(sim_frequency 100 Hz, action_repeat 10\) "
    r"but the estimator's model belongs to Ts = 0\.01 s"
)


@pytest.fixture(scope="module")
def slow_recording() -> pd.DataFrame:
    """A 30 s run of a synthetic driver at action_repeat 10 (one row every 0.1 s)."""
    driver = SyntheticDriver(population("paper", seed=0)[1])
    return run_driver(driver, ENV_ID, runs=1, seed=0, config=TEN, options={"bias_index": 1})[0]


def paper_ekf(**kw) -> GaussianMixtureEKF:
    return GaussianMixtureEKF(GeneralizedModel.paper().arx(), steering_ratio=15.0, **kw)


def test_run_estimator_refuses_a_recording_of_another_rate(slow_recording):
    assert recording_sample_time(slow_recording) == pytest.approx((0.1, 100.0, 10))
    with pytest.raises(ValueError, match=RATE_MESSAGE + r".*action_repeat 1"):
        run_estimator(paper_ekf(), slow_recording)
    # the replay tool's old mistake: the estimator stepped at the rows' 0.1 s with a 0.01 s model
    with pytest.raises(ValueError, match=RATE_MESSAGE):
        run_estimator(paper_ekf(dt=0.1), slow_recording)
    # without a config the rows' time spacing tells
    bare = slow_recording.copy()
    bare.attrs = {}
    with pytest.raises(ValueError, match=r"sampled every 0\.1 s but .* Ts = 0\.01 s"):
        run_estimator(paper_ekf(), bare)
    # in a batch the message names the recording
    fine = run_driver(SyntheticDriver(population("paper", seed=0)[1]), ENV_ID, runs=1, seed=0)[0]
    with pytest.raises(ValueError, match=r"recording 1 is sampled every 0\.1 s"):
        run_estimator(paper_ekf(), [fine, slow_recording])


def test_a_model_of_the_recordings_rate_is_accepted(slow_recording):
    two_point = TwoPointModel.paper(dt=0.1)
    res = run_estimator(GaussianMixtureEKF(two_point.arx(), steering_ratio=15.0), slow_recording)
    assert res.mean.shape[1] == len(slow_recording) and np.all(np.isfinite(res.mean))
    with pytest.raises(ValueError, match=r"steps with dt = 0\.02 s.*dt=0\.1"):
        run_estimator(NoSteeringEKF(dt=0.02), slow_recording)
    assert run_estimator(NoSteeringEKF(dt=0.1), slow_recording).num_runs == 1


def test_check_sample_time_messages():
    ekf = paper_ekf()
    check_sample_time(ekf, 0.01)
    check_sample_time(ekf, 0.01 * (1 + 1e-9))  # the same rate up to rounding
    with pytest.raises(ValueError, match=r"the env is sampled every 0\.02 s \(sim_frequency"):
        check_sample_time(ekf, 0.02, source="the env", sim_frequency=50.0, action_repeat=1)
    with pytest.raises(ValueError, match="no positive sample time"):
        check_sample_time(ekf, 0.0)
    check_sample_time(object(), 0.5)  # an estimator without dt or model is not checked


def test_wrappers_name_the_rates_the_same_way():
    message = (
        r"the env is sampled every 0\.1 s \(sim_frequency 100 Hz, action_repeat 10\) "
        r"but the estimator's model belongs to Ts = 0\.01 s"
    )
    with pytest.raises(ValueError, match=message):
        EstimatorInfoWrapper(gym.make(ENV_ID, config=TEN), paper_ekf())
    venv = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", config=TEN)
    with pytest.raises(ValueError, match=message):
        EstimatorInfoWrapper(venv, paper_ekf())
    with pytest.raises(ValueError, match=r"sampled every 0\.02 s \(sim_frequency 50 Hz"):
        EstimatorInfoWrapper(gym.make(ENV_ID, config={"sim_frequency": 50.0}), paper_ekf())
    # the env's IMU averages over the whole env step: a model of that step is fine
    two_point = GaussianMixtureEKF(TwoPointModel.paper(dt=0.1).arx(), steering_ratio=15.0)
    env = EstimatorInfoWrapper(
        gym.make(ENV_ID, config={**TEN, "action": {"type": "physical"}}), two_point
    )
    _, info = env.reset(seed=0)
    _, *_, info = env.step(np.zeros(2))
    assert np.isfinite(info["estimate_lateral_offset"])


def test_hasa_replay_refuses_instead_of_estimating(slow_recording, tmp_path, capsys):
    save_runs([slow_recording], tmp_path)
    assert replay_main([str(tmp_path), "--estimator"]) == 1  # replayed; the estimator refused
    out, err = capsys.readouterr()
    assert "estimator:" not in out  # no estimate printed
    assert "cannot run the estimator" in err
    assert "sampled every 0.1 s (sim_frequency 100 Hz, action_repeat 10)" in err
    assert "model belongs to Ts = 0.01 s" in err
