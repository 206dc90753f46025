"""The cheaper run generation gives the bits of the plain one (docs/design.md, the vector env).

The stacked output and speed stages of several archetypes (:class:`HumanComposite`) against
each archetype's batch driving its cars alone; the preview and slot sums
(:func:`sum_from`) and the disturbance's N-car sines against the loops they replace;
the road's slope-table curvature lookup against the two-node one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from _driver_states import random_info

from hasa_env.drivers import population
from hasa_env.drivers.base import CompositeBatch
from hasa_env.drivers.human import HumanBatch, HumanComposite, human_batch, sum_from
from hasa_env.sim.dynamics import ARRAY_OPS, SCALAR_OPS
from hasa_env.sim.road import curvature_lookup_array, make_road
from hasa_env.sim.setup import build_setup


def _per_archetype(params: list) -> CompositeBatch:
    """The cars of ``params`` driven by one batch per archetype, each with its own stages."""
    groups: dict[type, list[int]] = {}
    for i, p in enumerate(params):
        groups.setdefault(type(p), []).append(i)
    parts = [
        (np.array(idx), HumanBatch.registry[kind]([params[i] for i in idx]))
        for kind, idx in groups.items()
    ]
    return CompositeBatch(parts, len(params))


@pytest.mark.parametrize("track", ["straight", "curved"])
@pytest.mark.parametrize(("name", "stacked"), [("paper", True), ("mixed", False)])
def test_stacked_stages_give_each_archetypes_bits(track, name, stacked):
    road = make_road(track)
    params = population(name, seed=5003, size=9)
    seeds = list(range(5000, 5000 + len(params)))
    ours, theirs = human_batch(params), _per_archetype(params)
    assert isinstance(ours, HumanComposite)
    for batch in (ours, theirs):
        batch.reset(seeds, 0.01)
    assert ours.stacked == stacked  # mixed: noisy corrections draw no command noise
    rng = np.random.default_rng(5003)
    for k in range(1100):  # past the first block of noise draws (1000 steps)
        info = random_info(rng, len(params), k, bias=True)
        if k == 600:  # a partial reset restarts cars 1 and 4 in both
            for batch in (ours, theirs):
                batch.reset([5090, 5091], 0.01, cars=[1, 4])
        s1, a1 = ours.act(info, road)
        s2, a2 = theirs.act(info, road)
        np.testing.assert_array_equal(s1, s2, err_msg=f"steering, step {k}")
        np.testing.assert_array_equal(a1, a2, err_msg=f"acceleration, step {k}")


def test_sum_from_adds_as_the_loop_over_columns():
    rng = np.random.default_rng(5004)
    first = rng.normal(size=50) * 10.0 ** rng.integers(-8, 8, 50)
    terms = rng.normal(size=(50, 7)) * 10.0 ** rng.integers(-8, 8, (50, 7))
    terms[::3, 2] = 0.0
    loop = first
    for j in range(terms.shape[1]):
        loop = loop + terms[:, j]
    np.testing.assert_array_equal(sum_from(first, terms), loop)


def test_the_n_car_disturbance_is_the_one_car_sum():
    setup = build_setup({"disturbance": {"crosswind": 0.3, "camber": 0.2}}, "curved")
    disturbance = setup.disturbance
    assert disturbance is not None
    rng = np.random.default_rng(5005)
    n = 40
    phases = rng.uniform(0.0, 2.0 * math.pi, (n, disturbance.n_phases))
    time = rng.uniform(0.0, 30.0, n)
    station = rng.uniform(0.0, 1200.0, n)
    ours = disturbance.lateral_acceleration(time, station, phases, ARRAY_OPS)
    alone = [
        disturbance.lateral_acceleration(float(t), float(s), p.tolist(), SCALAR_OPS)
        for t, s, p in zip(time, station, phases, strict=True)
    ]
    np.testing.assert_array_equal(ours, np.array(alone))


def test_the_slope_table_lookup_is_the_two_node_lookup():
    road = make_road("curved")
    stations = np.random.default_rng(5006).uniform(-20.0, road.length + 50.0, (30, 33))
    plain = curvature_lookup_array(road.curvature, 1.0 / road.spacing, stations)
    np.testing.assert_array_equal(road.curvature_lookup(stations), plain)
    assert road.is_straight is False and make_road("straight").is_straight is True
