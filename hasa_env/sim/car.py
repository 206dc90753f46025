"""The car core: one record of a car during an episode, and the functions every env uses.

The plain lane-keeping env, its vector twin and both envs of the advisor task are thin
shells around this module, in the style of Gymnasium's functional envs and gymnax
(initial state, transition, observation, reward, terminal):

| step        | one car (floats)                      | N cars (arrays)                              |
|-------------|---------------------------------------|----------------------------------------------|
| initial     | :func:`start_car`                     | :func:`empty_cars`, :func:`start_cars`       |
| transition  | :func:`~hasa_env.sim.transition.env_step`, then :func:`advance_car` | the same, then :func:`advance_cars` |
| observation | :func:`state_values`, :class:`~hasa_env.sim.sensors.Sensors` | the same                |
| info        | :func:`car_info_values`               | the same                                     |
| reward      | :func:`~hasa_env.sim.transition.step_reward` | the same                              |
| terminal    | ``Transition.off_road``; truncated: :func:`truncated` | the same                     |

:class:`Car` holds what changes during an episode: the true state, the road-frame
velocity, the applied acceleration, the road curvature at the car, the camera bias
and its hypothesis index, the simulation-sample counter, the disturbance phases, the
sensor readings (named fields, :class:`~hasa_env.sim.sensors.Sensors`) and the noise
cursor (the car's current block of standard-normal draws and the next row of it).
Randomness comes only from the generator passed in (one per car), in a fixed order:
the episode's draws (:func:`hasa_env.sim.setup.draw_episode`), then, whenever a block
is used up, the next block (:func:`hasa_env.sim.setup.draw_noise_block`). So car ``i``
of N, with its own generator, is the single car bit for bit (``tests/test_vector.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from hasa_env.sim.dynamics import (
    ARRAY_OPS,
    SCALAR_OPS,
    VehicleState,
    road_frame_acceleration,
    road_frame_velocity,
)
from hasa_env.sim.sensors import Sensors, sensor_readings
from hasa_env.sim.setup import EnvSetup, draw_episode, draw_noise_block
from hasa_env.sim.transition import Transition

__all__ = [
    "Car",
    "advance_car",
    "advance_cars",
    "car_info_values",
    "empty_cars",
    "start_car",
    "start_cars",
    "state_values",
    "truncated",
]

T = TypeVar("T", float, np.ndarray)


@dataclass(slots=True, eq=False)
class Car(Generic[T]):
    """A car during an episode: floats for one car, (N,) arrays for N cars.

    Attributes:
        state: the true Frenet state.
        velocity: road-frame (v_x, v_y) of ``state`` (m/s).
        acceleration: the acceleration applied over the last step (m/s^2; 0 at reset).
        curvature: road curvature at the car's station (1/m).
        bias: the camera bias b of this episode (m).
        bias_index: its index in ``markings.hypotheses`` (-1: a bias given as a reset
            option that is none of them).
        sim_step: simulation samples since the episode started (the time is
            ``sim_step * Ts``).
        phases: the disturbance's phases this episode (rad; a list for one car, an
            (N, n_phases) array for N).
        sensors: the readings at the last sample.
        noise: the current block of standard-normal sensor noise (one car: a list of
            rows; N cars: an (N, block, channels) array).
        noise_pos: the next row of ``noise`` to use (per car for N).
    """

    state: VehicleState[T]
    velocity: tuple[T, T]
    acceleration: T
    curvature: T
    bias: T
    bias_index: Any
    sim_step: Any
    phases: Any
    sensors: Sensors
    noise: Any
    noise_pos: Any


# ---------------------------------------------------------------------------- one car
def start_car(
    rng: np.random.Generator,
    setup: EnvSetup,
    options: Any,
    curvature: Callable[[float], float],
) -> Car[float]:
    """A new episode's car: the episode drawn from ``rng`` and its first sensor sample.

    The first sample's IMU is the instantaneous road-frame acceleration at zero
    acceleration (there is no previous step to average over).
    """
    state, index, bias, block, phases = draw_episode(rng, setup, options)
    car: Car[float] = Car(
        state=state,
        velocity=road_frame_velocity(state, SCALAR_OPS),
        acceleration=0.0,
        curvature=0.0,
        bias=bias,
        bias_index=index,
        sim_step=0,
        phases=phases,
        sensors=_NO_READINGS,
        noise=block.tolist(),
        noise_pos=0,
    )
    kappa = curvature(state.station)
    imu = road_frame_acceleration(state, 0.0, kappa, setup.params, SCALAR_OPS)
    _read_sensors(car, rng, setup, imu, kappa)
    return car


def advance_car(
    car: Car[float],
    outcome: Transition,
    acceleration: float,
    samples: int,
    rng: np.random.Generator,
    setup: EnvSetup,
    curvature: Callable[[float], float],
) -> None:
    """Take the outcome of :func:`~hasa_env.sim.transition.env_step` (``samples``
    simulation samples long, ``acceleration`` applied) into ``car`` and read its sensors."""
    state = car.state = outcome.state
    car.velocity = outcome.velocity
    car.sim_step += samples
    car.acceleration = acceleration
    _read_sensors(car, rng, setup, outcome.imu, curvature(state.station))


def _read_sensors(
    car: Car[float],
    rng: np.random.Generator,
    setup: EnvSetup,
    imu: tuple[float, float],
    kappa: float,
) -> None:
    """The car's sensors at this sample, with the next row of its noise block."""
    if car.noise_pos >= len(car.noise):
        car.noise, car.noise_pos = draw_noise_block(rng, setup).tolist(), 0
    noise = car.noise[car.noise_pos]
    car.noise_pos += 1
    car.curvature = kappa
    car.sensors = sensor_readings(car.state, imu, car.bias, noise, setup.noise_std, setup.params)


_NO_READINGS = Sensors(*(0.0 for _ in Sensors._fields))


# ----------------------------------------------------------------------------- N cars
def empty_cars(num_cars: int, setup: EnvSetup) -> Car[np.ndarray]:
    """N cars before their first episode (zeros), to be started with :func:`start_cars`."""
    n = num_cars
    n_phases = setup.disturbance.n_phases if setup.disturbance is not None else 0
    channels = len(setup.noise_std)
    return Car(
        state=VehicleState(*(np.zeros(n) for _ in VehicleState._fields)),
        velocity=(np.zeros(n), np.zeros(n)),
        acceleration=np.zeros(n),
        curvature=np.zeros(n),
        bias=np.zeros(n),
        bias_index=np.zeros(n, dtype=np.int64),
        sim_step=np.zeros(n, dtype=np.int64),
        phases=np.zeros((n, n_phases)),
        sensors=Sensors(*np.zeros((channels, n))),
        noise=np.zeros((n, setup.noise_block, channels)),
        noise_pos=np.zeros(n, dtype=np.int64),
    )


def start_cars(
    cars: Car[np.ndarray],
    idx: np.ndarray,
    rngs: Sequence[np.random.Generator],
    setup: EnvSetup,
    options: Any,
    curvature: Callable[[np.ndarray], Any],
) -> None:
    """New episodes for the cars ``idx`` (each from its own generator ``rngs[i]``) and
    their first sensor sample, as :func:`start_car` for each; the other cars keep theirs."""
    fields = [f.copy() for f in cars.state]
    for i in idx.tolist():
        start, index, bias, block, phases = draw_episode(rngs[i], setup, options)
        if phases:
            cars.phases[i] = phases
        for f, value in zip(fields, start, strict=True):
            f[i] = value
        cars.bias[i], cars.bias_index[i] = bias, index
        cars.noise[i] = block
        cars.sim_step[i] = 0
        cars.acceleration[i] = 0.0
    cars.state = VehicleState(*fields)
    start_state = VehicleState(*(f[idx] for f in fields))
    velocity = road_frame_velocity(start_state, ARRAY_OPS)
    cars.velocity[0][idx], cars.velocity[1][idx] = velocity
    kappa = _broadcast(curvature(start_state.station), idx.shape)
    imu = road_frame_acceleration(start_state, 0.0, kappa, setup.params, ARRAY_OPS)
    noise = cars.noise[idx, 0]  # the new blocks' first rows
    cars.noise_pos[idx] = 1
    readings = sensor_readings(
        start_state, imu, cars.bias[idx], noise.T, setup.noise_std, setup.params
    )
    cars.curvature[idx] = kappa
    for channel, reading in zip(cars.sensors, readings, strict=True):
        channel[idx] = reading


def advance_cars(
    cars: Car[np.ndarray],
    outcome: Transition,
    acceleration: Any,
    samples: int,
    rngs: Sequence[np.random.Generator],
    setup: EnvSetup,
    curvature: Callable[[np.ndarray], Any],
    skip: np.ndarray,
) -> None:
    """Take the outcome of :func:`~hasa_env.sim.transition.env_step` into every car and
    read their sensors, as :func:`advance_car` for each.

    Cars in ``skip`` (about to be reset, which draws them a new block) draw nothing
    from their generators; their readings here are placeholders.
    """
    state = cars.state = VehicleState(*(np.asarray(f, dtype=np.float64) for f in outcome.state))
    cars.velocity = outcome.velocity
    cars.sim_step += samples
    cars.acceleration = np.asarray(acceleration, dtype=np.float64)
    block = setup.noise_block
    pos = cars.noise_pos
    if pos.max() >= block:
        for i in np.flatnonzero((pos >= block) & ~skip).tolist():
            cars.noise[i] = draw_noise_block(rngs[i], setup)
            pos[i] = 0
        pos = np.minimum(pos, block - 1)  # skipped cars: any row, overwritten at reset
    n = len(pos)
    noise = cars.noise.reshape(-1, cars.noise.shape[2])[np.arange(n) * block + pos]
    cars.noise_pos += 1
    readings = sensor_readings(
        state, outcome.imu, cars.bias, noise.T, setup.noise_std, setup.params
    )
    cars.curvature = np.array(_broadcast(curvature(state.station), state.station.shape))
    for channel, reading in zip(cars.sensors, readings, strict=True):
        channel[:] = reading


def _broadcast(kappa: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Curvature values (an array, or 0.0 on a straight road) as a float64 array of ``shape``."""
    return np.broadcast_to(np.asarray(kappa, dtype=np.float64), shape)


# ----------------------------------------------------------------- shared read-outs
def state_values(car: Car) -> tuple[Any, Any, Any, Any, Any]:
    """The ``"state"`` (oracle) observation's values: y, theta, v, delta, kappa."""
    s = car.state
    return (s.lateral_offset, s.heading, s.speed, s.steering, car.curvature)


def car_info_values(car: Car, setup: EnvSetup) -> tuple:
    """The values of ``info`` in :data:`hasa_env.sim.setup.INFO_KEYS` order."""
    state = car.state
    vx, vy = car.velocity
    return (
        car.sim_step * setup.dt,
        state.station,
        state.lateral_offset,
        state.heading,
        state.speed,
        state.steering,
        car.acceleration,
        car.curvature,
        vx,
        vy,
        car.bias,
        car.bias_index,
        *car.sensors,
    )


def truncated(car: Car, setup: EnvSetup) -> Any:
    """The episode's time is up: ``sim_step`` reached ``time_limit * sim_frequency``."""
    return car.sim_step >= setup.max_sim_steps
