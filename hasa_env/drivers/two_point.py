"""The two-point PI archetype of the synthetic drivers (docs/design.md §7.2 and §7.7).

The paper's fitted models are one-step predictors, not drivers (in closed
loop the generalized one only stabilises the car at Ts <= 0.02 s, the
two-point one barely). This synthetic human (archetype "two-point";
see :mod:`hasa_env.drivers.preview` and :mod:`hasa_env.drivers.intermittent`
for the others) combines:

1. Perception: the near- and far-point bearings phi, omega (rad) of the true
   lane centre at look-ahead *times* (``near_time`` ~0.4 s,
   ``far_time`` ~0.9-1.5 s: distances v * time, so the loop stays stable up
   to 45 m/s), computed exactly on curved roads.
2. A sensorimotor delay of ``delay`` s (0.15-0.25): the controller sees the
   bearings of that long ago.
3. Two-point PI control (Salvucci & Gray, velocity form; paper eq. 10 with
   the corrected signs of docs/design.md §10) on the delayed bearings::

       c(k) = c(k-1) + g(v) [k_f (omega(k) - omega(k-1)) + k_n (phi(k) - phi(k-1)) + k_I Ts phi(k)]

   clipped to the wheel's limit, with gains that adapt to speed,
   g(v) = (v_ref / v) ** speed_exponent (exponent ~1 keeps the lateral closed
   loop the same at every speed: the plant's gain from steering to lateral
   acceleration grows as v^2).
4. Command noise: white, or an Ornstein-Uhlenbeck process n with time
   constant 0.2-0.4 s, scaled by g(v)^2 (proportional to the steering a given
   lateral acceleration needs, ~1/v^2, so the lateral wander it causes is
   about the same at every speed)::

       u(k) = c(k) + g(v)^2 n(k)

5. The output stage every synthetic driver shares
   (:mod:`hasa_env.drivers.motor`): a second-order neuromuscular lag
   (natural frequency 8-14 rad/s, damping 0.6-0.85) discretised exactly,
   then remnant after the lag (broadband, 8-12 Hz tremor, signal-dependent)
   and wheel quantization, as set by ``motor`` (default: no remnant, no
   quantization, i.e. the lag alone, as this driver always was).
6. A speed behaviour (:class:`~hasa_env.drivers.base.SpeedProfile`): hold
   15 m/s, or ramps reaching up to 45 m/s; slowing for bends on curved roads.

:meth:`TwoPointParams.from_loop` chooses the three gains from a desired
lateral closed loop (bandwidth, damping, integral share) instead of by hand;
:func:`hasa_env.drivers.populations.population` draws seeded populations.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from hasa_env.drivers.base import SpeedProfile
from hasa_env.drivers.human import (
    MIN_SPEED,
    DelayLine,
    HumanBatch,
    HumanDriver,
    check_range,
    lane_bearings,
    params_from_dict,
    params_to_dict,
)
from hasa_env.drivers.motor import MotorParams, NoiseBlocks, ou_coefficients
from hasa_env.sim.road import Road

__all__ = ["ARCHETYPE", "TwoPointParams", "TwoPointDriver", "TwoPointBatch"]

ARCHETYPE = "two-point"
"""The archetype name of :class:`TwoPointParams` in dicts (``to_dict()["archetype"]``)."""


@dataclass(frozen=True)
class TwoPointParams:
    """Parameters of one two-point PI driver (SI units, radians).

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
        noise_std: command-noise standard deviation at v_ref (rad of command);
            it scales as g(v)^2.
        noise_time_constant: OU time constant (s); 0 = white noise.
        speed: the speed behaviour.
        max_steering: command saturation and wheel limit (rad), the env's default limit.
        motor: remnant and wheel of the output stage (default: none, no quantization).
        preferred_offset: the lateral offset (m, left positive) from the driven lane's
            centre the driver keeps, in [-2, 2] (:class:`~hasa_env.drivers.human.HumanBatch`).
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
    motor: MotorParams = field(default_factory=MotorParams)
    preferred_offset: float = 0.0

    def __post_init__(self) -> None:
        check_range("TwoPointParams", "preferred_offset", self.preferred_offset, -2.0, 2.0)
        positive = ("near_time", "far_time", "reference_speed", "neuromuscular_frequency",
                    "neuromuscular_damping", "max_steering")  # fmt: skip
        for key in positive:
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(
                    f"TwoPointParams.{key} must be a finite positive number, got {value!r}"
                )
        for key in ("near_gain", "far_gain", "integral_gain", "speed_exponent"):
            if not math.isfinite(getattr(self, key)):
                raise ValueError(f"TwoPointParams.{key} must be finite, got {getattr(self, key)!r}")
        for key in ("delay", "noise_std", "noise_time_constant"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(
                    f"TwoPointParams.{key} must be a finite number >= 0, got {value!r}"
                )
        if not isinstance(self.speed, SpeedProfile):
            raise TypeError(
                f"TwoPointParams.speed must be a SpeedProfile, got {type(self.speed).__name__}"
            )
        if not isinstance(self.motor, MotorParams):
            raise TypeError(
                f"TwoPointParams.motor must be a MotorParams, got {type(self.motor).__name__}"
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
    ) -> TwoPointParams:
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
            **kwargs: the other :class:`TwoPointParams` fields.
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

    def with_speed(self, speed: SpeedProfile) -> TwoPointParams:
        """The same driver with another speed behaviour."""
        return replace(self, speed=speed)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict of the parameters, with ``"archetype": "two-point"``."""
        return params_to_dict(self, ARCHETYPE)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TwoPointParams:
        """Inverse of :meth:`to_dict` (dicts without "archetype" or "motor" are accepted)."""
        return params_from_dict(cls, data, ARCHETYPE)


class TwoPointDriver(HumanDriver):
    """A two-point PI driver (see the module docstring), seeded and reproducible.

    :class:`~hasa_env.drivers.archetypes.SyntheticDriver` drives parameters of any archetype.
    """

    accepts = (TwoPointParams,)


class TwoPointBatch(HumanBatch):
    """N two-point PI drivers acting on N cars' info arrays (see :class:`TwoPointParams`)."""

    params_type = TwoPointParams
    sees_ahead = True

    # Per-run state, set by _reset() / _start().
    _noise: NoiseBlocks
    _delay: DelayLine
    _phi_prev: np.ndarray
    _omega_prev: np.ndarray
    _command_state: np.ndarray
    _command_noise: np.ndarray

    def __init__(self, params: Sequence[TwoPointParams]) -> None:
        super().__init__(params)
        self.near_time, self.far_time = self.arr("near_time"), self.arr("far_time")
        self.near_gain, self.far_gain = self.arr("near_gain"), self.arr("far_gain")
        self.integral_gain = self.arr("integral_gain")
        self.reference_speed = self.arr("reference_speed")
        self.speed_exponent = self.arr("speed_exponent")
        self.noise_std, self.noise_tau = self.arr("noise_std"), self.arr("noise_time_constant")

    def _reset(self, seeds: Sequence[int | None], dt: float, cars: np.ndarray | None) -> None:
        # the command noise keeps the stream it always had: the car's default_rng(seed)
        rngs = [np.random.default_rng(s) for s in seeds]
        if cars is not None:
            self._noise.restart(cars, rngs)
            self._delay.restart(cars)
            return
        self._noise = NoiseBlocks(rngs, 1)
        self._delay = DelayLine(self.delay_steps, 2)
        self._rho, self._innovation = ou_coefficients(self.noise_std, self.noise_tau, dt)

    def _bearings(
        self, info: Mapping[str, np.ndarray], road: Road
    ) -> tuple[np.ndarray, np.ndarray]:
        v = np.maximum(info["speed"], MIN_SPEED)
        return lane_bearings(
            info, road, v * self.near_time, v * self.far_time, self.preferred_offset
        )

    def _start(
        self,
        info: Mapping[str, np.ndarray],
        road: Road,
        steering: np.ndarray,
        cars: np.ndarray | None,
    ) -> None:
        phi, omega = self._bearings(info, road)
        if cars is not None:
            self._phi_prev[cars], self._omega_prev[cars] = phi[cars], omega[cars]
            self._command_state[cars] = steering[cars]
            self._command_noise[cars] = 0.0
            return
        self._phi_prev, self._omega_prev = phi.copy(), omega.copy()
        self._command_state = steering.copy()
        self._command_noise = np.zeros(self.num_cars)

    def _command(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        dt = self._dt
        phi, omega = self._bearings(info, road)
        seen = self._delay(np.column_stack([phi, omega]))
        phi_seen, omega_seen = seen[:, 0], seen[:, 1]
        v = np.maximum(info["speed"], MIN_SPEED)
        scale = (self.reference_speed / v) ** self.speed_exponent
        command = self._command_state + scale * (
            self.far_gain * (omega_seen - self._omega_prev)
            + self.near_gain * (phi_seen - self._phi_prev)
            + self.integral_gain * dt * phi_seen
        )
        limit = self.max_steering
        self._command_state = np.clip(command, -limit, limit)  # no wind-up beyond the limit
        self._phi_prev, self._omega_prev = phi_seen, omega_seen
        self._command_noise = self._rho * self._command_noise + (
            self._innovation * self._noise.next()[:, 0]
        )
        return self._command_state + scale * scale * self._command_noise
