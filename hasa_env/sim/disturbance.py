"""External lateral disturbances: crosswind gusts in time and road camber along the road.

People identifying a human controller excite the closed loop with external
disturbances (multisine forcing functions; docs/design.md §6.5): without
them a driver's steering is almost a function of the car's state and
closed-loop fits are ill-conditioned. The env offers two, off by default in
``gym.make`` and on in the benchmark's population (``config["disturbance"]``):

- **crosswind gusts**, a stationary random process in time: the sum of
  ``components`` sines with frequencies log-spaced from 0.05 Hz to
  ``crosswind_bandwidth`` Hz, equal amplitudes, random phases;
- **road camber**, a random profile along the road: the sum of
  ``components`` sines of the station with wavelengths log-spaced from
  ``20 * camber_wavelength`` down to ``camber_wavelength`` m, so a faster car
  meets it at higher frequencies.

Each sum has standard deviation ``std`` (m/s^2 of lateral acceleration), so
each sine has amplitude ``std * sqrt(2 / components)``::

    a_d(t, s) = sum_i A_w sin(omega_i t + p_i) + sum_j A_c sin(k_j s + q_j)       (m/s^2)

The phases ``p_i``, ``q_j`` are drawn per episode from the env's seeded
generator (:func:`hasa_env.sim.setup.draw_episode`), so an episode is
reproduced by its seed and the vector env reproduces the single env. The
vehicle turns ``a_d`` into a yaw rate (:func:`hasa_env.sim.dynamics.step_vehicle`);
the IMU measures its effect like any other acceleration, and a driver has to
steer against it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

__all__ = ["Disturbance"]


@dataclass(frozen=True)
class Disturbance:
    """The disturbance of an env (see the module docstring); None in EnvSetup when off.

    Attributes:
        wind_amplitude: A_w (m/s^2) of every crosswind sine (0: no crosswind).
        wind_frequencies: omega_i (rad/s), one per sine.
        camber_amplitude: A_c (m/s^2) of every camber sine (0: no camber).
        camber_wavenumbers: k_j (rad/m), one per sine.
    """

    wind_amplitude: float
    wind_frequencies: tuple[float, ...]
    camber_amplitude: float
    camber_wavenumbers: tuple[float, ...]
    _rates: np.ndarray = field(init=False, repr=False, compare=False)
    _amplitudes: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # the array backend's tables, one entry per sine in the order of the sum: its rate
        # (omega_i per s of time, then k_j per m of station) and its amplitude
        winds, cambers = len(self.wind_frequencies), len(self.camber_wavenumbers)
        rates = np.array((*self.wind_frequencies, *self.camber_wavenumbers), dtype=np.float64)
        amplitudes = np.array(
            (self.wind_amplitude,) * winds + (self.camber_amplitude,) * cambers, dtype=np.float64
        )
        for name, table in (("_rates", rates), ("_amplitudes", amplitudes)):
            table.setflags(write=False)
            object.__setattr__(self, name, table)

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> Disturbance | None:
        """The disturbance of a validated config's ``disturbance`` section (None when off)."""
        section = config["disturbance"]
        wind, camber = float(section["crosswind"]), float(section["camber"])
        if wind == 0.0 and camber == 0.0:
            return None
        n = int(section["components"])
        scale = math.sqrt(2.0 / n)
        top = float(section["crosswind_bandwidth"])
        low = min(0.05, top)
        frequencies = np.geomspace(low, top, n) * 2.0 * math.pi if wind else np.zeros(0)
        shortest = float(section["camber_wavelength"])
        wavelengths = np.geomspace(20.0 * shortest, shortest, n) if camber else np.zeros(0)
        return cls(
            wind * scale,
            tuple(float(f) for f in frequencies),
            camber * scale,
            tuple(float(2.0 * math.pi / w) for w in wavelengths),
        )

    @property
    def n_phases(self) -> int:
        """Random phases an episode draws: one per sine."""
        return len(self.wind_frequencies) + len(self.camber_wavenumbers)

    def lateral_acceleration(
        self,
        time: float | np.ndarray,
        station: float | np.ndarray,
        phases: Any,
        ops: SimpleNamespace,
    ) -> float | np.ndarray:
        """a_d (m/s^2) at ``time`` (s) and ``station`` (m) for an episode's ``phases``.

        ``phases`` is a sequence of floats (one car) or an (N, n_phases) array
        (N cars, ``time`` and ``station`` then (N,) arrays); the sines are
        added one by one in the same order for both, so the two backends give
        the same bits (N cars: every sine at once, then summed left to right by
        ``np.add.accumulate``, the same additions in the same order).
        """
        if not isinstance(phases, list | tuple):
            return self._lateral_acceleration_array(time, station, phases)
        columns = phases
        total = 0.0
        k = 0
        for omega in self.wind_frequencies:
            total = total + self.wind_amplitude * ops.sin(omega * time + columns[k])
            k += 1
        for wavenumber in self.camber_wavenumbers:
            total = total + self.camber_amplitude * ops.sin(wavenumber * station + columns[k])
            k += 1
        return total

    def _lateral_acceleration_array(
        self, time: Any, station: Any, phases: np.ndarray
    ) -> np.ndarray:
        """:meth:`lateral_acceleration` of N cars: the (N, n_phases) sines at once, summed
        left to right from 0.0 (``0.0 + s_0 + s_1 + ...``, as the scalar loop adds them)."""
        winds = len(self.wind_frequencies)
        clocks = np.empty(np.shape(phases))  # omega_i t, then k_j s, per car and sine
        clocks[..., :winds] = np.asarray(time, dtype=np.float64)[..., None] * self._rates[:winds]
        clocks[..., winds:] = np.asarray(station, dtype=np.float64)[..., None] * self._rates[winds:]
        terms = self._amplitudes * np.sin(clocks + phases)
        if terms.shape[-1] == 0:
            return np.zeros(terms.shape[:-1])
        terms[..., 0] += 0.0  # the loop's 0.0 + s_0 (a -0.0 becomes 0.0)
        return np.add.accumulate(terms, axis=-1)[..., -1]
