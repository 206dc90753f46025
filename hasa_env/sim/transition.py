"""The env transition: one pure function shared by the single and the vector env.

``env_step(state, velocity, steering, acceleration, setup, curvature, ops)``
advances one car (Python floats, :data:`~hasa_env.sim.dynamics.SCALAR_OPS`)
or N cars (float64 arrays, :data:`~hasa_env.sim.dynamics.ARRAY_OPS`) by one
env step of ``setup.action_repeat`` simulation samples with the physical
action held, and returns what the env reports about it::

    for each of the action_repeat samples, at time t_k:
        a_d = disturbance(t_k, s)                       crosswind + camber (m/s^2), if any
        x <- step_vehicle(x, delta, a, a_d)            RK4 over Ts (docs/design.md §4)
        off_road <- off_road or left_road(x)           checked at every sample
    (v_x, v_y) = (v cos theta, v sin theta)            road-frame velocity at the end
    imu = ((v_x, v_y) - (v_x, v_y)_start) / (action_repeat Ts)

The reward and the end of an episode are functions of the transition:
:func:`step_reward` (of the steering at the start of the env step and the outcome)
and ``Transition.off_road`` (terminated); :func:`hasa_env.sim.car.truncated` says when
the time is up. The advisor task steps ``env_step`` one sample at a time and takes the
reward of the whole env step from the same function.

Sensor noise is not part of it: each env draws its noise rows from its
cars' own generators (blocks, :func:`hasa_env.sim.setup.draw_noise_block`)
and passes them to :func:`hasa_env.sim.sensors.sensor_readings` (:mod:`hasa_env.sim.car`), so the
transition is a function of its arguments only, bit-identical for both
backends (tested by ``tests/test_vector.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace
from typing import Any, NamedTuple

from hasa_env.sim.dynamics import (
    VehicleState,
    lane_keeping_reward,
    left_road,
    mean_road_frame_acceleration,
    road_frame_velocity,
    step_vehicle,
)
from hasa_env.sim.setup import EnvSetup

__all__ = ["Transition", "env_step", "step_reward"]


class Transition(NamedTuple):
    """The outcome of :func:`env_step` (floats for one car, (N,) arrays for N).

    Attributes:
        state: the car's state at the end of the env step.
        velocity: road-frame (v_x, v_y) at the end (m/s).
        imu: mean road-frame acceleration (x'', y'') over the step (m/s^2),
            what the IMU reports before noise.
        off_road: the car left the road (or turned backwards) at any sample: the
            episode is terminated.
    """

    state: VehicleState
    velocity: tuple[Any, Any]
    imu: tuple[Any, Any]
    off_road: Any


def env_step(
    state: VehicleState,
    velocity: tuple[Any, Any],
    steering: Any,
    acceleration: Any,
    setup: EnvSetup,
    curvature: Callable[[Any], Any],
    ops: SimpleNamespace,
    sim_step: Any = 0,
    phases: Any = (),
) -> Transition:
    """Advance by one env step (see the module docstring).

    Args:
        state: the state at the start of the step.
        velocity: road-frame (v_x, v_y) at the start (m/s), from the previous step.
        steering: road-wheel angle delta (rad), already validated and clipped.
        acceleration: a (m/s^2), already validated and clipped.
        setup: the env's set-up (vehicle parameters, road edges, reward weights, rates).
        curvature: kappa(s) of the road for this backend (:meth:`EnvSetup.curvature_scalar`
            or :meth:`EnvSetup.curvature_array`).
        ops: :data:`~hasa_env.sim.dynamics.SCALAR_OPS` or :data:`~hasa_env.sim.dynamics.ARRAY_OPS`.
        sim_step: simulation samples since the episode started (the disturbance's clock).
        phases: the episode's disturbance phases (unused without a disturbance).
    """
    params = setup.params
    lower, upper = setup.lower_edge, setup.upper_edge
    disturbance = setup.disturbance
    off_road = None
    for i in range(setup.action_repeat):
        a_d = None
        if disturbance is not None:
            a_d = disturbance.lateral_acceleration(
                (sim_step + i) * params.dt, state.station, phases, ops
            )
        state = step_vehicle(state, steering, acceleration, params, curvature, ops, a_d)
        left = left_road(state, lower, upper, ops)
        off_road = left if off_road is None else off_road | left
    assert off_road is not None  # (action_repeat >= 1)
    end_velocity = road_frame_velocity(state, ops)
    imu = mean_road_frame_acceleration(velocity, end_velocity, setup.env_step_duration)
    return Transition(state, end_velocity, imu, off_road)


def step_reward(setup: EnvSetup, start_steering: Any, state: VehicleState, off_road: Any) -> Any:
    """The reward of an env step (floats for one car, arrays for N)::

        reward = 1 - w_y (y / (W/2))^2 - w_d ((delta - delta_start) / delta_max)^2
                 - offroad_penalty * off_road

    with y and delta of ``state``, the state at the end of the step, delta_start the
    steering at its start and ``off_road`` whether the car left the road during it
    (``Transition.off_road``).
    """
    lateral_weight, rate_weight, penalty = setup.reward_weights
    return lane_keeping_reward(
        state.lateral_offset,
        state.steering - start_steering,
        off_road,
        0.5 * setup.road.lane_width,
        setup.steering_limit,
        lateral_weight,
        rate_weight,
        penalty,
    )
