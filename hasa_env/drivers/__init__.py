"""Drivers: synthetic humans, drivers built from steering models, replay; running them.

- :class:`Driver`: the protocol (``reset(seed, dt=...)``, ``act(info, road)``
  -> (road-wheel angle rad, acceleration m/s^2)), acting on the env's true
  ``info``, never the biased camera.
- Synthetic humans of four archetypes (docs/design.md §7.2 and §7.7), all
  with delay, neuromuscular lag, remnant after the lag and wheel
  quantization (:class:`MotorParams`): two-point PI (:class:`TwoPointParams`),
  preview optimal control (:class:`PreviewParams`), intermittent control
  (:class:`IntermittentParams`), intermittent control whose remnant is the
  noise on each correction (:class:`NoisyCorrectionsParams`). :func:`make_driver` makes the driver of
  any of them (:class:`SyntheticDriver` drives them all);
  :func:`population` draws a seeded population ("Ill", "1", ..., "8").
- :class:`ModelDriver`: any steering model plus noise, with a steering ratio.
- :class:`ReplayDriver`: plays back a recording's actions.
- :func:`lane_keeping_check`: can a steering model drive? (closed loop, :class:`LaneKeepingCheck`).
- :func:`run_driver`, :func:`run_drivers`, :func:`run_population`: recordings
  (one DataFrame per run), vectorized over the native vector env;
  :func:`save_runs` writes them in the recording format.
"""

from hasa_env.drivers.archetypes import ARCHETYPES, SyntheticDriver, make_driver, params_from_dict
from hasa_env.drivers.base import BatchDriver, Driver, SpeedProfile, make_batch
from hasa_env.drivers.closed_loop import (
    LANE_CHECK_CONFIG,
    LaneKeepingCheck,
    lane_keeping_check,
    lane_keeping_checks,
    require_lane_keeping,
)
from hasa_env.drivers.intermittent import IntermittentDriver, IntermittentParams
from hasa_env.drivers.model_driver import ModelDriver, ReplayDriver
from hasa_env.drivers.motor import G29_RESOLUTION, MotorParams
from hasa_env.drivers.noisy_corrections import NoisyCorrectionsDriver, NoisyCorrectionsParams
from hasa_env.drivers.populations import POPULATIONS, population
from hasa_env.drivers.preview import PreviewDriver, PreviewParams
from hasa_env.drivers.runner import (
    recording_meta,
    run_driver,
    run_drivers,
    run_population,
    run_seeds,
    save_runs,
)
from hasa_env.drivers.two_point import TwoPointDriver, TwoPointParams

__all__ = [
    "LANE_CHECK_CONFIG",
    "LaneKeepingCheck",
    "lane_keeping_check",
    "lane_keeping_checks",
    "require_lane_keeping",
    "ARCHETYPES",
    "BatchDriver",
    "Driver",
    "G29_RESOLUTION",
    "IntermittentDriver",
    "IntermittentParams",
    "NoisyCorrectionsDriver",
    "NoisyCorrectionsParams",
    "ModelDriver",
    "MotorParams",
    "POPULATIONS",
    "PreviewDriver",
    "PreviewParams",
    "ReplayDriver",
    "SpeedProfile",
    "SyntheticDriver",
    "TwoPointDriver",
    "TwoPointParams",
    "make_batch",
    "make_driver",
    "params_from_dict",
    "population",
    "recording_meta",
    "run_driver",
    "run_drivers",
    "run_population",
    "run_seeds",
    "save_runs",
]
