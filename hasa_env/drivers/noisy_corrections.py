"""Noisy corrections: intermittent steering whose remnant is the noise on each correction.

The intermittent driver of :mod:`hasa_env.drivers.intermittent` (Markkula,
Boer, Romano & Merat 2018, "Sustained sensorimotor control as intermittent
decisions about prediction errors", Biological Cybernetics 112:181-207,
doi:10.1007/s00422-017-0743-9: accumulated prediction errors trigger
ballistic minimum-jerk corrections) with the randomness of a human put where
that framework puts it, not in a continuous command noise:

- WHEN a correction starts is random: the noisy evidence accumulator
  (sigma_A, as in the intermittent driver);
- HOW LARGE it is, is random: each correction's executed amplitude carries
  motor execution noise, a signal-dependent part whose standard deviation is
  proportional to the intended amplitude (Harris & Wolpert 1998,
  "Signal-dependent noise determines motor planning", Nature 394:780-784)
  and a signal-independent part (van Beers, Haggard & Wolpert 2004, "The role
  of execution noise in movement variability", J. Neurophysiol.
  91:1050-1063: both parts in the amplitude of the motor commands)::

      a_m = e_m (1 + k_s n_1) + sigma_0 n_2          (rad at the road wheel)

  e_m is the prediction error (rad) at launch, n_1, n_2 ~ N(0, 1) are drawn
  every env step from the car's own generator (stream 3 of its
  SeedSequence), whether a correction starts or not.

There is NO command noise before the lag (``motor.command_std`` must be 0:
the Ornstein-Uhlenbeck command noise that every other archetype shares is
what a road-blind AR(2) of the steering predicts as well as a model that
sees the road). Between corrections the command is held; the wheel moves only
by the remnant after the lag (tremor, broadband) and its quantization. The
driver's prediction of where its ongoing corrections take the steering uses
the executed amplitudes (a simplification: the hands feel the correction
under way; Markkula et al. predict from the efference copy).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hasa_env.drivers.human import HumanDriver, car_streams, check_range
from hasa_env.drivers.intermittent import IntermittentBatch, IntermittentParams
from hasa_env.drivers.motor import NoiseBlocks

__all__ = ["ARCHETYPE", "NoisyCorrectionsBatch", "NoisyCorrectionsDriver", "NoisyCorrectionsParams"]

ARCHETYPE = "noisy-corrections"
"""The archetype name of :class:`NoisyCorrectionsParams` in dicts."""

EXECUTION_STREAM = 3
"""Spawn key of a car's SeedSequence for the execution noise of its corrections (0-2 are the
output stage's, the accumulator's and the pedal's: :mod:`hasa_env.drivers.human`)."""


@dataclass(frozen=True)
class NoisyCorrectionsParams(IntermittentParams):
    """Parameters of one noisy-corrections driver (SI units, radians).

    The fields of :class:`~hasa_env.drivers.intermittent.IntermittentParams`
    (the underlying LQR law, the accumulator, the corrections) and:

    Attributes:
        amplitude_noise: k_s, the coefficient of variation of a correction's executed
            amplitude (dimensionless: std per rad of intended amplitude), in [0, 1].
        amplitude_floor: sigma_0, the signal-independent std of a correction's
            amplitude (rad at the road wheel), in [0, 0.01].

    ``motor.command_std`` must be 0 (no command noise before the lag).
    """

    archetype: ClassVar[str] = ARCHETYPE

    amplitude_noise: float = 0.2
    amplitude_floor: float = 0.0

    def __post_init__(self) -> None:
        owner = "NoisyCorrectionsParams"
        check_range(owner, "amplitude_noise", self.amplitude_noise, 0.0, 1.0)
        check_range(owner, "amplitude_floor", self.amplitude_floor, 0.0, 0.01)
        super().__post_init__()
        if self.motor.command_std != 0.0:
            raise ValueError(
                f"{owner}.motor.command_std must be 0 (its remnant is the noise on each "
                f"correction, not command noise before the lag), got {self.motor.command_std!r}"
            )


class NoisyCorrectionsDriver(HumanDriver):
    """A noisy-corrections driver (see the module docstring), seeded and reproducible."""

    accepts = (NoisyCorrectionsParams,)


class NoisyCorrectionsBatch(IntermittentBatch):
    """N noisy-corrections drivers acting on N cars' info arrays."""

    params_type = NoisyCorrectionsParams

    _execution: NoiseBlocks

    def __init__(self, params: Sequence[NoisyCorrectionsParams]) -> None:
        super().__init__(params)
        self.amplitude_noise = self.arr("amplitude_noise")
        self.amplitude_floor = self.arr("amplitude_floor")

    def _reset(self, seeds: Sequence[int | None], dt: float, cars: np.ndarray | None) -> None:
        super()._reset(seeds, dt, cars)
        rngs = [car_streams(s, EXECUTION_STREAM) for s in seeds]
        if cars is not None:
            self._execution.restart(cars, rngs)
            return
        self._execution = NoiseBlocks(rngs, 2)

    def _executed(self, error: np.ndarray) -> np.ndarray:
        """a = e (1 + k_s n_1) + sigma_0 n_2 for every car (rad), fresh draws every step."""
        draws = self._execution.next()
        return error * (1.0 + self.amplitude_noise * draws[:, 0]) + (
            self.amplitude_floor * draws[:, 1]
        )
