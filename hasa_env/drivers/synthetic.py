"""Synthetic human drivers and seeded populations of them (DESIGN.md section 4).

The paper's fitted models are one-step predictors, not drivers (in closed
loop the generalized one only stabilises the car at Ts <= 0.02 s, the
two-point one barely). A synthetic human instead combines:

1. Perception: the near- and far-point bearings phi, omega (rad) of the true
   lane centre at look-ahead *times* (``near_time`` ~0.4 s,
   ``far_time`` ~0.9-1.5 s: distances v * time, so the loop stays stable up
   to 45 m/s), computed exactly on curved roads.
2. A sensorimotor delay of ``delay`` s (0.15-0.25): the controller sees the
   bearings of that long ago.
3. Two-point PI control (Salvucci & Gray, velocity form; paper eq. 10 with
   DESIGN.md's corrected signs) on the delayed bearings::

       u(k) = u(k-1) + g(v) [k_f (omega(k) - omega(k-1)) + k_n (phi(k) - phi(k-1)) + k_I Ts phi(k)]

   with gains that adapt to speed, g(v) = (v_ref / v) ** speed_exponent
   (exponent ~1 keeps the lateral closed loop the same at every speed: the
   plant's gain from steering to lateral acceleration grows as v^2).
4. Motor noise on the command: white, or an Ornstein-Uhlenbeck process with
   time constant 0.2-0.4 s, scaled by g(v)^2: signal-dependent noise,
   proportional to the steering a given lateral acceleration needs (~1/v^2),
   so the lateral wander it causes is about the same at every speed.
5. A second-order neuromuscular lag (natural frequency 8-14 rad/s,
   damping 0.6-0.85) from the command to the road-wheel angle, discretised
   exactly (zero-order hold).
6. A speed behaviour (:class:`~hasa_env.drivers.base.SpeedProfile`): hold
   15 m/s, or ramps reaching up to 45 m/s; slowing for bends on curved roads.

:meth:`DriverParams.from_loop` chooses the three gains from a desired
lateral closed loop (bandwidth, damping, integral share) instead of by hand;
:func:`population` draws a seeded list of drivers ("Ill", "1", ..., "8" by
default) that anyone can regenerate by name and seed.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from scipy.linalg import expm

from hasa_env.drivers.base import SpeedProfile, _profile_arrays, info_arrays, speed_command
from hasa_env.sim.road import Road, lane_centre_bearing

__all__ = ["DriverParams", "SyntheticDriver", "SyntheticBatch", "population", "POPULATIONS"]

_NOISE_BLOCK = 1000
_MIN_SPEED = 1.0  # m/s; below it gains and look-ahead distances stop scaling


@dataclass(frozen=True)
class DriverParams:
    """Parameters of one synthetic driver (SI units, radians).

    Attributes:
        name: label ("Ill", "1", ...).
        near_time: look-ahead time of the near point (s); distance = v * near_time.
        far_time: look-ahead time of the far point (s).
        near_gain: k_n (rad/rad) at ``reference_speed``.
        far_gain: k_f (rad/rad) at ``reference_speed``.
        integral_gain: k_I (1/s) at ``reference_speed``.
        reference_speed: v_ref (m/s) of the gains.
        speed_exponent: gains scale as (v_ref / v) ** speed_exponent.
        delay: sensorimotor delay (s).
        neuromuscular_frequency: omega_n (rad/s) of the lag.
        neuromuscular_damping: zeta of the lag.
        noise_std: motor-noise standard deviation at v_ref (rad of command);
            it scales as g(v)^2.
        noise_time_constant: OU time constant (s); 0 = white noise.
        speed: the speed behaviour.
        max_steering: command saturation (rad), the env's default limit.
    """

    name: str = "driver"
    near_time: float = 0.4
    far_time: float = 1.2
    near_gain: float = 0.05
    far_gain: float = 0.3
    integral_gain: float = 0.1
    reference_speed: float = 15.0
    speed_exponent: float = 1.0
    delay: float = 0.2
    neuromuscular_frequency: float = 10.0
    neuromuscular_damping: float = 0.7
    noise_std: float = 0.0
    noise_time_constant: float = 0.3
    speed: SpeedProfile = field(default_factory=SpeedProfile)
    max_steering: float = 0.5

    def __post_init__(self) -> None:
        positive = ("near_time", "far_time", "reference_speed", "neuromuscular_frequency",
                    "neuromuscular_damping", "max_steering")  # fmt: skip
        for key in positive:
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(
                    f"DriverParams.{key} must be a finite positive number, got {value!r}"
                )
        for key in ("near_gain", "far_gain", "integral_gain", "speed_exponent"):
            if not math.isfinite(getattr(self, key)):
                raise ValueError(f"DriverParams.{key} must be finite, got {getattr(self, key)!r}")
        for key in ("delay", "noise_std", "noise_time_constant"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"DriverParams.{key} must be a finite number >= 0, got {value!r}")
        if not isinstance(self.speed, SpeedProfile):
            raise TypeError(
                f"DriverParams.speed must be a SpeedProfile, got {type(self.speed).__name__}"
            )

    @classmethod
    def from_loop(
        cls,
        bandwidth: float,
        damping: float,
        integral_share: float,
        near_time: float = 0.4,
        far_time: float = 1.2,
        wheelbase: float = 2.8,
        reference_speed: float = 15.0,
        **kwargs: Any,
    ) -> DriverParams:
        """Gains that give a chosen lateral closed loop (small angles, no delay or lag).

        With phi ~ -(v_y + y / t_n) / v, omega ~ -(v_y + y / t_f) / v and gains
        scaled by v_ref / v, the lateral offset obeys (for every speed)
        ``y''' + A1 y'' + A0 y' + AI y = 0`` with
        ``A1 = c (k_n + k_f)``, ``A0 = c (k_n / t_n + k_f / t_f + k_I)``,
        ``AI = c k_I / t_n``, ``c = v_ref / L``. The gains place its poles at
        ``(s + share * bandwidth)(s^2 + 2 damping bandwidth s + bandwidth^2)``.

        Args:
            bandwidth: natural frequency of the lateral loop (rad/s).
            damping: its damping ratio.
            integral_share: the integral pole as a fraction of the bandwidth.
            near_time, far_time: look-ahead times (s).
            wheelbase: L (m).
            reference_speed: v_ref (m/s).
            **kwargs: the other :class:`DriverParams` fields.
        """
        w, z, a = bandwidth, damping, integral_share
        c = reference_speed / wheelbase
        a1 = w * (2.0 * z + a)
        a0 = w * w * (1.0 + 2.0 * z * a)
        ai = a * w**3
        integral = ai * near_time / c
        # k_n + k_f = a1 / c ; k_n / t_n + k_f / t_f = a0 / c - k_I
        total = a1 / c
        weighted = a0 / c - integral
        near = (weighted - total / far_time) / (1.0 / near_time - 1.0 / far_time)
        far = total - near
        return cls(
            near_time=near_time,
            far_time=far_time,
            near_gain=near,
            far_gain=far,
            integral_gain=integral,
            reference_speed=reference_speed,
            **kwargs,
        )

    def with_speed(self, speed: SpeedProfile) -> DriverParams:
        """The same driver with another speed behaviour."""
        return replace(self, speed=speed)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict of the parameters."""
        out = asdict(self)
        out["speed"] = self.speed.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> DriverParams:
        """Inverse of :meth:`to_dict`."""
        values = dict(data)
        speed = values.pop("speed", {})
        return cls(**values, speed=SpeedProfile(**speed))


class SyntheticDriver:
    """A synthetic human driver (see the module docstring), seeded and reproducible.

    ``SyntheticDriver(params).reset(seed, dt=0.01)`` then ``act(info, road)``
    each env step. Runs are identical whether the driver acts alone or
    vectorized with others (:meth:`make_batch`).
    """

    def __init__(self, params: DriverParams) -> None:
        if not isinstance(params, DriverParams):
            raise TypeError(f"SyntheticDriver needs DriverParams, got {type(params).__name__}")
        self.params = params
        self.name = params.name
        self._batch: SyntheticBatch | None = None

    @classmethod
    def make_batch(cls, drivers: Sequence[SyntheticDriver]) -> SyntheticBatch:
        """A vectorized batch of these drivers (one car each)."""
        return SyntheticBatch([d.params for d in drivers])

    def reset(self, seed: int | None = None, *, dt: float = 0.01) -> None:
        self._batch = SyntheticBatch([self.params])
        self._batch.reset([seed], dt)

    def act(self, info: Mapping[str, Any], road: Road) -> tuple[float, float]:
        if self._batch is None:
            raise RuntimeError("call reset() before act()")
        steering, acceleration = self._batch.act(info_arrays(info, _INFO_NEEDED), road)
        return float(steering[0]), float(acceleration[0])

    def __repr__(self) -> str:
        return f"SyntheticDriver({self.params!r})"


_INFO_NEEDED = ("time", "station", "lateral_offset", "heading", "speed", "steering")


def _neuromuscular(frequency: float, damping: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of delta'' = w^2 (u - delta) - 2 z w delta'."""
    w, z = frequency, damping
    m = np.zeros((3, 3))
    m[0, 1] = 1.0
    m[1, 0] = -w * w
    m[1, 1] = -2.0 * z * w
    m[1, 2] = w * w
    e = expm(m * dt)
    return e[:2, :2], e[:2, 2]


class SyntheticBatch:
    """N synthetic drivers acting on N cars' info arrays (see :class:`SyntheticDriver`)."""

    def __init__(self, params: Sequence[DriverParams]) -> None:
        self.params = list(params)
        if not self.params:
            raise ValueError("SyntheticBatch needs at least one DriverParams")
        self.num_cars = len(self.params)
        p = self.params

        def arr(key: str) -> np.ndarray:
            return np.array([getattr(q, key) for q in p], dtype=np.float64)

        self.near_time, self.far_time = arr("near_time"), arr("far_time")
        self.near_gain, self.far_gain, self.integral_gain = (
            arr("near_gain"),
            arr("far_gain"),
            arr("integral_gain"),
        )
        self.reference_speed, self.speed_exponent = arr("reference_speed"), arr("speed_exponent")
        self.noise_std, self.noise_tau = arr("noise_std"), arr("noise_time_constant")
        self.max_steering = arr("max_steering")
        self.profile = _profile_arrays([q.speed for q in p])
        self._dt: float | None = None

    def reset(self, seeds: Sequence[int | None], dt: float) -> None:
        if len(seeds) != self.num_cars:
            raise ValueError(f"got {len(seeds)} seeds for {self.num_cars} drivers")
        if not dt > 0:
            raise ValueError(f"dt must be > 0 s, got {dt}")
        n = self.num_cars
        self._dt = float(dt)
        self._rngs = [np.random.default_rng(s) for s in seeds]
        self._noise_block = np.zeros((n, _NOISE_BLOCK))
        self._noise_pos = _NOISE_BLOCK
        self.delay_steps = np.array([round(q.delay / dt) for q in self.params], dtype=np.int64)
        self._ring = int(self.delay_steps.max()) + 1
        self._phi_buffer = np.zeros((n, self._ring))
        self._omega_buffer = np.zeros((n, self._ring))
        self._pos = 0
        nm = [
            _neuromuscular(q.neuromuscular_frequency, q.neuromuscular_damping, dt)
            for q in self.params
        ]
        ad = np.array([m[0] for m in nm])
        bd = np.array([m[1] for m in nm])
        self._a00, self._a01, self._a10, self._a11 = (
            ad[:, 0, 0],
            ad[:, 0, 1],
            ad[:, 1, 0],
            ad[:, 1, 1],
        )
        self._b0, self._b1 = bd[:, 0], bd[:, 1]
        with np.errstate(divide="ignore"):
            self._rho = np.where(
                self.noise_tau > 0, np.exp(-dt / np.maximum(self.noise_tau, 1e-300)), 0.0
            )
        self._innovation = self.noise_std * np.sqrt(1.0 - self._rho**2)
        self._fresh = True

    def _next_noise(self) -> np.ndarray:
        if self._noise_pos >= _NOISE_BLOCK:
            for i, rng in enumerate(self._rngs):
                self._noise_block[i] = rng.standard_normal(_NOISE_BLOCK)
            self._noise_pos = 0
        w = self._noise_block[:, self._noise_pos]
        self._noise_pos += 1
        return w

    def _bearings(
        self, info: Mapping[str, np.ndarray], road: Road
    ) -> tuple[np.ndarray, np.ndarray]:
        v = np.maximum(info["speed"], _MIN_SPEED)
        y, theta = info["lateral_offset"], info["heading"]
        near, far = v * self.near_time, v * self.far_time
        if road.is_straight:
            return -(theta + np.arctan(y / near)), -(theta + np.arctan(y / far))
        s = info["station"]
        return (
            np.asarray(lane_centre_bearing(road, s, y, theta, near), dtype=np.float64),
            np.asarray(lane_centre_bearing(road, s, y, theta, far), dtype=np.float64),
        )

    def act(self, info: Mapping[str, np.ndarray], road: Road) -> tuple[np.ndarray, np.ndarray]:
        if self._dt is None:
            raise RuntimeError("call reset() before act()")
        dt = self._dt
        phi, omega = self._bearings(info, road)
        if self._fresh:
            self._phi_buffer[:] = phi[:, None]
            self._omega_buffer[:] = omega[:, None]
            self._phi_prev, self._omega_prev = phi.copy(), omega.copy()
            start = np.asarray(info["steering"], dtype=np.float64)
            self._command = start.copy()
            self._nm_angle, self._nm_rate = start.copy(), np.zeros(self.num_cars)
            self._noise = np.zeros(self.num_cars)
            self._initial_speed = np.asarray(info["speed"], dtype=np.float64).copy()
            self._fresh = False
        rows = np.arange(self.num_cars)
        self._phi_buffer[:, self._pos] = phi
        self._omega_buffer[:, self._pos] = omega
        seen = (self._pos - self.delay_steps) % self._ring
        phi_seen, omega_seen = self._phi_buffer[rows, seen], self._omega_buffer[rows, seen]
        self._pos = (self._pos + 1) % self._ring
        v = np.maximum(info["speed"], _MIN_SPEED)
        scale = (self.reference_speed / v) ** self.speed_exponent
        self._command = self._command + scale * (
            self.far_gain * (omega_seen - self._omega_prev)
            + self.near_gain * (phi_seen - self._phi_prev)
            + self.integral_gain * dt * phi_seen
        )
        limit = self.max_steering
        self._command = np.clip(self._command, -limit, limit)  # no wind-up beyond the wheel's limit
        self._phi_prev, self._omega_prev = phi_seen, omega_seen
        self._noise = self._rho * self._noise + self._innovation * self._next_noise()
        drive = self._command + scale * scale * self._noise
        angle = self._a00 * self._nm_angle + self._a01 * self._nm_rate + self._b0 * drive
        rate = self._a10 * self._nm_angle + self._a11 * self._nm_rate + self._b1 * drive
        self._nm_angle, self._nm_rate = angle, rate
        steering = np.clip(angle, -limit, limit)
        acceleration = speed_command(self.profile, self._initial_speed, info, road)
        return steering, acceleration


# ------------------------------------------------------------- populations
@dataclass(frozen=True)
class _Range:
    low: float
    high: float

    def draw(self, rng: np.random.Generator) -> float:
        return float(rng.uniform(self.low, self.high))


@dataclass(frozen=True)
class PopulationSpec:
    """How a named population is drawn: ranges of the loop design and of each trait.

    Speed behaviours are a fixed list (one per driver, shuffled by the seed);
    each entry is (target speed range or None for "hold 15 m/s", ramp-rate
    range m/s^2, start-time range s).
    """

    description: str
    bandwidth: _Range
    damping: _Range
    integral_share: _Range
    near_time: _Range
    far_time: _Range
    speed_exponent: _Range
    delay: _Range
    neuromuscular_frequency: _Range
    neuromuscular_damping: _Range
    noise_std: _Range
    noise_time_constant: _Range
    white_noise_probability: float
    max_lateral_acceleration: _Range
    speed_behaviours: tuple[tuple[_Range | None, _Range, _Range], ...]


_HOLD = (None, _Range(1.0, 1.0), _Range(0.0, 0.0))
_MODERATE = (_Range(25.0, 38.0), _Range(1.0, 2.0), _Range(1.0, 6.0))
_FAST = (_Range(45.0, 45.0), _Range(1.8, 3.0), _Range(1.0, 4.0))

POPULATIONS: dict[str, PopulationSpec] = {
    "paper": PopulationSpec(
        description=(
            "Nine drivers like the paper's participants: 'Ill' and 1-8, differing in gains "
            "(lateral-loop bandwidth 0.9-1.25 rad/s, damping 0.5-0.75), look-ahead times, delay "
            "0.15-0.25 s, neuromuscular lag, motor noise (white or OU) and speed: three hold "
            "15 m/s, three ramp to 25-38 m/s, three ramp to 45 m/s."
        ),
        bandwidth=_Range(0.9, 1.25),
        damping=_Range(0.5, 0.75),
        integral_share=_Range(0.2, 0.4),
        near_time=_Range(0.35, 0.5),
        far_time=_Range(0.9, 1.5),
        speed_exponent=_Range(0.85, 1.15),
        delay=_Range(0.15, 0.25),
        neuromuscular_frequency=_Range(8.0, 14.0),
        neuromuscular_damping=_Range(0.6, 0.85),
        noise_std=_Range(0.0004, 0.0012),
        noise_time_constant=_Range(0.2, 0.4),
        white_noise_probability=1.0 / 3.0,
        max_lateral_acceleration=_Range(2.5, 4.0),
        speed_behaviours=(
            _HOLD,
            _HOLD,
            _HOLD,
            _MODERATE,
            _MODERATE,
            _MODERATE,
            _FAST,
            _FAST,
            _FAST,
        ),
    ),
}
"""Named population definitions (see :func:`population`)."""


def _driver_names(size: int) -> list[str]:
    return ["Ill", *(str(i) for i in range(1, size))]


def population(name: str = "paper", seed: int = 0, size: int = 9) -> list[DriverParams]:
    """A seeded population of synthetic drivers, regenerable anywhere by name and seed.

    Args:
        name: a key of :data:`POPULATIONS` ("paper").
        seed: the seed; the same (name, seed, size) gives the same drivers.
        size: number of drivers; they are named "Ill", "1", ..., str(size - 1).
            Speed behaviours cycle through the population's list.

    Returns:
        The drivers' parameters, in name order.
    """
    try:
        spec = POPULATIONS[name]
    except KeyError:
        raise ValueError(
            f"unknown population {name!r}; allowed: {', '.join(sorted(POPULATIONS))}"
        ) from None
    if isinstance(size, bool) or not isinstance(size, int) or size < 1:
        raise ValueError(f"population size must be a positive integer, got {size!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"population seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), _stable_hash(name)]))
    behaviours = [spec.speed_behaviours[i % len(spec.speed_behaviours)] for i in range(size)]
    order = rng.permutation(size)
    drivers = []
    for index, driver_name in enumerate(_driver_names(size)):
        target, rate, start = behaviours[int(order[index])]
        speed = SpeedProfile(
            target_speed=None if target is None else target.draw(rng),
            ramp_rate=rate.draw(rng),
            start_time=start.draw(rng),
            max_lateral_acceleration=spec.max_lateral_acceleration.draw(rng),
        )
        white = bool(rng.random() < spec.white_noise_probability)
        tau = spec.noise_time_constant.draw(rng)
        drivers.append(
            DriverParams.from_loop(
                bandwidth=spec.bandwidth.draw(rng),
                damping=spec.damping.draw(rng),
                integral_share=spec.integral_share.draw(rng),
                near_time=spec.near_time.draw(rng),
                far_time=spec.far_time.draw(rng),
                name=driver_name,
                speed_exponent=spec.speed_exponent.draw(rng),
                delay=spec.delay.draw(rng),
                neuromuscular_frequency=spec.neuromuscular_frequency.draw(rng),
                neuromuscular_damping=spec.neuromuscular_damping.draw(rng),
                noise_std=spec.noise_std.draw(rng),
                noise_time_constant=0.0 if white else tau,
                speed=speed,
            )
        )
    return drivers


def _stable_hash(text: str) -> int:
    """A hash of a string that is the same in every Python process (unlike hash())."""
    return zlib.crc32(text.encode("utf-8"))
