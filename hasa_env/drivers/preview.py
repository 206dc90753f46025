"""Preview optimal control: a synthetic driver that steers by LQR with road preview.

After Sharp, Casanova & Symonds (2000): the linear-quadratic regulator with
a shift register of previewed curvatures of :mod:`hasa_env.drivers.lqr`
(its design equations are there), applied as a rate law every env step Ts on
the state and the road seen ``delay`` s ago (the command delta is the
driver's own, known without delay)::

    f(k) = k_y y + k_v v theta + sum_j k_j v^2 kappa(s + v t_j)      (delayed y, theta, s, v)
    j(k) = -(f(k) + k_a v^2 delta(k) / L)                            (lateral jerk, m/s^3)
    delta(k+1) = clip(delta(k) + Ts L j(k) / v^2, -limit, limit)     (command, rad)

The closed loop has the same time response at every speed (5 to 45 m/s),
so the delay (0.15-0.25 s) and the lag do not destabilise it at high speed.
The gains of the sampled design (sample time T = preview step, 0.1 s) are
applied at every env step (Ts <= T): its continuous limit, to
O(T x bandwidth). The command then goes through the output stage every
synthetic driver shares (:mod:`hasa_env.drivers.motor`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Self

import numpy as np

from hasa_env.drivers.base import SpeedProfile
from hasa_env.drivers.human import (
    MIN_SPEED,
    DelayLine,
    HumanBatch,
    HumanDriver,
    check_common,
    check_range,
    params_from_dict,
    params_to_dict,
)
from hasa_env.drivers.lqr import PreviewCost, PreviewFeedback
from hasa_env.drivers.motor import MotorParams
from hasa_env.sim.road import Road

__all__ = ["ARCHETYPE", "LqrDriverParams", "PreviewParams", "PreviewDriver", "PreviewBatch"]

ARCHETYPE = "preview"
"""The archetype name of :class:`PreviewParams` in dicts."""


@dataclass(frozen=True)
class LqrDriverParams:
    """Fields of a driver that steers with the preview LQR design (SI units, radians).

    The base of :class:`PreviewParams` and
    :class:`~hasa_env.drivers.intermittent.IntermittentParams`; each subclass
    names its archetype in ``archetype``.

    Attributes:
        name: label ("Ill", "1", ...).
        cost: cost weights and preview of the LQR design.
        wheelbase: L (m) of the driver's internal model, in [0.5, 10].
        delay: sensorimotor delay (s), in [0, 1].
        neuromuscular_frequency: omega_n (rad/s) of the lag, in (0, 200].
        neuromuscular_damping: zeta of the lag, in (0, 5].
        speed: the speed behaviour.
        max_steering: command saturation and wheel limit (rad), in (0, 1.5].
        motor: remnant and wheel of the output stage.
        preferred_offset: the lateral offset (m, left positive) from the driven lane's
            centre the driver keeps, in [-2, 2].
    """

    archetype: ClassVar[str]

    name: str = "driver"
    cost: PreviewCost = field(default_factory=PreviewCost)
    wheelbase: float = 2.8
    delay: float = 0.2
    neuromuscular_frequency: float = 10.0
    neuromuscular_damping: float = 0.7
    speed: SpeedProfile = field(default_factory=SpeedProfile)
    max_steering: float = 0.5
    motor: MotorParams = field(default_factory=MotorParams)
    preferred_offset: float = 0.0

    def __post_init__(self) -> None:
        owner = type(self).__name__
        if not isinstance(self.cost, PreviewCost):
            raise TypeError(f"{owner}.cost must be a PreviewCost, got {type(self.cost).__name__}")
        check_range(owner, "wheelbase", self.wheelbase, 0.5, 10.0)
        check_common(owner, self)

    def with_speed(self, speed: SpeedProfile) -> Self:
        """The same driver with another speed behaviour."""
        return replace(self, speed=speed)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict of the parameters, with the ``"archetype"``."""
        return params_to_dict(self, self.archetype)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Self:
        """Inverse of :meth:`to_dict`."""
        return params_from_dict(cls, data, cls.archetype, cost=PreviewCost.from_dict)


@dataclass(frozen=True)
class PreviewParams(LqrDriverParams):
    """Parameters of one preview-optimal-control driver: the fields of :class:`LqrDriverParams`."""

    archetype: ClassVar[str] = ARCHETYPE


class PreviewDriver(HumanDriver):
    """A preview-optimal-control driver (see the module docstring), seeded and reproducible."""

    accepts = (PreviewParams,)


class PreviewBatch(HumanBatch):
    """N preview drivers acting on N cars' info arrays."""

    params_type = PreviewParams

    # Per-run state, set by _reset() / _start().
    _delay: DelayLine
    _command_state: np.ndarray

    def __init__(self, params: Sequence[PreviewParams]) -> None:
        super().__init__(params)
        self.wheelbase = self.arr("wheelbase")
        self.feedback = PreviewFeedback([p.cost for p in self.params])
        self.delay = self.arr("delay")

    def _reset(self, seeds: Sequence[int | None], dt: float, cars: np.ndarray | None) -> None:
        if cars is not None:
            self._delay.restart(cars)
            return
        self._delay = DelayLine(self.delay_steps, 4)

    def _start(
        self,
        info: Mapping[str, np.ndarray],
        road: Road,
        steering: np.ndarray,
        cars: np.ndarray | None,
    ) -> None:
        if cars is not None:
            self._command_state[cars] = steering[cars]
            return
        self._command_state = steering.copy()

    def _command(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        seen = self._delay(
            np.column_stack(
                [info["lateral_offset"], info["heading"], info["station"], info["speed"]]
            )
        )
        v = np.maximum(seen[:, 3], MIN_SPEED)
        v2 = v * v
        length = self.wheelbase
        delta = self._command_state
        # the road ahead is previewed from where the car is now (the station seen a delay
        # ago plus v * delay: a longitudinal prediction); the lateral state is the delayed one
        now = seen[:, 2] + v * self.delay
        f = self.feedback(seen[:, 0], seen[:, 1], now, v, road, info.get("bias"))
        jerk = -(f + self.feedback.acceleration_gain * (v2 * delta / length))
        limit = self.max_steering
        self._command_state = np.clip(delta + self._dt * length * jerk / v2, -limit, limit)
        return self._command_state
