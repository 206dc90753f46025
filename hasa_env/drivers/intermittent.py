"""Intermittent control: a synthetic driver that steers in ballistic corrections.

After Markkula, Boer, Romano & Merat (2018), "Sustained sensorimotor control
as intermittent decisions about prediction errors: computational framework
and application to ground vehicle steering" (Biological Cybernetics 112),
and the intermittent-control models of Gawthrop, Loram et al.: the driver
does not steer continuously, but launches open-loop corrections when the
evidence that one is needed has piled up. Per env step Ts:

1. An underlying control law gives the desired steering (rad): the
   positional form of the preview LQR of :mod:`hasa_env.drivers.lqr` (the
   steering at which its rate law would rest), on the state and the road
   seen ``delay`` s ago::

       f(k) = k_y y + k_v v theta + sum_j k_j v^2 kappa(s + v t_j)
       u*(k) = -L f(k) / (k_a v^2)

   (feedback on the lateral offset and heading, feed-forward of the
   previewed curvature: u* = L kappa on a steady bend).
2. The prediction error is between it and the steering the ongoing
   corrections will reach, u_T (all corrections launched so far, complete),
   expressed as the lateral acceleration it would make (so the decision is
   the same at every speed)::

       e(k) = u*(k) - u_T(k),   eps(k) = v^2 e(k) / L   (m/s^2)

3. A noisy leaky accumulator of the prediction error (threshold 1)::

       A(k) = A(k-1) + Ts (k_A eps(k) - lambda A(k-1)) + sigma_A sqrt(Ts) n(k)

   with n ~ N(0, 1) from the car's own generator; A is held at 0 during the
   refractory period after a correction.
4. When |A(k)| >= 1, a correction of amplitude e(k) is launched and A is
   reset to 0. A correction is a minimum-jerk step of duration D (its rate is
   bell-shaped), superimposed on the earlier ones::

       G(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5   (0 <= tau <= 1; 1 after)
       u(k) = u_0 + sum_m e_m G((k - k_m) Ts / D)

   Between corrections the command is held.

The command u(k) then goes through the output stage every synthetic driver
shares (:mod:`hasa_env.drivers.motor`), whose remnant is all that moves the
wheel during a hold.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hasa_env.drivers.human import (
    MIN_SPEED,
    OWN_STREAM,
    DelayLine,
    HumanBatch,
    HumanDriver,
    car_streams,
    check_range,
    sum_from,
)
from hasa_env.drivers.lqr import PreviewFeedback
from hasa_env.drivers.motor import NoiseBlocks
from hasa_env.drivers.preview import LqrDriverParams
from hasa_env.sim.road import Road

__all__ = ["ARCHETYPE", "IntermittentParams", "IntermittentDriver", "IntermittentBatch"]

ARCHETYPE = "intermittent"
"""The archetype name of :class:`IntermittentParams` in dicts."""


@dataclass(frozen=True)
class IntermittentParams(LqrDriverParams):
    """Parameters of one intermittent-control driver (SI units, radians).

    The fields of :class:`~hasa_env.drivers.preview.LqrDriverParams` (``cost``:
    the underlying LQR law) and:

    Attributes:
        accumulator_gain: k_A (1/(m/s^2 s)), in [0, 1e4].
        accumulator_leak: lambda (1/s), in [0, 100].
        accumulator_noise: sigma_A (1/sqrt(s)), in [0, 10].
        correction_duration: D (s) of a correction, in [0.05, 2].
        refractory_period: s after a correction before the next can start, in [0, 2].
    """

    archetype: ClassVar[str] = ARCHETYPE

    accumulator_gain: float = 30.0
    accumulator_leak: float = 1.0
    accumulator_noise: float = 0.3
    correction_duration: float = 0.4
    refractory_period: float = 0.2

    def __post_init__(self) -> None:
        owner = "IntermittentParams"
        check_range(owner, "accumulator_gain", self.accumulator_gain, 0.0, 1e4)
        check_range(owner, "accumulator_leak", self.accumulator_leak, 0.0, 100.0)
        check_range(owner, "accumulator_noise", self.accumulator_noise, 0.0, 10.0)
        check_range(owner, "correction_duration", self.correction_duration, 0.05, 2.0)
        check_range(owner, "refractory_period", self.refractory_period, 0.0, 2.0)
        super().__post_init__()


def minimum_jerk(tau: np.ndarray) -> np.ndarray:
    """G(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 on [0, 1], 0 before, 1 after."""
    t = np.clip(tau, 0.0, 1.0)
    return t * t * t * (10.0 + t * (-15.0 + 6.0 * t))


class IntermittentDriver(HumanDriver):
    """An intermittent-control driver (see the module docstring), seeded and reproducible."""

    accepts = (IntermittentParams,)


class IntermittentBatch(HumanBatch):
    """N intermittent drivers acting on N cars' info arrays."""

    params_type = IntermittentParams

    # Per-run state, set by _reset() / _start().
    _noise: NoiseBlocks
    _delay: DelayLine
    _base: np.ndarray

    def __init__(self, params: Sequence[IntermittentParams]) -> None:
        super().__init__(params)
        self.feedback = PreviewFeedback([p.cost for p in self.params])
        self.delay = self.arr("delay")
        self.accumulator_gain = self.arr("accumulator_gain")
        self.leak, self.accumulator_noise = (
            self.arr("accumulator_leak"),
            self.arr("accumulator_noise"),
        )
        self.wheelbase = self.arr("wheelbase")

    def _reset(self, seeds: Sequence[int | None], dt: float, cars: np.ndarray | None) -> None:
        rngs = [car_streams(s, OWN_STREAM) for s in seeds]
        if cars is not None:
            self._noise.restart(cars, rngs)
            self._delay.restart(cars)
            return
        self._noise = NoiseBlocks(rngs, 1)
        self._delay = DelayLine(self.delay_steps, 4)
        self.duration_steps = np.array(
            [max(1, round(p.correction_duration / dt)) for p in self.params], dtype=np.int64
        )
        self.refractory_steps = np.array(
            [round(p.refractory_period / dt) for p in self.params], dtype=np.int64
        )
        # a correction occupies a slot for D / Ts steps; launches are >= refractory + 1 apart
        slots = -(-self.duration_steps // (self.refractory_steps + 1)) + 1
        self.slots = int(slots.max())

    def _start(
        self,
        info: Mapping[str, np.ndarray],
        road: Road,
        steering: np.ndarray,
        cars: np.ndarray | None,
    ) -> None:
        if cars is not None:
            self._base[cars] = steering[cars]
            for name in ("_amplitude", "_age", "_active", "_accumulator", "_refractory",
                         "launches"):  # fmt: skip
                getattr(self, name)[cars] = 0
            return
        n, m = self.num_cars, self.slots
        self._base = steering.copy()
        self._amplitude = np.zeros((n, m))
        self._age = np.zeros((n, m), dtype=np.int64)
        self._active = np.zeros((n, m), dtype=bool)
        self._accumulator = np.zeros(n)
        self._refractory = np.zeros(n, dtype=np.int64)
        self.launches = np.zeros(n, dtype=np.int64)

    def _executed(self, error: np.ndarray) -> np.ndarray:
        """The amplitude (rad) each car's correction would have if launched now, for the
        prediction error ``error`` (rad): the error itself (no execution noise). Called
        every step for every car (a subclass may draw noise here)."""
        return error

    def _command(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        dt = self._dt
        assert dt is not None  # (act() checked)
        seen = self._delay(
            np.column_stack(
                [info["lateral_offset"], info["heading"], info["station"], info["speed"]]
            )
        )
        v = np.maximum(seen[:, 3], MIN_SPEED)
        v2 = v * v
        # the road ahead is previewed from where the car is now (the station seen a delay
        # ago plus v * delay: a longitudinal prediction); the lateral state is the delayed one
        now = seen[:, 2] + v * self.delay
        f = self.feedback(seen[:, 0], seen[:, 1], now, v, road, info.get("bias"))
        desired = -self.wheelbase * f / (self.feedback.acceleration_gain * v2)
        # fixed order (slot 0, 1, ...): the same bits alone or in a batch
        target = sum_from(self._base, np.where(self._active, self._amplitude, 0.0))
        error = desired - target
        evidence = v2 * error / self.wheelbase
        drift = self.accumulator_gain * evidence - self.leak * self._accumulator
        noise = self.accumulator_noise * math.sqrt(dt) * self._noise.next()[:, 0]
        accumulator = self._accumulator + dt * drift + noise
        waiting = self._refractory > 0
        accumulator = np.where(waiting, 0.0, accumulator)
        self._refractory = np.where(waiting, self._refractory - 1, self._refractory)
        fire = np.abs(accumulator) >= 1.0
        amplitude = self._executed(error)
        if fire.any():
            rows = np.flatnonzero(fire)
            free = np.argmin(self._active[rows], axis=1)  # first free slot
            self._amplitude[rows, free] = amplitude[rows]
            self._age[rows, free] = 0
            self._active[rows, free] = True
            accumulator = np.where(fire, 0.0, accumulator)
            self._refractory = np.where(fire, self.refractory_steps, self._refractory)
            self.launches += fire
        self._accumulator = accumulator
        shape = minimum_jerk(self._age / self.duration_steps[:, None])
        command = sum_from(self._base, np.where(self._active, self._amplitude * shape, 0.0))
        self._age = np.where(self._active, self._age + 1, self._age)
        done = self._active & (self._age >= self.duration_steps[:, None])
        self._base = sum_from(self._base, np.where(done, self._amplitude, 0.0))
        self._active &= ~done
        self._amplitude = np.where(done, 0.0, self._amplitude)
        limit = self.max_steering
        return np.clip(command, -limit, limit)
