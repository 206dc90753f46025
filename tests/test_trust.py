"""One rule turns a steering model into a trusted filter (estimators.trust), for every caller."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

from estimators.baselines import NoSteeringEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.settings import STRAIGHT_CURVATURE, FilterSettings
from estimators.trust import TrainingRecord, trusted_filter
from hasa_env.steering import GeneralizedModel

SPEEDS = (15.2, 16.1)
"""The training speeds (m/s) given to the test model: limits 14.2 and 17.1 m/s."""


def _model() -> GeneralizedModel:
    model = GeneralizedModel.paper()  # fitted on a straight road (its own record)
    model.training_speed_range = SPEEDS
    return model


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A 0.5 s recording of the default env driven by the test model itself (plus 1e-3 rad of
    equation noise): a driver it describes (its config: the default sensor noise)."""
    from hasa_env.drivers import ModelDriver, run_driver
    from hasa_env.drivers.runner import recording_meta
    from hasa_env.recording import load_recording, save_recording

    frame = run_driver(
        ModelDriver(_model(), noise_std=1e-3), runs=1, seed=3, config={"time_limit": 0.5}
    )[0]
    path = save_recording(frame, tmp_path_factory.mktemp("rec") / "run", recording_meta(frame))
    return load_recording(path)


@pytest.fixture(scope="module")
def still_recording(tmp_path_factory):
    """A 50-step recording of the default env with the steering held at zero."""
    from hasa_env.recording import RecordingWrapper, load_recording

    directory = tmp_path_factory.mktemp("still")
    env = RecordingWrapper(
        gym.make("hasa_env/LaneKeeping-v0", config={"time_limit": 0.5}), directory
    )
    env.reset(seed=3)
    for _ in range(50):
        env.step(np.zeros(2, dtype=np.float32))
    env.close()
    return load_recording(env.path)


def _captured_runs(monkeypatch) -> list:
    """Patch the offline runner to keep every estimator it is given."""
    import estimators.offline as offline

    seen: list = []
    original = offline.run_estimator

    def run(estimator, *args, **kwargs):
        seen.append(estimator)
        return original(estimator, *args, **kwargs)

    monkeypatch.setattr(offline, "run_estimator", run)
    return seen


@pytest.mark.parametrize("equation_error", [(), (0.3, 0.2)], ids=["white", "ar2"])
def test_six_callers_get_the_same_filter_for_the_same_model(
    tmp_path, recording, monkeypatch, equation_error
):
    from advisor_tasks.config import estimator_factory, split_config
    from benchmarks.protocol.models import FittedModel
    from benchmarks.protocol.tasks import model_estimator
    from benchmarks.recordings import estimate_recordings, prepare_model
    from estimators.offline import estimate_recording
    from estimators.wrappers import estimator_wrapper
    from hasa_cli.inputs import estimator_for
    from hasa_env.envs.lane_keeping import LaneKeepingEnv

    model = _model()
    model.equation_error_ar = equation_error  # saved in the model file, read back
    path = tmp_path / "model.json"
    model.save(path)
    env = LaneKeepingEnv()
    level = FilterSettings.steering_residual_std  # what a caller without data uses
    seen = _captured_runs(monkeypatch)
    estimate_recording(recording, model, residual_std=level)
    estimate_recordings(prepare_model(str(path), [recording]), [recording])
    _, own = split_config(
        {"estimator": {"steering_model": str(path), "lane_check": False, "outlier_gate": True}}
    )
    lines: list[str] = []
    filters = {
        "estimators.wrappers": estimator_wrapper(model)(env).estimator,
        "hasa-drive": estimator_for(str(path), env, lane_check=False, log=lines.append)(
            env
        ).estimator,
        "advisor task": estimator_factory(own, env.unwrapped.config)(),
        "estimators.offline": seen[0],
        "hasa-replay": seen[1],
        "hasa-bench": model_estimator(
            FittedModel("m", "user", model, level, TrainingRecord(keeps_lane=True)),
            FilterSettings.from_env_config(recording.config),
        ),
    }
    expected = trusted_filter(
        model,
        FilterSettings.from_env_config(env.unwrapped.config),
        training=TrainingRecord(residual_std=level),
    )
    assert (expected.arx == model.arx()) is not bool(equation_error)
    assert expected.settings.steering_max_speed == pytest.approx(SPEEDS[1] + 1.0)
    assert expected.settings.min_speed == pytest.approx(SPEEDS[0] - 1.0)
    assert expected.settings.steering_curvature_limit == STRAIGHT_CURVATURE
    # hasa-replay measures the residual level on the recording itself: all else is the same
    replay_level = filters["hasa-replay"].settings.steering_residual_std
    assert 0 < replay_level != level
    for caller, ekf in filters.items():
        assert type(ekf) is GaussianMixtureEKF, caller
        settings = ekf.settings
        if caller == "hasa-replay":
            settings = dataclasses.replace(
                settings, steering_residual_std=expected.settings.steering_residual_std
            )
        assert settings == expected.settings, caller
        assert ekf.decision_lag == model.decision_lag, caller
        own_form = caller == "hasa-replay" and equation_error
        # hasa-replay measures both levels on the recording, whose residuals are white (the
        # model drives it): a declared autoregression predicts worse there, and is ignored
        assert ekf.steering_model == (model.arx() if own_form else expected.arx), caller
    assert lines == [f"hasa-drive: --estimator {path}: {expected.describe()}"]


def test_a_model_no_better_than_the_steerings_own_past_gives_no_lane_evidence(
    recording, still_recording
) -> None:
    from estimators.offline import recording_filter
    from estimators.tuning import PredictionCheck, prediction_check

    model = _model()
    arx = model.arx()
    # a driver the model describes: its residual is below the lane-free level
    check = prediction_check(arx, recording.data)
    assert check.passed and check.residual_std < 0.9 * check.lane_free_residual_std
    assert trusted_filter(model, training=TrainingRecord(prediction=check)).arx == arx
    # nobody steers: the lane-free autoregression predicts the (sensor's) readings far better
    still = prediction_check(arx, still_recording.data)
    assert not still.passed and still.residual_std > 10 * still.lane_free_residual_std
    refused = trusted_filter(model, training=TrainingRecord(prediction=still))
    assert refused.arx is None and isinstance(refused.estimator(), NoSteeringEKF)
    assert refused.reasons == (
        "steering off: the model predicts the steering no better than its own past does "
        f"({still.describe()})",
    )
    assert still.describe() == (
        f"one-step residual {still.residual_std:.3g} rad, a lane-free autoregression of its "
        f"order {still.lane_free_residual_std:.3g} rad on the same data"
    )
    # the rule is a check: the unchecked filter and an unchecked record keep the steering
    record = TrainingRecord(residual_std=2e-3, prediction=PredictionCheck(2e-3, 1e-3))
    assert trusted_filter(model, training=record).arx is None
    assert trusted_filter(model, training=record, checks=False).arx == arx
    assert trusted_filter(model, training=TrainingRecord(residual_std=2e-3)).arx == arx
    better = dataclasses.replace(record, prediction=PredictionCheck(9e-4, 1e-3))
    assert trusted_filter(model, training=better).arx == arx
    # a recording of someone else is not the model's training data: no check there
    assert recording_filter(still_recording, model).arx == arx
    assert recording_filter(still_recording, model, training=record).arx is None


def _ar2_frame(n: int, sensor_std: float = 0.0) -> pd.DataFrame:
    """A run whose applied steering is an AR(2) process with 1e-3 rad innovations, read by a
    steering sensor with ``sensor_std`` rad of white noise; the car holds the lane centre."""
    rng = np.random.default_rng(7)
    delta = np.zeros(n)
    noise = 1e-3 * rng.standard_normal(n)
    for k in range(2, n):
        delta[k] = 1.6 * delta[k - 1] - 0.64 * delta[k - 2] + noise[k]
    return pd.DataFrame(
        {
            "steering": delta,
            "sensor_steering": delta + sensor_std * rng.standard_normal(n),
            "lateral_offset": np.zeros(n),
            "heading": np.zeros(n),
            "speed": np.full(n, 15.0),
            "time": 0.01 * np.arange(n),
        }
    )


def test_the_lane_free_level_is_a_held_out_autoregression_of_the_models_order() -> None:
    from estimators.tuning import prediction_check
    from hasa_env.steering.arx import ARXForm

    frame = _ar2_frame(4000)
    exact = ARXForm(a=(1.6, -0.64), b=(0.0,))  # the process itself: its residual is the noise
    check = prediction_check(exact, frame, decision_lag=0)
    assert check.residual_std == pytest.approx(1e-3, rel=0.05)
    # no lane input: the lane-free autoregression, fitted on 4/5 of the run, is as good
    assert check.lane_free_residual_std == pytest.approx(check.residual_std, rel=0.01)
    # order 0 predicts zero: the level is the steering's own RMS
    delta = frame["steering"].to_numpy()
    none = prediction_check(ARXForm(a=(), b=(0.0,)), frame, decision_lag=0)
    assert none.lane_free_residual_std == pytest.approx(float(np.sqrt(np.mean(delta**2))))
    # two runs (lags never cross from one to the next); shorter than the memory: an error
    both = prediction_check(exact, [frame, frame], decision_lag=0)
    assert both.lane_free_residual_std == pytest.approx(check.lane_free_residual_std, rel=0.05)
    with pytest.raises(ValueError, match="shorter than the model's memory"):
        prediction_check(exact, frame.iloc[:3], decision_lag=0)


def test_the_check_reads_the_steering_sensor_as_the_fit_and_the_filter_do() -> None:
    from estimators.tuning import prediction_check
    from hasa_env.steering.arx import ARXForm

    exact = ARXForm(a=(1.6, -0.64), b=(0.0,))
    clean = prediction_check(exact, _ar2_frame(4000), decision_lag=0)
    noisy = prediction_check(exact, _ar2_frame(4000, sensor_std=1e-3), decision_lag=0)
    # both predictors see the noisy readings: both levels rise, not only the model's
    assert noisy.residual_std > 1.5 * clean.residual_std
    assert noisy.lane_free_residual_std > 1.5 * clean.lane_free_residual_std


def test_the_reasons_say_what_is_off_and_why() -> None:
    trusted = trusted_filter(_model())
    speeds = "outside the training speeds 15.2-16.1 m/s +- 1"
    assert trusted.reasons == (
        "steering off where the road ahead curves more than 0.0002 1/m: beyond the roads it "
        "was fitted on (|curvature| up to 0 1/m)",
        "no curvature feed-forward (G = -29.4): the covariance of its parameters is unknown (a "
        "preset, or a model file saved without one), so whether its fit pins G down is unknown",
        f"steering off below 14.2 m/s: {speeds}",
        f"steering off above 17.1 m/s: {speeds}",
    )
    assert trusted.describe() == "; ".join(trusted.reasons)
    model = GeneralizedModel.paper()
    model.training_curvature = None  # a model that does not say where it was fitted
    unknown = trusted_filter(model)
    assert unknown.reasons == () and unknown.settings == FilterSettings()
    assert unknown.describe() == "the steering counts at every speed and on every road"


def test_the_user_overrides_win_field_by_field() -> None:
    trusted = trusted_filter(
        _model(),
        training=TrainingRecord(residual_std=1e-4),
        overrides={"steering_max_speed": 30.0, "steering_residual_std": 3e-3},
    )
    assert trusted.settings.steering_max_speed == 30.0
    assert trusted.settings.min_speed == pytest.approx(14.2)  # still the rule's
    assert trusted.settings.steering_residual_std == 3e-3
    assert (
        trusted.reasons[-1] == "steering off above 30.0 m/s: set by the user (steering_max_speed)"
    )
    assert (
        trusted_filter(
            _model(), training=TrainingRecord(residual_std=0.0)
        ).settings.steering_residual_std
        == 1e-9
    )
    with pytest.raises(ValueError, match="steering_max_speed"):
        trusted_filter(_model(), overrides={"steering_max_speed": -1.0})


def test_hasa_benchs_filter_honours_the_users_evidence_checks() -> None:
    # `hasa-bench --filter evidence_checks=false` reached the trust rule as an override that
    # the benchmark's checks=True then overruled: the "unchecked" run was the checked one
    from benchmarks.protocol.models import FittedModel
    from benchmarks.protocol.tasks import model_estimator

    fitted = FittedModel("m", "user", _model(), 1e-4, TrainingRecord(keeps_lane=True))
    checked = model_estimator(fitted, FilterSettings())
    assert checked.settings.evidence_checks
    unchecked = model_estimator(fitted, FilterSettings(), {"evidence_checks": False})
    assert not unchecked.settings.evidence_checks
    # only the evidence checks: the model's limits stay (--compare-checks drops them too)
    assert unchecked.settings.steering_max_speed == checked.settings.steering_max_speed
    compared = model_estimator(fitted, FilterSettings(), None, checks=False)
    assert not compared.settings.evidence_checks
    assert compared.settings.steering_max_speed == math.inf


def test_a_model_that_cannot_drive_gives_no_lane_evidence_unless_unchecked() -> None:
    training = TrainingRecord(keeps_lane=False, lane_check="left the road after 15.5 s")
    trusted = trusted_filter(_model(), training=training)
    assert trusted.arx is None and isinstance(trusted.estimator(), NoSteeringEKF)
    assert trusted.reasons == (
        "steering off: the model does not keep the car in its lane when it steers itself "
        "(left the road after 15.5 s)",
    )
    unchecked = trusted_filter(
        _model(), training=training, overrides={"steering_curvature_limit": 0.01}, checks=False
    )
    assert unchecked.arx is not None and not unchecked.settings.evidence_checks
    assert unchecked.settings.steering_curvature_limit == math.inf
    assert unchecked.settings.steering_max_speed == math.inf
    assert trusted_filter(None).reasons == ("steering off: no steering model",)


def test_a_training_run_stands_in_for_what_the_model_does_not_record() -> None:
    run = pd.DataFrame({"speed": [15.0, 16.0, np.nan], "road_curvature": [0.0, -0.01, np.nan]})
    record = TrainingRecord.from_run(run)
    assert record.speed_range == (15.0, 16.0) and record.curvature == 0.01
    paper = GeneralizedModel.paper()  # keeps its roads (straight), not its speeds
    settings = trusted_filter(paper, training=record).settings
    assert settings.steering_curvature_limit == STRAIGHT_CURVATURE  # its own record first
    assert (settings.min_speed, settings.steering_max_speed) == (14.0, 17.0)
    assert TrainingRecord.from_run(pd.DataFrame({"x": [1.0]})) == TrainingRecord()


def test_hasa_replay_prints_where_the_estimator_does_not_listen(tmp_path, recording, capsys):
    from hasa_cli.replay import main

    path = tmp_path / "model.json"
    _model().save(path)
    argv = [str(recording.path), "--model", str(path), "--estimator", "--no-lane-check"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if "estimator trust:" in ln)
    assert line.startswith(f"model {path}: estimator trust: steering off ")
    assert "above 17.1 m/s" in line


def test_the_benchmark_describes_each_models_limits() -> None:
    from benchmarks.protocol.models import FittedModel, describe_trust

    fitted = [
        FittedModel("m", "user", _model(), 1e-3),
        FittedModel("road_blind", "baseline", _model(), None),  # no estimator: no reasons
    ]
    infos = [{"name": "m"}, {"name": "road_blind"}]
    describe_trust(fitted, infos, {"min_speed": 5.0})
    assert infos[0]["steering_trust"] == [
        *trusted_filter(_model()).reasons[:2],
        "steering off below 5.0 m/s: set by the user (min_speed)",
        "steering off above 17.1 m/s: outside the training speeds 15.2-16.1 m/s +- 1",
    ]
    assert "steering_trust" not in infos[1]


def test_a_model_fitted_in_python_gets_the_benchmarks_training_record() -> None:
    from benchmarks.protocol.models import _filter_residual, _training_record
    from hasa_env.drivers import SyntheticDriver, population, run_driver

    runs = run_driver(SyntheticDriver(population("paper", seed=0)[0]), runs=3, seed=0,
                      config={"time_limit": 8.0})  # fmt: skip
    model = GeneralizedModel(equation_error_order=2).fit(runs[:2])
    record = TrainingRecord.measured(model, runs[:2])
    # what hasa-bench records for a model it fitted on the same runs
    _, residual, prediction, whitened, _, gain = _filter_residual("m", model, runs[:2])
    info = {
        "whitened_residual_std": whitened,
        "speed_scaled_gain": gain,
        "prediction_residual_std": prediction.residual_std,
        "lane_free_residual_std": prediction.lane_free_residual_std,
    }
    bench = dataclasses.replace(
        _training_record(False, runs[:2], info, True), residual_std=residual
    )
    assert record == bench
    assert record.prediction is not None and record.prediction.passed
    speeds = pd.concat(runs[:2])["speed"]
    assert record.speed_range == (speeds.min(), speeds.max())
    assert record.whitened_residual_std is not None and record.speed_scaled_gain is None
    # the trusted filter carries the measured level; the bare EKF the default 2e-3 rad
    trusted = trusted_filter(model, training=record).estimator()
    assert trusted.settings.steering_residual_std < 0.5 * FilterSettings.steering_residual_std
    assert GaussianMixtureEKF(model.arx()).settings == FilterSettings()
    assert TrainingRecord.measured(model, runs[0]) == TrainingRecord.measured(model, [runs[0]])
    with pytest.raises(ValueError, match="at least one training run"):
        TrainingRecord.measured(model, [])


def test_a_model_without_an_arx_form_records_only_its_roads_and_speeds() -> None:
    class NoForm:
        def arx(self):
            return None

    frame = pd.DataFrame({"speed": [14.0, 16.0], "road_curvature": [0.0, -0.002]})
    record = TrainingRecord.measured(NoForm(), frame)
    assert record == TrainingRecord(curvature=0.002, speed_range=(14.0, 16.0))


def test_hasa_replay_says_when_the_steering_was_never_used(recording) -> None:
    from benchmarks.replay_estimate import describe_estimate, estimate_verdict
    from estimators.offline import estimate_recording

    run = estimate_recording(recording, _model(), training=TrainingRecord(keeps_lane=False))
    verdict = estimate_verdict(run)  # the no-steering filter: its steering never used
    assert verdict["steering"]["unused"] == pytest.approx(1.0) and verdict["lateral_nees"] > 0
    assert "steering live 0% of the time (off 0%, unused 100%," in describe_estimate(run)
    listened = estimate_verdict(estimate_recording(recording, _model()))["steering"]
    assert listened is not None and listened["unused"] < 0.1  # used (0.5 s: mostly tempered)
    unknown = dataclasses.replace(run, result=None)
    assert estimate_verdict(unknown) == {"steering": None, "lateral_nees": None}
