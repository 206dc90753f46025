"""HumanPool: N cars' synthetic humans, each car's human chosen per episode."""

from __future__ import annotations

import numpy as np
import pytest

from hasa_env.drivers import population
from hasa_env.drivers.human import INFO_NEEDED, human_batch
from hasa_env.rl.humans import HumanPool
from hasa_env.sim.road import make_road

ROAD = make_road("straight")


def _info(rng: np.random.Generator, n: int, k: int) -> dict[str, np.ndarray]:
    return {
        "time": np.full(n, 0.01 * k),
        "station": 0.15 * k + rng.uniform(0.0, 1.0, n),
        "lateral_offset": rng.normal(0.0, 0.3, n),
        "heading": rng.normal(0.0, 0.01, n),
        "speed": rng.uniform(13.0, 17.0, n),
        "steering": rng.normal(0.0, 0.004, n),
    }


def test_every_car_drives_as_its_driver_alone_through_reassignments():
    drivers = population("paper", seed=1)
    n, steps = 6, 200
    pool = HumanPool(drivers, n, 0.01)
    rng = np.random.default_rng(0)
    alone: dict[int, object] = {}

    def start(cars: list[int], k: int) -> None:
        chosen = rng.integers(len(drivers), size=len(cars))
        seeds = [1000 * k + c for c in cars]
        pool.assign(cars, chosen, seeds)
        for car, d, seed in zip(cars, chosen.tolist(), seeds, strict=True):
            alone[car] = human_batch([drivers[d]])
            alone[car].reset([seed], 0.01)
        assert pool.driver_of[cars].tolist() == chosen.tolist()

    start(list(range(n)), 0)
    for k in range(steps):
        if k and k % 17 == 0:  # some cars start new episodes, with new humans
            start(sorted(rng.choice(n, size=2, replace=False).tolist()), k)
        info = _info(rng, n, k)
        steering, acceleration = pool.act(info, ROAD)
        for car in range(n):
            one = {key: info[key][car : car + 1] for key in INFO_NEEDED}
            s, a = alone[car].act(one, ROAD)
            assert (s[0], a[0]) == (steering[car], acceleration[car]), (k, car)
    assert pool.num_batches <= 2 * len(drivers), "free slots are not reused"


def test_steer_is_the_steering_of_act_and_cars_without_a_human_get_nan():
    drivers = population("paper", seed=0)[:3]
    a, b = HumanPool(drivers, 4, 0.01), HumanPool(drivers, 4, 0.01)
    for pool in (a, b):
        pool.assign([0, 2, 3], [0, 1, 1], [5, 6, 7])
    rng = np.random.default_rng(2)
    for k in range(30):
        info = _info(rng, 4, k)
        steering = a.act(info, ROAD)[0]
        assert np.array_equal(steering, b.steer(info, ROAD), equal_nan=True)
        assert np.isnan(steering[1]) and np.isfinite(steering[[0, 2, 3]]).all()


def test_bad_arguments_are_refused():
    drivers = population("paper", seed=0)[:2]
    with pytest.raises(ValueError, match="num_cars"):
        HumanPool(drivers, 0, 0.01)
    with pytest.raises(TypeError):
        HumanPool([object()], 2, 0.01)
    pool = HumanPool(drivers, 2, 0.01)
    with pytest.raises(IndexError, match="drivers"):
        pool.assign([0], [5], [1])
    with pytest.raises(ValueError, match="twice"):
        pool.assign([0, 0], [0, 1], [1, 2])
    with pytest.raises(ValueError, match="one driver and one seed"):
        pool.assign([0, 1], [0], [1, 2])
