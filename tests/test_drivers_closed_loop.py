"""Closed loop: the synthetic population keeps its lane; docs/design.md's model-driver facts (§7.6)."""

import dataclasses

import numpy as np
import pytest

from hasa_env.drivers import (
    ModelDriver,
    SpeedProfile,
    SyntheticDriver,
    population,
    run_drivers,
    run_population,
)
from hasa_env.steering import GeneralizedModel

START = {"lateral_offset": -0.5, "bias_index": 0}


def first_time_within(frame, limit=0.1):
    inside = np.abs(frame["lateral_offset"].to_numpy()) < limit
    return float(frame["time"].to_numpy()[np.argmax(inside)]) if inside.any() else np.inf


@pytest.mark.slow
@pytest.mark.parametrize("speed", [15.0, 30.0, 45.0])
def test_every_synthetic_driver_centres_the_car_at_constant_speed(speed):
    """The control loop itself (no motor noise): from y = -0.5 m to |y| < 0.1 m within 20 s."""
    drivers = [
        SyntheticDriver(dataclasses.replace(p, noise_std=0.0, speed=SpeedProfile.hold()))
        for p in population("paper-pi")
    ]
    frames = run_drivers(drivers, [(0, 0)] * len(drivers), options={**START, "speed": speed})
    for driver, frame in zip(drivers, frames, strict=True):
        assert not frame["terminated"].any(), driver.name
        assert first_time_within(frame) <= 20.0, driver.name
        y = frame["lateral_offset"].to_numpy()
        assert abs(y[-1]) < 0.02, driver.name
        assert y.max() < 0.1, driver.name  # no big overshoot
        assert frame["speed"].iloc[-1] == pytest.approx(speed)


@pytest.mark.slow
def test_every_synthetic_driver_centres_the_car_at_its_own_speeds_with_noise():
    params = population("paper-pi")
    runs = run_population(params, runs=2, seed=0, options=START)
    top_speeds = []
    for p in params:
        for frame in runs[p.name]:
            assert not frame["terminated"].any(), p.name
            assert first_time_within(frame) <= 20.0, p.name
            late = frame.loc[frame["time"] >= 20.0, "lateral_offset"].to_numpy()
            assert np.sqrt(np.mean(late**2)) < 0.1, p.name  # stays centred, noise and all
            assert np.abs(late).max() < 0.25, p.name
            top_speeds.append(frame["speed"].max())
    assert max(top_speeds) == pytest.approx(45.0, abs=0.1)  # some reach 45 m/s
    assert min(top_speeds) == pytest.approx(15.0, abs=0.1)  # some hold 15 m/s


@pytest.mark.slow
def test_every_synthetic_driver_stays_on_the_curved_road():
    params = population()
    runs = run_population(params, runs=1, seed=0, env_id="hasa_env/LaneKeepingCurved-v0")
    for p in params:
        frame = runs[p.name][0]
        assert len(frame) == 3001 and not frame["terminated"].any(), p.name
        assert frame["lateral_offset"].abs().max() < 1.8, p.name  # rear axle stays in its lane
        # it drove into the bends (a driver holding 15 m/s who slows for them ends near 450 m)
        assert frame["station"].iloc[-1] > 400.0, p.name


def peak_lateral_acceleration(frame):
    speed, steering = frame["speed"].to_numpy(), frame["steering"].to_numpy()
    return float(np.max(np.abs(speed**2 * np.tan(steering) / 2.8)))


@pytest.mark.slow
def test_design_facts_of_the_paper_generalized_model_as_a_driver():
    """docs/design.md §5.8: at Ts = 0.01 s from y = -0.5 m the paper's generalized preset
    centres the car at 15 and 30 m/s with ratio 1 (peak lateral acceleration 6.6 and
    18.9 m/s^2) and diverges at 45 m/s; with ratio 15 it centres at 15, 30 and 45 m/s
    (0.8, 2.8, 5.6 m/s^2); with the paper's unconverted d signs it diverges at ratio 1."""
    model = GeneralizedModel.paper()
    paper_signs = GeneralizedModel.from_coefficients(
        (1.47, -0.51), (-5.73, 17.32, -17.65, 6.12), (0.11,), (0.02, -0.02)
    )
    cases = [  # (model, ratio, speed, expected peak lateral acceleration or None: diverges)
        (model, 1.0, 15.0, 6.6),
        (model, 1.0, 30.0, 18.9),
        (model, 1.0, 45.0, None),
        (model, 15.0, 15.0, 0.8),
        (model, 15.0, 30.0, 2.8),
        (model, 15.0, 45.0, 5.6),
        (paper_signs, 1.0, 15.0, None),
    ]
    results = []
    for speed in (15.0, 30.0, 45.0):  # one vector env per speed
        group = [case for case in cases if case[2] == speed]
        drivers = [ModelDriver(m, steering_ratio=ratio) for m, ratio, _, _ in group]
        runs = run_drivers(drivers, [(0, 0)] * len(group), options={**START, "speed": speed})
        results.extend(zip(group, runs, strict=True))
    assert len(results) == len(cases)
    for (m, ratio, speed, peak), frame in results:
        label = (m.name, ratio, speed)
        y = frame["lateral_offset"].to_numpy()
        if peak is None:
            steering = frame["steering"].abs().to_numpy()
            # diverged: off the road, or steering slammed against its 0.5 rad limit
            assert frame["terminated"].any() or np.max(steering[-500:]) >= 0.5 - 1e-9, label
            assert frame["terminated"].any() or np.abs(y[-500:]).max() > 0.1, label
        else:
            assert not frame["terminated"].any(), label
            assert abs(y[-1]) < 1e-6, label
            assert peak_lateral_acceleration(frame) == pytest.approx(peak, abs=0.15), label
