"""Vehicle dynamics, sensors and reward as pure functions.

One implementation serves the single env (Python floats, fast for one car)
and the vector env (numpy arrays of N cars): every function takes an ``ops``
backend, :data:`SCALAR_OPS` or :data:`ARRAY_OPS`, and uses only arithmetic,
``sin``, ``cos``, ``sqrt``, ``minimum`` and ``maximum``, which give
bit-identical results in both backends (numpy's and libm's sin/cos/sqrt agree
to the last bit on float64; tan and atan2 do not, so they are avoided).

Kinematic bicycle about the rear axle (paper eq. (1)) in Frenet coordinates on
a road of curvature kappa(s) (docs/design.md §4.1-4.2)::

    s'     = v cos(theta) / (1 - kappa(s) y)
    y'     = v sin(theta)
    theta' = v tan(delta) / L - kappa(s) s'
    v'     = a            (saturated to [0, v_max])

integrated over one sample Ts with classical RK4 (delta and a held constant,
v(t) integrated exactly). On a straight road the error is below 1e-12 m per
step at 100 Hz (tests/test_dynamics.py checks against the closed-form arc).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Generic, NamedTuple, TypeVar

import numpy as np

__all__ = [
    "VehicleParams",
    "VehicleState",
    "SCALAR_OPS",
    "ARRAY_OPS",
    "step_vehicle",
    "road_frame_velocity",
    "road_frame_acceleration",
    "mean_road_frame_acceleration",
    "lane_keeping_reward",
    "left_road",
]


_HALF_PI = 0.5 * math.pi
_FADE_SPEED_SQ = 25.0  # (5 m/s)^2: below 5 m/s a lateral disturbance fades out


def _where(cond, a, b):  # noqa: ANN001 - scalar backend helper
    return a if cond else b


SCALAR_OPS = SimpleNamespace(
    sin=math.sin, cos=math.cos, sqrt=math.sqrt, abs=abs, minimum=min, maximum=max, where=_where
)
"""Backend for one car: Python floats and the math module."""

ARRAY_OPS = SimpleNamespace(
    sin=np.sin,
    cos=np.cos,
    sqrt=np.sqrt,
    abs=np.abs,
    minimum=np.minimum,
    maximum=np.maximum,
    where=np.where,
)
"""Backend for N cars: float64 arrays of shape (N,)."""


@dataclass(frozen=True)
class VehicleParams:
    """Parameters of the kinematic bicycle.

    Attributes:
        wheelbase: L (m).
        max_speed: speed saturation (m/s); speed is also kept >= 0.
        dt: sample time Ts (s).
    """

    wheelbase: float = 2.8
    max_speed: float = 60.0
    dt: float = 0.01


StateValue = TypeVar("StateValue", float, np.ndarray)
"""A state field's type: a float for one car, an (N,) array for N cars."""


class VehicleState(NamedTuple, Generic[StateValue]):
    """Frenet state of the car (each field a float, or an array of N cars:
    ``VehicleState[float]``, ``VehicleState[np.ndarray]``).

    Attributes:
        station: s, arc length along the lane centre (m).
        lateral_offset: y, rear-axle offset from the true lane centre (m, left +).
        heading: theta, yaw relative to the road tangent (rad, counter-clockwise +).
        speed: v (m/s).
        steering: delta, road-wheel angle in effect (rad, left +).
    """

    station: StateValue
    lateral_offset: StateValue
    heading: StateValue
    speed: StateValue
    steering: StateValue


def step_vehicle(
    state: VehicleState,
    steering: float | np.ndarray,
    acceleration: float | np.ndarray,
    params: VehicleParams,
    curvature: Callable,
    ops: SimpleNamespace,
    lateral_disturbance: float | np.ndarray | None = None,
) -> VehicleState:
    """Advance the car by one sample Ts with steering delta and acceleration a held.

    Args:
        state: the state at t.
        steering: road-wheel angle delta (rad) applied over the sample.
        acceleration: a (m/s^2) applied over the sample.
        params: vehicle parameters (L, v_max, Ts).
        curvature: kappa(s) (1/m) of the road, for the backend's type; a
            function with the attribute ``is_zero = True`` marks a straight road.
        ops: :data:`SCALAR_OPS` or :data:`ARRAY_OPS`.
        lateral_disturbance: a_d (m/s^2), a lateral acceleration the road and
            the wind put on the car over the sample (crosswind, camber:
            :mod:`hasa_env.sim.disturbance`), or None. A kinematic car turns
            it into a yaw rate ``r_d = a_d v / max(v^2, v_fade^2)`` (v at the
            sample's midpoint, v_fade = 5 m/s), so that its lateral
            acceleration is ``a_d`` at speed and it fades to 0 at a standstill.

    Returns:
        The state at t + Ts (``steering`` field = the applied delta).
    """
    h = params.dt
    v_max = params.max_speed
    yaw_gain = ops.sin(steering) / ops.cos(steering) / params.wheelbase  # tan(delta) / L
    v0 = state.speed
    v_half = ops.minimum(ops.maximum(v0 + acceleration * (0.5 * h), 0.0), v_max)
    v1 = ops.minimum(ops.maximum(v0 + acceleration * h, 0.0), v_max)

    if lateral_disturbance is not None:
        r_d = lateral_disturbance * v_half / ops.maximum(v_half * v_half, _FADE_SPEED_SQ)
        straight = getattr(curvature, "is_zero", False)

        def deriv(s, y, th, v):  # noqa: ANN001, ANN202
            k = 0.0 if straight else curvature(s)
            s_dot = v * ops.cos(th) / (1.0 - k * y)
            return s_dot, v * ops.sin(th), v * yaw_gain + r_d - k * s_dot

    elif getattr(curvature, "is_zero", False):
        # straight road: the curvature terms vanish exactly (x / 1.0 and x - 0.0 * y
        # are exact), so this shortcut gives the same bits as the general form
        def deriv(s, y, th, v):  # noqa: ANN001, ANN202
            return v * ops.cos(th), v * ops.sin(th), v * yaw_gain

    else:

        def deriv(s, y, th, v):  # noqa: ANN001, ANN202
            k = curvature(s)
            s_dot = v * ops.cos(th) / (1.0 - k * y)
            return s_dot, v * ops.sin(th), v * yaw_gain - k * s_dot

    s, y, th = state.station, state.lateral_offset, state.heading
    k1s, k1y, k1t = deriv(s, y, th, v0)
    k2s, k2y, k2t = deriv(s + 0.5 * h * k1s, y + 0.5 * h * k1y, th + 0.5 * h * k1t, v_half)
    k3s, k3y, k3t = deriv(s + 0.5 * h * k2s, y + 0.5 * h * k2y, th + 0.5 * h * k2t, v_half)
    k4s, k4y, k4t = deriv(s + h * k3s, y + h * k3y, th + h * k3t, v1)
    c = h / 6.0
    return VehicleState(
        s + c * (k1s + 2.0 * k2s + 2.0 * k3s + k4s),
        y + c * (k1y + 2.0 * k2y + 2.0 * k3y + k4y),
        th + c * (k1t + 2.0 * k2t + 2.0 * k3t + k4t),
        v1,
        steering,
    )


def road_frame_velocity(state: VehicleState, ops: SimpleNamespace) -> tuple:
    """Road-frame velocity (v_x, v_y) = (v cos theta, v sin theta) (m/s); v_y = dy/dt."""
    return state.speed * ops.cos(state.heading), state.speed * ops.sin(state.heading)


def mean_road_frame_acceleration(
    start_velocity: tuple, end_velocity: tuple, interval: float
) -> tuple:
    """Road-frame acceleration (m/s^2) averaged over ``interval`` s.

    What the IMU reports at each observation: the change of the road-frame
    velocity (v_x, v_y) (see :func:`road_frame_velocity`) since the previous
    observation divided by the time between them, i.e. exactly the input of
    the paper's discrete model (eq. (4), docs/design.md §4.4) at the observation rate.
    """
    return (
        (end_velocity[0] - start_velocity[0]) / interval,
        (end_velocity[1] - start_velocity[1]) / interval,
    )


def road_frame_acceleration(
    state: VehicleState,
    acceleration: float | np.ndarray,
    curvature: float | np.ndarray,
    params: VehicleParams,
    ops: SimpleNamespace,
) -> tuple:
    """Instantaneous road-frame acceleration (d v_x/dt, d v_y/dt) (m/s^2), paper eq. (2) (docs/design.md §4.4).

    With theta' = v tan(delta)/L - kappa s': x'' = a cos(theta) - v sin(theta) theta',
    y'' = a sin(theta) + v cos(theta) theta'.
    """
    v, th = state.speed, state.heading
    cos_t, sin_t = ops.cos(th), ops.sin(th)
    s_dot = v * cos_t / (1.0 - curvature * state.lateral_offset)
    yaw_rate = (
        v * ops.sin(state.steering) / ops.cos(state.steering) / params.wheelbase - curvature * s_dot
    )
    return acceleration * cos_t - v * sin_t * yaw_rate, acceleration * sin_t + v * cos_t * yaw_rate


def left_road(
    state: VehicleState, lower: float, upper: float, ops: SimpleNamespace
) -> bool | np.ndarray:
    """True when the car is off the road (y outside [lower, upper]) or faces backwards.

    ``|`` is the same operator on Python bools and numpy bool arrays, so one
    expression serves both backends.
    """
    y = state.lateral_offset
    return (y < lower) | (y > upper) | (ops.abs(state.heading) > _HALF_PI)


def lane_keeping_reward(
    lateral_offset: float | np.ndarray,
    steering_change: float | np.ndarray,
    terminated: bool | np.ndarray,
    half_lane: float,
    max_steering: float,
    lateral_weight: float,
    steering_rate_weight: float,
    offroad_penalty: float,
) -> float | np.ndarray:
    """Reward of one env step.

    ``1 - w_y (y / (W/2))^2 - w_d (d_delta / delta_max)^2 - penalty * terminated``:
    1 at the lane centre with steady steering, 0 at the lane edge, and a
    one-off penalty for leaving the road.
    """
    ey = lateral_offset / half_lane
    ed = steering_change / max_steering
    return (
        1.0
        - lateral_weight * ey * ey
        - steering_rate_weight * ed * ed
        - offroad_penalty * terminated
    )
