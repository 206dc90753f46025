"""The motor and output stage shared by every synthetic driver (docs/design.md §7.7).

Every synthetic driver's control law produces a command u(k) (road-wheel
angle, rad). Between it and the car stand, per car and env step Ts:

0. Command noise BEFORE the lag (the part of a human's remnant injected at the
   control input: variability of intent), an Ornstein-Uhlenbeck process scaled
   with speed like the steering a given lateral acceleration needs, so the
   lateral wander it causes is about the same at every speed::

       rho_c = exp(-Ts / tau_c)                                  (0 if tau_c = 0)
       c(k) = rho_c c(k-1) + sigma_c sqrt(1 - rho_c^2) e_c(k)
       u'(k) = u(k) + (15 / max(v, 5))^2 c(k)                     (v in m/s)

   Filtered by the lag it makes the steering move (the two-point model
   cannot predict those moves) but stays smooth at the sample scale.

1. A second-order neuromuscular lag, discretised exactly (zero-order hold on u')::

       delta_n'' = w_n^2 (u' - delta_n) - 2 zeta_n w_n delta_n'
       [delta_n, delta_n'](k) = Ad [delta_n, delta_n'](k-1) + Bd u'(k)

2. Remnant added AFTER the lag (so it reaches the wheel unfiltered), all in rad
   at the road wheel:

   a. broadband noise, white (tau_b = 0) or Ornstein-Uhlenbeck::

          rho_b = exp(-Ts / tau_b)                      (0 if tau_b = 0)
          b(k) = rho_b b(k-1) + sigma_b sqrt(1 - rho_b^2) e_b(k)

   b. physiological tremor: a lightly damped resonator (f_t 8-12 Hz,
      zeta_t 0.1-0.3) driven by white noise, discretised by pole matching
      (z = exp(s Ts)) into an AR(2) process::

          w_t = 2 pi f_t,  r = exp(-zeta_t w_t Ts),  a = w_t Ts sqrt(1 - zeta_t^2)
          x(k) = 2 r cos(a) x(k-1) - r^2 x(k-2) + c e_t(k)
          c = sigma_t sqrt((1 + p2) ((1 - p2)^2 - p1^2) / (1 - p2)),  p1 = 2 r cos a, p2 = -r^2

      (c makes sigma_t the stationary standard deviation);

   c. signal-dependent noise, whose standard deviation is the gain s (in s)
      times the lag output's rate |delta_n'(k)| (rad/s), filtered like (a)::

          m(k) = rho_b m(k-1) + sqrt(1 - rho_b^2) s |delta_n'(k)| e_m(k)

   e_b, e_t, e_m are independent N(0, 1) draws from the car's own generator.
   A tremor at or above the Nyquist frequency 1 / (2 Ts) of the env step
   (e.g. a driver acting every 0.1 s) cannot be carried by held actions and
   is left out.
   The OU components start from their stationary distributions, the tremor
   at rest (it settles within 1 / (zeta_t w_t) < 0.2 s).

3. The steering wheel (a Logitech G29 by default: 16 bits over 900 deg lock
   to lock, a step q = 2 pi 2.5 / 65536 = 2.4e-4 rad at the wheel) and the
   steering ratio R (default 15) quantize the road-wheel angle; the wheel's
   limit clips it::

       delta_raw(k) = delta_n(k) + b(k) + x(k) + m(k)
       delta(k) = clip(round(R delta_raw(k) / q), -n_max, n_max) q / R,   n_max = floor(R limit / q)
       delta(k) = clip(delta_raw(k), -limit, limit)                        (q = 0: no quantization)

delta(k) is the applied steering: the action the car gets and the
recording's ``steering`` column. With :class:`MotorParams` at its defaults
(no remnant, no quantization) the stage is the lag alone.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields, replace
from functools import lru_cache
from typing import Any

import numpy as np
from scipy.linalg import expm

__all__ = ["G29_RESOLUTION", "MotorParams", "MotorStage", "NoiseBlocks", "neuromuscular_lag"]

G29_RESOLUTION = 2.0 * math.pi * 2.5 / 65536
"""Logitech G29 steering-wheel step (rad at the steering wheel): 16 bits over 900 deg."""

NOISE_BLOCK = 1000
"""Standard normal draws per car and channel taken at once from each car's generator."""

_LIMITS: dict[str, tuple[float, float, bool]] = {
    # field: (low, high, low is exclusive)
    "command_std": (0.0, 0.1, False),
    "command_time_constant": (0.0, 10.0, False),
    "broadband_std": (0.0, 0.05, False),
    "broadband_time_constant": (0.0, 10.0, False),
    "tremor_std": (0.0, 0.05, False),
    "tremor_frequency": (0.5, 40.0, False),
    "tremor_damping": (0.0, 1.0, True),
    "signal_dependent_gain": (0.0, 1.0, False),
    "steering_ratio": (1.0, 100.0, False),
    "wheel_resolution": (0.0, 0.1, False),
}


@dataclass(frozen=True)
class MotorParams:
    """Remnant and steering wheel of a synthetic driver (see the module docstring).

    The neuromuscular lag belongs to each driver's own parameters
    (``neuromuscular_frequency``, ``neuromuscular_damping``), as it always did
    for :class:`~hasa_env.drivers.two_point.TwoPointParams`.

    Attributes:
        command_std: sigma_c, std of the command noise before the lag at 15 m/s
            (rad at the road wheel), in [0, 0.1].
        command_time_constant: tau_c (s) of the command noise, in [0, 10]; 0 = white.
        broadband_std: sigma_b, rad at the road wheel, in [0, 0.05].
        broadband_time_constant: tau_b (s) of the broadband OU process, in [0, 10]; 0 = white.
        tremor_std: sigma_t, stationary std of the tremor, rad at the road wheel, in [0, 0.05].
        tremor_frequency: f_t (Hz), in [0.5, 40] (left out at or above the env step's Nyquist frequency).
        tremor_damping: zeta_t, in (0, 1].
        signal_dependent_gain: s (s): std of the signal-dependent noise per rad/s of
            the lag output's rate, in [0, 1].
        steering_ratio: R, steering-wheel angle per road-wheel angle, in [1, 100].
        wheel_resolution: q, rad at the steering wheel, in [0, 0.1]; 0 = no quantization
            (:data:`G29_RESOLUTION` for a Logitech G29).
    """

    command_std: float = 0.0
    command_time_constant: float = 0.3
    broadband_std: float = 0.0
    broadband_time_constant: float = 0.0
    tremor_std: float = 0.0
    tremor_frequency: float = 10.0
    tremor_damping: float = 0.2
    signal_dependent_gain: float = 0.0
    steering_ratio: float = 15.0
    wheel_resolution: float = 0.0

    def __post_init__(self) -> None:
        for name, (low, high, open_low) in _LIMITS.items():
            value = getattr(self, name)
            ok = isinstance(value, int | float) and math.isfinite(value)
            ok = ok and (value > low if open_low else value >= low) and value <= high
            if not ok:
                bracket = "(" if open_low else "["
                raise ValueError(
                    f"MotorParams.{name} must be in {bracket}{low:g}, {high:g}], got {value!r}"
                )

    @property
    def has_remnant(self) -> bool:
        """Whether any remnant component is on."""
        return (
            self.command_std > 0
            or self.broadband_std > 0
            or self.tremor_std > 0
            or self.signal_dependent_gain > 0
        )

    def scaled(self, factor: float, command_factor: float = 1.0) -> MotorParams:
        """The same stage with every remnant std after the lag (and the signal-dependent
        gain) times ``factor`` and the command noise before it times ``command_factor``."""
        for label, value in (("remnant", factor), ("command noise", command_factor)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{label} scale must be a finite number >= 0, got {value!r}")
        return replace(
            self,
            command_std=self.command_std * command_factor,
            broadband_std=self.broadband_std * factor,
            tremor_std=self.tremor_std * factor,
            signal_dependent_gain=self.signal_dependent_gain * factor,
        )

    def to_dict(self) -> dict[str, float]:
        """A JSON-able dict of the parameters."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MotorParams:
        """Inverse of :meth:`to_dict` (unknown keys are an error)."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"MotorParams: unknown fields {unknown}; allowed: {sorted(known)}")
        return cls(**data)


def ou_coefficients(std: Any, time_constant: Any, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(rho, innovation std) of an Ornstein-Uhlenbeck process of stationary std ``std`` and
    time constant ``time_constant`` (s) sampled every ``dt`` s, per car::

        x(k) = rho x(k-1) + std sqrt(1 - rho^2) e(k),   rho = exp(-dt / tau)   (0 if tau = 0: white)
    """
    tau = np.asarray(time_constant, dtype=np.float64)
    with np.errstate(divide="ignore"):
        rho = np.where(tau > 0, np.exp(-dt / np.maximum(tau, 1e-300)), 0.0)
    return rho, np.asarray(std, dtype=np.float64) * np.sqrt(1.0 - rho**2)


@lru_cache(maxsize=256)
def neuromuscular_lag(frequency: float, damping: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of delta'' = w^2 (u - delta) - 2 z w delta'.

    Returns (Ad, Bd): [delta, delta'](k) = Ad [delta, delta'](k-1) + Bd u(k).
    """
    w, z = frequency, damping
    m = np.zeros((3, 3))
    m[0, 1] = 1.0
    m[1, 0] = -w * w
    m[1, 1] = -2.0 * z * w
    m[1, 2] = w * w
    e = expm(m * dt)
    ad, bd = e[:2, :2].copy(), e[:2, 2].copy()
    ad.setflags(write=False)
    bd.setflags(write=False)
    return ad, bd


class NoiseBlocks:
    """Standard normal draws for N cars, ``channels`` per step, from each car's own generator.

    Every :data:`NOISE_BLOCK` steps each car draws ``(channels, NOISE_BLOCK)``
    numbers from its generator, so a car's noise is the same alone or in any
    batch. ``next()`` returns the (N, channels) draws of one step;
    :meth:`restart` gives some cars new generators (their next draw starts a
    new block), as a car's first block after a reset.
    """

    def __init__(self, rngs: Sequence[np.random.Generator], channels: int) -> None:
        self.rngs = list(rngs)
        self.channels = int(channels)
        # car i's block is rows i * NOISE_BLOCK ... of (N * NOISE_BLOCK, channels): one
        # step of every car is then a gather of N contiguous rows
        self._block = np.zeros((len(self.rngs) * NOISE_BLOCK, self.channels))
        self._pos = np.full(len(self.rngs), NOISE_BLOCK, dtype=np.int64)  # per car
        self._base = np.arange(len(self.rngs)) * NOISE_BLOCK

    def restart(self, cars: np.ndarray, rngs: Sequence[np.random.Generator]) -> None:
        """Cars ``cars`` (indices) draw from ``rngs`` (one each) from their next step on."""
        for i, rng in zip(np.asarray(cars).tolist(), rngs, strict=True):
            self.rngs[i] = rng
            self._pos[i] = NOISE_BLOCK

    def next(self) -> np.ndarray:
        pos = self._pos
        if pos.max() >= NOISE_BLOCK:
            for i in np.flatnonzero(pos >= NOISE_BLOCK).tolist():
                draws = self.rngs[i].standard_normal((self.channels, NOISE_BLOCK))
                self._block[i * NOISE_BLOCK : (i + 1) * NOISE_BLOCK] = draws.T
                pos[i] = 0
        out = self._block.take(self._base + pos, axis=0)
        pos += 1
        return out


class MotorStage:
    """The output stage of N drivers: lag, remnant, wheel (see the module docstring).

    Args:
        frequency: neuromuscular natural frequency w_n (rad/s) of each car.
        damping: neuromuscular damping zeta_n of each car.
        motors: each car's :class:`MotorParams`.
        max_steering: each car's wheel limit (rad at the road wheel).
    """

    # Per-run state, set by reset().
    _noise: NoiseBlocks
    _fresh: np.ndarray
    _angle: np.ndarray
    _rate: np.ndarray

    def __init__(
        self,
        frequency: np.ndarray,
        damping: np.ndarray,
        motors: Sequence[MotorParams],
        max_steering: np.ndarray,
    ) -> None:
        self.motors = list(motors)
        self.num_cars = len(self.motors)
        self.frequency = np.asarray(frequency, dtype=np.float64)
        self.damping = np.asarray(damping, dtype=np.float64)
        self.max_steering = np.asarray(max_steering, dtype=np.float64)

        def arr(key: str) -> np.ndarray:
            return np.array([getattr(m, key) for m in self.motors], dtype=np.float64)

        self.command_std, self.command_tau = arr("command_std"), arr("command_time_constant")
        self.broadband_std, self.broadband_tau = (
            arr("broadband_std"),
            arr("broadband_time_constant"),
        )
        self.tremor_std, self.tremor_frequency = arr("tremor_std"), arr("tremor_frequency")
        self.tremor_damping = arr("tremor_damping")
        self.gain = arr("signal_dependent_gain")
        self.ratio, self.resolution = arr("steering_ratio"), arr("wheel_resolution")
        self._dt: float | None = None

    def reset(
        self, rngs: Sequence[np.random.Generator], dt: float, cars: np.ndarray | None = None
    ) -> None:
        """Start a run with time step ``dt`` (s), drawing each car's remnant from ``rngs[i]``.

        With ``cars`` (indices; ``rngs`` then has one generator per entry) only
        those cars start a new run, with the batch's ``dt``; the others go on.
        """
        if cars is not None:
            if self._dt is None or float(dt) != self._dt:
                raise ValueError(
                    "MotorStage.reset(cars=...) restarts cars of a running batch at its dt "
                    f"({self._dt} s); got dt = {dt} s"
                )
            self._noise.restart(cars, rngs)
            self._fresh[cars] = True
            return
        self._dt = float(dt)
        lags = [
            neuromuscular_lag(float(w), float(z), self._dt)
            for w, z in zip(self.frequency, self.damping, strict=True)
        ]
        ad = np.array([a for a, _ in lags])
        bd = np.array([b for _, b in lags])
        self._a00, self._a01, self._a10, self._a11 = (
            ad[:, 0, 0],
            ad[:, 0, 1],
            ad[:, 1, 0],
            ad[:, 1, 1],
        )
        self._b0, self._b1 = bd[:, 0], bd[:, 1]
        self._rho, self._innovation = ou_coefficients(1.0, self.broadband_tau, dt)
        self._rho_c, self._innovation_c = ou_coefficients(self.command_std, self.command_tau, dt)
        self.commanded = bool(np.any(self.command_std > 0))
        # a tremor at or above the Nyquist frequency of the env step cannot be carried by
        # actions held over the step (e.g. a policy acting every 0.1 s): it is left out
        self.tremor_on = self.tremor_frequency < 0.5 / dt
        w_t = 2.0 * np.pi * np.where(self.tremor_on, self.tremor_frequency, 0.25 / dt)
        r = np.exp(-self.tremor_damping * w_t * dt)
        angle = w_t * dt * np.sqrt(1.0 - self.tremor_damping**2)
        self._p1, self._p2 = 2.0 * r * np.cos(angle), -(r**2)
        p1, p2 = self._p1, self._p2
        self._tremor_gain = np.where(self.tremor_on, self.tremor_std, 0.0) * np.sqrt(
            (1.0 + p2) * ((1.0 - p2) ** 2 - p1**2) / (1.0 - p2)
        )
        self.quantized = self.resolution > 0
        self._q = np.where(self.quantized, self.resolution, 1.0)
        self._levels = np.floor(self.ratio * self.max_steering / self._q)
        self._noise = NoiseBlocks(rngs, 4 if self.commanded else 3)
        self._fresh = np.ones(self.num_cars, dtype=bool)

    def start(self, steering: np.ndarray, cars: np.ndarray | None = None) -> None:
        """The lag at rest at the car's initial steering (rad), the remnant at its start.

        ``steering`` holds every car's angle; with ``cars`` (indices) only those
        cars start, the others go on.
        """
        start = np.asarray(steering, dtype=np.float64)
        if cars is not None:
            for name in ("_command_noise", "_broadband", "_dependent", "_tremor", "_tremor_prev",
                         "_rate"):  # fmt: skip
                getattr(self, name)[cars] = 0.0
            self._angle[cars] = start[cars]
            self._fresh[cars] = True
            return
        self._angle, self._rate = start.copy(), np.zeros(self.num_cars)
        zeros = np.zeros(self.num_cars)
        self._command_noise = zeros.copy()
        self._broadband, self._dependent = zeros.copy(), zeros.copy()
        self._tremor, self._tremor_prev = zeros.copy(), zeros.copy()
        self._fresh = np.ones(self.num_cars, dtype=bool)

    def step(self, command: np.ndarray, speed: np.ndarray | None = None) -> np.ndarray:
        """Applied steering (rad at the road wheel) for the command u(k) (rad) at ``speed``
        (m/s; needed with command noise)."""
        if self._dt is None:
            raise RuntimeError("MotorStage: call reset() before step()")
        e = self._noise.next()
        fresh = self._fresh  # per car: the first step of its run
        any_fresh = bool(fresh.any())
        if self.commanded:
            if speed is None:
                raise ValueError("MotorStage.step needs the speed when there is command noise")
            noise = self._rho_c * self._command_noise + self._innovation_c * e[:, 3]
            if any_fresh:  # stationary start
                noise = np.where(fresh, self.command_std * e[:, 3], noise)
            self._command_noise = noise
            scale = (15.0 / np.maximum(np.asarray(speed, dtype=np.float64), 5.0)) ** 2
            command = command + scale * self._command_noise
        angle = self._a00 * self._angle + self._a01 * self._rate + self._b0 * command
        rate = self._a10 * self._angle + self._a11 * self._rate + self._b1 * command
        self._angle, self._rate = angle, rate
        dependent_std = self.gain * np.abs(rate)
        broadband = self._rho * self._broadband + (self.broadband_std * self._innovation * e[:, 0])
        dependent = self._rho * self._dependent + (self._innovation * dependent_std * e[:, 1])
        if any_fresh:  # stationary start of the OU components
            broadband = np.where(fresh, self.broadband_std * e[:, 0], broadband)
            dependent = np.where(fresh, dependent_std * e[:, 1], dependent)
            self._fresh = np.zeros(self.num_cars, dtype=bool)
        self._broadband, self._dependent = broadband, dependent
        tremor = (
            self._p1 * self._tremor + self._p2 * self._tremor_prev + self._tremor_gain * e[:, 2]
        )
        self._tremor_prev, self._tremor = self._tremor, tremor
        raw = angle + self._broadband + tremor + self._dependent
        limit = self.max_steering
        clipped = np.clip(raw, -limit, limit)
        if not self.quantized.any():
            return clipped
        steps = np.clip(np.round(self.ratio * raw / self._q), -self._levels, self._levels)
        return np.where(self.quantized, steps * self._q / self.ratio, clipped)
