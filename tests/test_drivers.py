"""Drivers: protocol, population, runner, replay, and the model driver's sample alignment."""

import dataclasses

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

import hasa_env  # noqa: F401  (registers the env ids)
from hasa_env.drivers import (
    Driver,
    ModelDriver,
    ReplayDriver,
    SpeedProfile,
    SyntheticDriver,
    TwoPointParams,
    population,
    run_driver,
    run_population,
    run_seeds,
    save_runs,
)
from hasa_env.sim.road import curved_road
from hasa_env.sim.setup import RECORDING_COLUMNS
from hasa_env.steering import GeneralizedModel, TwoPointModel
from hasa_env.steering.base import Design, Regressor, SteeringModel, lagged

SHORT = {"time_limit": 3.0}


def test_drivers_implement_the_protocol():
    model = GeneralizedModel.paper()
    for driver in (
        SyntheticDriver(TwoPointParams()),
        ModelDriver(model),
        ReplayDriver([[0.0, 0.0]]),
    ):
        assert isinstance(driver, Driver)


def test_population_is_reproducible_by_name_and_seed():
    # the all-PI population; "paper" (mixed archetypes): tests/test_drivers_populations.py
    first = population("paper-pi", seed=0)
    assert [p.name for p in first] == ["Ill", "1", "2", "3", "4", "5", "6", "7", "8"]
    assert population("paper-pi", seed=0) == first
    other = population("paper-pi", seed=1)
    assert other != first
    for trait in ("near_gain", "far_gain", "integral_gain", "delay", "noise_std"):
        values = [getattr(p, trait) for p in first]
        assert len(set(values)) == len(values), trait  # every driver differs
    targets = [p.speed.target_speed for p in first]
    assert targets.count(None) == 3 and targets.count(45.0) == 3  # hold 15 m/s .. ramp to 45
    assert all(0.15 <= p.delay <= 0.25 for p in first)
    assert all(8 <= p.neuromuscular_frequency <= 14 for p in first)
    assert all(0.6 <= p.neuromuscular_damping <= 0.85 for p in first)
    assert any(p.noise_time_constant == 0 for p in first)  # white motor noise
    assert any(0.2 <= p.noise_time_constant <= 0.4 for p in first)  # OU motor noise
    assert len(population("paper-pi", size=4)) == 4
    assert TwoPointParams.from_dict(first[3].to_dict()) == first[3]
    with pytest.raises(
        ValueError, match="unknown population 'nope'; allowed: mixed, paper, paper-pi"
    ):
        population("nope")


def test_loop_design_places_the_lateral_poles():
    params = TwoPointParams.from_loop(1.1, 0.6, 0.3, near_time=0.4, far_time=1.2)
    c = params.reference_speed / 2.8
    k_n, k_f, k_i = params.near_gain, params.far_gain, params.integral_gain
    # y''' + A1 y'' + A0 y' + AI y = 0 (see TwoPointParams.from_loop)
    actual = [1.0, c * (k_n + k_f), c * (k_n / 0.4 + k_f / 1.2 + k_i), c * k_i / 0.4]
    desired = np.poly([-0.3 * 1.1, *np.roots([1.0, 2 * 0.6 * 1.1, 1.1**2])])
    np.testing.assert_allclose(actual, desired.real, rtol=1e-12)


def test_runs_are_recordings_and_reproducible():
    driver = SyntheticDriver(population()[0])
    frames = run_driver(driver, runs=2, seed=3, config=SHORT)
    again = run_driver(driver, runs=2, seed=3, config=SHORT)
    other = run_driver(driver, runs=2, seed=4, config=SHORT)
    assert len(frames) == 2
    for frame, same, different in zip(frames, again, other, strict=True):
        assert list(frame.columns) == list(RECORDING_COLUMNS)
        assert len(frame) == 301 and frame["step"].tolist() == list(range(301))
        assert frame["step"].dtype == np.int64 and frame["terminated"].dtype == bool
        assert frame.loc[0, "lateral_offset"] == -0.5 and frame.loc[0, "speed"] == 15.0
        assert frame["truncated"].iloc[-1] and not frame["truncated"].iloc[:-1].any()
        assert frame.attrs["config"]["action"]["type"] == "physical"
        assert frame.attrs["driver"] == "Ill"
        pd.testing.assert_frame_equal(frame, same)
        assert not frame["steering"].equals(different["steering"])
    assert frames[0].attrs["seed"] != frames[1].attrs["seed"]


@pytest.mark.parametrize("make_driver", [
    lambda: SyntheticDriver(population()[6]),
    lambda: SyntheticDriver(population("mixed", 0)[3]),  # noisy corrections
    lambda: ModelDriver(GeneralizedModel.paper(), noise_std=1e-3, steering_ratio=15.0),
    lambda: ReplayDriver(np.column_stack([np.linspace(0, 0.01, 50), np.ones(50)])),
])  # fmt: skip
def test_vectorized_runs_equal_single_env_runs(make_driver):
    driver = make_driver()
    vector = run_driver(driver, runs=3, seed=5, config=SHORT, vectorized=True)
    single = run_driver(driver, runs=3, seed=5, config=SHORT, vectorized=False)
    for a, b in zip(vector, single, strict=True):
        pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-12, atol=1e-12)


def test_population_runs_equal_runs_of_each_driver():
    drivers = population()[:3]
    runs = run_population(drivers, runs=2, seed=9, config=SHORT, runs_by_name={"1": 3})
    assert [len(v) for v in runs.values()] == [2, 3, 2]
    alone = run_driver(SyntheticDriver(drivers[1]), runs=3, seed=9, config=SHORT)
    for a, b in zip(runs["1"], alone, strict=True):
        pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="unknown drivers"):
        run_population(drivers, runs_by_name={"9": 1})
    assert run_seeds(0, 2, "Ill/straight") != run_seeds(0, 2, "1/straight")


def test_replay_reproduces_a_recording():
    original = run_driver(SyntheticDriver(population()[2]), seed=1, config=SHORT)[0]
    env = gym.make("hasa_env/LaneKeeping-v0", config={**SHORT, "action": {"type": "physical"}})
    replayed = run_driver(ReplayDriver(original), env, seed=0)[0]
    for column in ("lateral_offset", "heading", "speed", "steering", "station"):
        np.testing.assert_array_equal(replayed[column], original[column])
    with pytest.raises(ValueError, match="lacks the columns"):
        ReplayDriver(pd.DataFrame({"steering": [0.0]}))


def test_drivers_work_in_a_normalized_action_env():
    env = gym.make("hasa_env/LaneKeeping-v0", config=SHORT)  # default: normalized actions
    actions = np.column_stack([np.full(300, 0.002), np.full(300, 1.0)])
    frame = run_driver(ReplayDriver(actions), env)[0]
    np.testing.assert_allclose(frame["steering"][1:], 0.002, atol=1e-12)
    np.testing.assert_allclose(frame["acceleration"][1:], 1.0, atol=1e-12)


class SpeedScheduledGain(SteeringModel):
    """Not an ARX model: the near-point gain falls with speed (exercises the generic path)."""

    model_type = "test_speed_scheduled_gain"

    @property
    def parameter_names(self):
        return ("memory", "near")

    @property
    def regressors(self):
        return (Regressor("delta", 1), Regressor("phi", 0), Regressor("speed", 0))

    def design(self, features):
        delta = features["delta"].to_numpy()
        phi, speed = features["phi"].to_numpy(), features["speed"].to_numpy()
        return Design(
            delta, np.zeros_like(delta), np.column_stack([lagged(delta, 1), phi * 15.0 / speed])
        )


@pytest.mark.parametrize(("model", "env_id", "ratio"), [
    (GeneralizedModel.paper(steering_signal="applied"), "hasa_env/LaneKeeping-v0", 1.0),
    (TwoPointModel.paper(steering_signal="applied"), "hasa_env/LaneKeeping-v0", 1.0),
    (GeneralizedModel.paper(steering_signal="applied"), "hasa_env/LaneKeepingCurved-v0", 15.0),
    (SpeedScheduledGain([0.98, 0.05], steering_signal="applied"), "hasa_env/LaneKeeping-v0", 1.0),
    # a dead time: the model driver acts on the bearings of decision_lag - 1 steps before
    (GeneralizedModel.paper(steering_signal="applied", decision_lag=3), "hasa_env/LaneKeeping-v0",
     1.0),
    (TwoPointModel.paper(steering_signal="applied", decision_lag=20),
     "hasa_env/LaneKeepingCurved-v0", 15.0),
])  # fmt: skip
def test_a_model_driver_is_what_its_model_predicts(model, env_id, ratio):
    """Noise-free, a model driver's recording is exactly the model's one-step prediction
    of the applied steering: the sample alignment of the features matches how drivers act."""
    options = {"lateral_offset": -0.5, "speed": 20.0}
    config = {"time_limit": 12.0} if "Curved" in env_id else SHORT  # 240 m: into the first bend
    driver = ModelDriver(model, steering_ratio=ratio)
    frame = run_driver(driver, env_id, config=config, options=options)[0]
    if "Curved" in env_id:
        assert frame["road_curvature"].abs().max() > 1e-3
    road = curved_road() if "Curved" in env_id else None
    in_model_units = frame.assign(steering=frame["steering"] * ratio)
    predicted = model.predict(in_model_units, road=road) / ratio
    recorded = frame["steering"].to_numpy()
    start = model.max_lag + model.decision_lag
    assert np.isfinite(predicted[start:]).all()
    np.testing.assert_allclose(predicted[start:], recorded[start:], rtol=1e-9, atol=1e-13)
    assert np.abs(recorded).max() > 1e-3  # it actually steered


def test_model_driver_checks_its_arguments():
    with pytest.raises(ValueError, match="no parameters"):
        ModelDriver(GeneralizedModel())
    with pytest.raises(ValueError, match="steering_ratio"):
        ModelDriver(GeneralizedModel.paper(), steering_ratio=0.0)
    driver = ModelDriver(GeneralizedModel.paper())
    with pytest.raises(ValueError, match="Ts = 0.01"):
        run_driver(driver, config={"sim_frequency": 50.0, **SHORT})
    with pytest.raises(ValueError, match="speed_exponent"):
        TwoPointParams(speed_exponent=float("nan"))


def test_speed_profiles_ramp_and_slow_for_bends():
    params = dataclasses.replace(
        population("paper-pi")[0],
        noise_std=0.0,
        speed=SpeedProfile(target_speed=30.0, ramp_rate=2.0, start_time=1.0),
    )
    frame = run_driver(SyntheticDriver(params), config={"time_limit": 15.0})[0]
    speed = frame.set_index("time")["speed"]
    assert speed.loc[0.9] == pytest.approx(15.0, abs=0.01)
    assert speed.loc[5.0] == pytest.approx(15.0 + 2.0 * 4.0, abs=0.5)  # on the ramp
    assert speed.loc[14.0] == pytest.approx(30.0, abs=0.2)  # reached the target
    assert speed.max() < 30.5
    # on the curved track the same driver slows down to keep 3 m/s^2 in the bends
    fast = dataclasses.replace(params.speed, target_speed=45.0, max_lateral_acceleration=3.0)
    bends = dataclasses.replace(params, speed=fast)
    curved = run_driver(
        SyntheticDriver(bends), "hasa_env/LaneKeepingCurved-v0", config={"time_limit": 30.0}
    )[0]
    lateral = curved["speed"] ** 2 * curved["road_curvature"].abs()
    assert lateral.max() < 3.0 * 1.15
    assert curved["speed"].max() > 25.0


def test_saved_runs_load_and_replay_exactly(tmp_path):
    from hasa_env.recording import compare_recordings, load_recordings, replay

    frames = run_driver(SyntheticDriver(population()[4]), runs=2, seed=2, config=SHORT)
    paths = save_runs(frames, tmp_path)
    assert [p.name for p in paths] == ["run_000.csv", "run_001.csv"]
    loaded = load_recordings(tmp_path)
    assert len(loaded) == 2 and not loaded.errors
    for recording, frame in zip(loaded, frames, strict=True):
        pd.testing.assert_frame_equal(recording.data, frame, check_exact=True, check_like=True)
        assert recording.meta["metadata"]["driver"] == "4"
        assert recording.seed == frame.attrs["seed"]
        assert compare_recordings(recording.data, replay(recording)) is None  # bit-identical
