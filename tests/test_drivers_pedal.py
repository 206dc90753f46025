"""The pedal remnant of the synthetic humans: a held speed wanders as a foot's does."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hasa_env.drivers import population
from hasa_env.drivers.base import SpeedProfile
from hasa_env.drivers.populations import POPULATIONS
from hasa_env.drivers.runner import run_population


def _held_speed_std(noise: float, time_constant: float, gain: float = 1.0) -> float:
    """Stationary std (m/s) of a held speed: OU acceleration into the speed loop of gain g."""
    return noise * math.sqrt(time_constant / (gain * (1.0 + gain * time_constant)))


@pytest.mark.slow
def test_a_held_speed_wanders_by_the_std_the_docstring_states():
    noise, tau = 0.35, 2.0
    drivers = [
        dataclasses.replace(
            p.with_speed(SpeedProfile(pedal_noise=noise, pedal_time_constant=tau)),
            name=f"{p.name}-{i}",
        )
        for i, p in enumerate(population("paper", seed=3) * 3)
    ]
    runs = run_population(drivers, runs=1, seed=1, config={"time_limit": 80.0})
    # after 10 s the remnant is stationary; pool the cars' deviations from 15 m/s
    deviations = np.concatenate(
        [runs[p.name][0]["speed"].to_numpy()[1000:] - 15.0 for p in drivers]
    )
    expected = _held_speed_std(noise, tau)  # 0.286 m/s
    assert abs(np.mean(deviations)) < 0.1
    assert np.std(deviations) == pytest.approx(expected, rel=0.2)


def test_without_a_pedal_remnant_the_speed_is_held_exactly():
    params = [p.with_speed(SpeedProfile.hold()) for p in population("paper", seed=0)[:3]]
    runs = run_population(params, runs=1, seed=0, config={"time_limit": 5.0})
    for p in params:
        assert np.ptp(runs[p.name][0]["speed"].to_numpy()) < 1e-9


def test_the_paper_population_has_a_pedal_remnant_and_the_pi_population_none():
    for p in population("paper", seed=5):
        assert 0.2 <= p.speed.pedal_noise <= 0.5 and 1.0 <= p.speed.pedal_time_constant <= 3.0
    assert all(p.speed.pedal_noise == 0.0 for p in population("paper-pi", seed=5))


def test_the_pedal_draws_leave_every_other_trait_as_it_was(monkeypatch):
    without = dataclasses.replace(POPULATIONS["paper"], pedal=None, seed_key="paper")
    monkeypatch.setitem(POPULATIONS, "paper-no-pedal", without)
    for a, b in zip(population("paper", 4), population("paper-no-pedal", 4), strict=True):
        assert a == dataclasses.replace(
            b,
            speed=dataclasses.replace(
                b.speed,
                pedal_noise=a.speed.pedal_noise,
                pedal_time_constant=a.speed.pedal_time_constant,
            ),
        )


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("pedal_noise", -0.1),
        ("pedal_noise", math.nan),
        ("pedal_noise", 5.0),
        ("pedal_time_constant", 0.0),
        ("pedal_time_constant", math.inf),
    ],
)
def test_a_bad_pedal_remnant_is_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"SpeedProfile.{field}"):
        SpeedProfile(**{field: value})


def test_a_model_driver_refuses_a_pedal_remnant():
    from hasa_env.drivers.model_driver import ModelDriver
    from hasa_env.steering import GeneralizedModel

    with pytest.raises(ValueError, match="pedal_noise"):
        ModelDriver(GeneralizedModel.paper(), speed=SpeedProfile(pedal_noise=0.3))


def test_a_saved_driver_keeps_its_pedal_remnant_and_an_old_file_loads_without_one():
    params = population("paper", seed=1)[0]
    data = params.to_dict()
    assert type(params).from_dict(data) == params
    for key in ("pedal_noise", "pedal_time_constant"):
        del data["speed"][key]
    assert type(params).from_dict(data).speed.pedal_noise == 0.0
