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
from dataclasses import dataclass
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
        the same bits.
        """
        columns = phases if isinstance(phases, list | tuple) else phases.T
        total = 0.0
        k = 0
        for omega in self.wind_frequencies:
            total = total + self.wind_amplitude * ops.sin(omega * time + columns[k])
            k += 1
        for wavenumber in self.camber_wavenumbers:
            total = total + self.camber_amplitude * ops.sin(wavenumber * station + columns[k])
            k += 1
        return total
