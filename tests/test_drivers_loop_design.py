"""Gains designed with the driver's delay and lag, and the "paper-with-delay" population (§7.10)."""

import dataclasses

import numpy as np
import pytest

import hasa_env  # noqa: F401  (registers the env ids)
from hasa_env.drivers import POPULATIONS, TwoPointParams, population, run_population
from hasa_env.drivers.loop_design import (
    FREQUENCIES,
    feedback_gains,
    loop_margins,
    preview_cost_for_margin,
    preview_loop,
    two_point_for_crossover,
    two_point_loop,
)
from hasa_env.drivers.lqr import PreviewCost, preview_gains


def test_loop_margins_of_a_crossover_model():
    # L = w_c exp(-s tau) / s: crossover w_c, margin 90 deg - w_c tau
    w = FREQUENCIES
    crossover, margin = loop_margins(w, 2.0 * np.exp(-1j * w * 0.3) / (1j * w))
    assert crossover == pytest.approx(2.0, rel=1e-3)
    assert margin == pytest.approx(90.0 - np.degrees(0.6), abs=0.2)


@pytest.mark.parametrize(
    ("crossover", "margin", "delay", "lag"),
    [(2.0, 40.0, 0.15, (14.0, 0.6)), (2.2, 35.0, 0.2, (10.0, 0.7)), (1.8, 30.0, 0.25, (8.0, 0.85))],
)
def test_the_two_point_design_has_its_crossover_and_margin(crossover, margin, delay, lag):
    params = two_point_for_crossover(crossover, margin, 0.4, 1.2, delay, *lag, name="x")
    measured = loop_margins(FREQUENCIES, two_point_loop(params))
    assert measured[0] == pytest.approx(crossover, rel=2e-3)
    assert measured[1] == pytest.approx(margin, abs=0.3)
    # N(s) = A1 (s + w_z)^2: a double real zero, A0^2 = 4 A1 AI
    a1 = params.near_gain + params.far_gain
    a0 = params.near_gain / 0.4 + params.far_gain / 1.2 + params.integral_gain
    ai = params.integral_gain / 0.4
    assert a0**2 == pytest.approx(4.0 * a1 * ai, rel=1e-9) and a0 > 0 and ai > 0
    # the delay-free design of "paper" at the same loop speed has far less margin
    old = TwoPointParams.from_loop(1.1, 0.6, 0.3, 0.4, 1.2, delay=delay,
                                   neuromuscular_frequency=lag[0], neuromuscular_damping=lag[1])  # fmt: skip
    assert loop_margins(FREQUENCIES, two_point_loop(old))[1] < margin


def test_an_unreachable_margin_is_refused_with_the_bound():
    with pytest.raises(ValueError, match="phase_margin 45 deg .* not reachable .* allowed: below"):
        two_point_for_crossover(2.5, 45.0, 0.4, 1.2, 0.25, 8.0, 0.85)
    with pytest.raises(ValueError, match="crossover must be"):
        two_point_for_crossover(10.0, 45.0, 0.4, 1.2, 0.2, 10.0, 0.7)


def test_feedback_gains_are_those_of_the_full_preview_design():
    for cost in (PreviewCost(), PreviewCost.from_bandwidth(1.3, 30.0, preview_time=1.5)):
        np.testing.assert_allclose(feedback_gains(cost), preview_gains(cost)[:3], rtol=1e-9)


def test_the_preview_design_has_its_margin():
    cost = preview_cost_for_margin(28.0, 30.0, 0.2, 10.0, 0.7, preview_time=1.2)
    crossover, margin = loop_margins(FREQUENCIES, preview_loop(cost, 0.2, 10.0, 0.7))
    assert margin == pytest.approx(28.0, abs=0.2) and crossover > 1.3


def test_paper_crossover_redesigns_the_paper_drivers_gains_only():
    for seed in (0, 1):
        base, new = population("paper", seed), population("paper-with-delay", seed)
        assert population("paper-with-delay", seed) == new  # seeded, regenerable
        targets = POPULATIONS["paper-with-delay"].loop_targets
        for a, b in zip(base, new, strict=True):
            assert type(a) is type(b) and a.name == b.name
            assert (a.delay, a.motor, a.speed) == (b.delay, b.motor, b.speed)
            if isinstance(b, TwoPointParams):
                assert b.speed_exponent == 1.0 and b.far_gain != a.far_gain
                crossover, margin = loop_margins(FREQUENCIES, two_point_loop(b))
                assert crossover <= targets.crossover.high + 1e-6
                assert targets.phase_margin.low - 0.3 <= margin <= targets.phase_margin.high + 0.3
                same = dataclasses.replace(
                    b, near_gain=a.near_gain, far_gain=a.far_gain,
                    integral_gain=a.integral_gain, speed_exponent=a.speed_exponent,
                )  # fmt: skip
                assert same == a
            else:
                assert b.cost != a.cost and b.cost.preview_time == a.cost.preview_time
                args = (b.delay, b.neuromuscular_frequency, b.neuromuscular_damping)
                margin = loop_margins(FREQUENCIES, preview_loop(b.cost, *args))[1]
                low, high = targets.preview_phase_margin.low, targets.preview_phase_margin.high
                assert low - 0.3 <= margin <= high + 0.3


def test_paper_crossover_drivers_keep_their_lane_on_a_short_run():
    drivers = population("paper-with-delay", seed=3)
    env = dict(POPULATIONS["paper-with-delay"].env_config) | {"time_limit": 8.0}
    runs = run_population(drivers, runs=1, seed=0, config=env)
    for p in drivers:
        frame = runs[p.name][0]
        assert not frame["terminated"].any(), p.name
        assert frame["lateral_offset"].abs().max() < 1.0, p.name
