"""Drivers: synthetic humans, drivers built from steering models, replay; running them.

- :class:`Driver`: the protocol (``reset(seed, dt=...)``, ``act(info, road)``
  -> (road-wheel angle rad, acceleration m/s^2)), acting on the env's true
  ``info``, never the biased camera.
- :class:`SyntheticDriver` (:class:`DriverParams`): a synthetic human,
  DESIGN.md section 4; :func:`population` draws a seeded population
  ("Ill", "1", ..., "8").
- :class:`ModelDriver`: any steering model plus noise, with a steering ratio.
- :class:`ReplayDriver`: plays back a recording's actions.
- :func:`run_driver`, :func:`run_drivers`, :func:`run_population`: recordings
  (one DataFrame per run), vectorized over the native vector env;
  :func:`save_runs` writes them in the recording format.
"""

from hasa_env.drivers.base import BatchDriver, Driver, SpeedProfile, make_batch
from hasa_env.drivers.model_driver import ModelDriver, ReplayDriver
from hasa_env.drivers.runner import (
    recording_meta,
    run_driver,
    run_drivers,
    run_population,
    run_seeds,
    save_runs,
)
from hasa_env.drivers.synthetic import POPULATIONS, DriverParams, SyntheticDriver, population

__all__ = [
    "BatchDriver",
    "Driver",
    "DriverParams",
    "ModelDriver",
    "POPULATIONS",
    "ReplayDriver",
    "SpeedProfile",
    "SyntheticDriver",
    "make_batch",
    "population",
    "recording_meta",
    "run_driver",
    "run_drivers",
    "run_population",
    "run_seeds",
    "save_runs",
]
