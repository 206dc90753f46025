"""Partial resets of driver batches: a restarted car drives as a driver reset alone.

The vector advisor task (``advisor_tasks.vector``) restarts one car's
synthetic human when that car's episode ends, while the other cars' humans
go on; these tests pin the batch hooks it relies on.
"""

from __future__ import annotations

import numpy as np
import pytest
from _driver_states import random_info

from hasa_env.drivers import population
from hasa_env.drivers.human import INFO_NEEDED, human_batch
from hasa_env.sim.road import make_road


@pytest.mark.parametrize("track", ["straight", "curved"])
@pytest.mark.parametrize(("population_name", "restarted"), [("paper", [1, 4]), ("mixed", [2, 4])])
def test_a_restarted_car_drives_as_a_driver_reset_alone(track, population_name, restarted):
    road = make_road(track)
    # paper: two of each archetype; mixed: two-point, intermittent, noisy corrections (two
    # each, car 2 one of the latter): a composite batch
    params = population(population_name, seed=2)[:6]
    n = len(params)
    batch = human_batch(params)
    batch.reset(list(range(100, 100 + n)), 0.01)
    rng = np.random.default_rng(0)
    infos = [random_info(rng, n, k) for k in range(260)]
    restart_at, cars, seeds = 37, np.array(restarted), [7, 9]
    alone = {int(c): human_batch([params[c]]) for c in cars}
    steering, accelerations = [], []
    for k, info in enumerate(infos):
        if k == restart_at:
            batch.reset(seeds, 0.01, cars=cars)
            for c, seed in zip(cars.tolist(), seeds, strict=True):
                alone[c].reset([seed], 0.01)
        s, a = batch.act(info, road)
        steering.append(s)
        accelerations.append(a)
        if k >= restart_at:
            for c, single in alone.items():
                one = {key: info[key][c : c + 1] for key in INFO_NEEDED}
                s1, a1 = single.act(one, road)
                assert s1[0] == s[c] and a1[0] == a[c], (k, c)
    # the cars that were not restarted drive on as in a batch never touched
    untouched = human_batch(params)
    untouched.reset(list(range(100, 100 + n)), 0.01)
    others = np.setdiff1d(np.arange(n), cars)
    for k, info in enumerate(infos):
        s, a = untouched.act(info, road)
        assert np.array_equal(s[others], steering[k][others]), k
        assert np.array_equal(a[others], accelerations[k][others]), k  # pedal remnant too


def test_steer_is_the_steering_of_act():
    road = make_road("straight")
    params = population("paper", seed=0)
    a, b = human_batch(params), human_batch(params)
    a.reset(list(range(9)), 0.01)
    b.reset(list(range(9)), 0.01)
    rng = np.random.default_rng(1)
    for k in range(50):
        info = random_info(rng, 9, k)
        assert np.array_equal(a.act(info, road)[0], b.steer(info, road))


def test_partial_reset_is_refused_before_a_full_one_and_with_another_dt():
    batch = human_batch(population("paper", seed=0)[:3])
    with pytest.raises(RuntimeError, match="whole batch"):
        batch.reset([1], 0.01, cars=[0])
    batch.reset([1, 2, 3], 0.01)
    with pytest.raises(ValueError, match="dt"):
        batch.reset([1], 0.02, cars=[0])
    with pytest.raises(ValueError, match="seeds"):
        batch.reset([1, 2], 0.01, cars=[0])
