"""The car's sensors, in one table: what each reads, its noise and its bounds.

Every env, the recordings, the advisor task and the exports take their sensor
channels from here (:data:`SENSOR_NAMES`, the ``sensor_<name>`` info keys and
recording columns, the ``"sensors"`` observation), so a new sensor is a field of
:class:`Sensors`, its line in :func:`sensor_readings`, its unit and noise key in
:data:`SENSOR_UNITS` and :data:`SENSOR_NOISE_KEYS` and its bounds in
:func:`sensor_bounds` (plus the
observation table of the env's docstring and its tests).

Each reading is the true quantity plus Gaussian noise (docs/design.md §3.6)::

    speed            = v + sigma_speed n_0                     (m/s)
    camera_lateral   = y + b + sigma_camera n_1                (m; b the camera bias)
    camera_heading   = theta + sigma_camera_heading n_2        (rad)
    imu_longitudinal = mean x'' over the step + sigma_imu n_3  (m/s^2, road frame)
    imu_lateral      = mean y'' over the step + sigma_imu n_4  (m/s^2, road frame)
    steering         = delta + sigma_steering n_5              (rad, road wheel)

with n_k standard-normal draws from the car's noise block.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from hasa_env.sim.dynamics import VehicleParams, VehicleState

__all__ = [
    "SENSOR_NAMES",
    "SENSOR_NOISE_KEYS",
    "SENSOR_UNITS",
    "Sensors",
    "sensor_bounds",
    "sensor_readings",
]


class Sensors(NamedTuple):
    """One value per sensor channel (floats for one car, (N,) arrays for N cars).

    Attributes:
        speed: speedometer, v + noise (m/s).
        camera_lateral: the camera's lateral offset, y + b + noise (m): biased by the
            unknown lane-marking bias b.
        camera_heading: the camera's heading to the markings, theta + noise (rad).
        imu_longitudinal: road-frame x'' averaged over the step, + noise (m/s^2).
        imu_lateral: road-frame y'' averaged over the step, + noise (m/s^2).
        steering: the steering sensor, road-wheel angle delta + noise (rad).
    """

    speed: Any
    camera_lateral: Any
    camera_heading: Any
    imu_longitudinal: Any
    imu_lateral: Any
    steering: Any


_new_sensors = tuple.__new__

SENSOR_NAMES: tuple[str, ...] = Sensors._fields
"""Sensor channels, in observation order (their units: :data:`SENSOR_UNITS`)."""

SENSOR_UNITS = Sensors("m/s", "m", "rad", "m/s^2", "m/s^2", "rad")
"""Each channel's unit (SI)."""

SENSOR_NOISE_KEYS = Sensors("speed", "camera", "camera_heading", "imu", "imu", "steering")
"""The ``config["noise"]`` key holding each channel's noise standard deviation."""


def sensor_bounds(max_speed: float, steering_limit: float) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of the ``"sensors"`` observation, float32; readings saturate there.

    Args:
        max_speed: the car's top speed (m/s).
        steering_limit: the largest road-wheel angle (rad).
    """
    low = Sensors(-10.0, -50.0, -math.pi, -200.0, -200.0, -(steering_limit + 1.0))
    high = Sensors(max_speed + 10.0, 50.0, math.pi, 200.0, 200.0, steering_limit + 1.0)
    return np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)


def sensor_readings(
    state: VehicleState,
    imu: tuple[Any, Any],
    bias: Any,
    noise: Any,
    noise_std: Sensors,
    params: VehicleParams,
) -> Sensors:
    """Noisy sensor readings (the module docstring's equations).

    Args:
        state: true state (floats, or (N,) arrays).
        imu: true road-frame accelerations (x'', y'') (m/s^2).
        bias: camera bias b (m): the camera reads y + b.
        noise: one standard-normal draw per channel (a sequence of floats, or of (N,) arrays).
        noise_std: each channel's noise standard deviation.
        params: the vehicle's parameters (for sensors that read through them, e.g. a
            yaw rate v tan(delta) / L; none of the six does).
    """
    return _new_sensors(  # the NamedTuple's own __new__, without its Python frame
        Sensors,
        (
            state.speed + noise_std[0] * noise[0],
            state.lateral_offset + bias + noise_std[1] * noise[1],
            state.heading + noise_std[2] * noise[2],
            imu[0] + noise_std[3] * noise[3],
            imu[1] + noise_std[4] * noise[4],
            state.steering + noise_std[5] * noise[5],
        ),
    )
