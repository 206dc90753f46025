"""What the protocol runs: :class:`ProtocolConfig`, its errors and names."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from hasa_env.drivers import POPULATIONS
from hasa_env.sim.config import deep_merge

__all__ = [
    "BASELINES",
    "BUILTIN_MODELS",
    "DEFAULT_SEEDS",
    "ILLUSTRATIVE",
    "BenchmarkError",
    "ProtocolConfig",
]


BUILTIN_MODELS = ("two_point", "generalized")
"""Names of the built-in steering models in the results."""

BASELINES = ("no_steering", "oracle")
"""Names of the estimation baselines in the results."""

ILLUSTRATIVE = "Ill"
DEFAULT_SEEDS = (0, 1, 2, 3, 4)
"""Population seeds of the default protocol."""
_ENV_IDS = {"straight": "hasa_env/LaneKeeping-v0", "curved": "hasa_env/LaneKeepingCurved-v0"}
_NOISE_KEYS = ("speed", "camera", "camera_heading", "imu", "steering")


class BenchmarkError(RuntimeError):
    """The protocol cannot run (invalid configuration or data); nothing was measured."""


@dataclass(frozen=True)
class ProtocolConfig:
    """What :func:`run_protocol` runs (defaults: the paper's protocol).

    Attributes:
        population: name of the synthetic population (:data:`hasa_env.drivers.POPULATIONS`).
        seeds: the population seeds: the whole protocol runs once per seed S,
            with the drivers of ``population(population, S)`` and runs whose
            seeds derive from S, the driver's name, the track and the run
            index (:func:`hasa_env.drivers.run_seeds`). Five by default: a
            verdict that holds on one seed only is an anecdote.
        drivers: number of drivers ("Ill", "1", ..., str(drivers - 1)).
        runs: runs per driver on the main track.
        ill_runs: runs of the illustrative driver on the main track, the
            training run included (None: ``runs + 4``, the paper's 14).
        duration: length of each run (s).
        track: the main track, "straight" or "curved".
        curved_runs: extra runs of the illustrative driver on the curved
            track (steering scores only; 0: none).
        noise: sensor noise std overrides {speed (m/s), camera (m),
            camera_heading (rad), imu (m/s^2), steering (rad)}.
        recordings: a directory of recordings (hasa_env recording format) to
            use instead of synthetic runs; the generation options above are
            then ignored.
        illustrative: the driver whose run trains the models (recordings:
            default "Ill" if present, else the first driver by name).
        training_run: index of the training run among the illustrative
            driver's main-track runs.
        batch_size: runs per task, vectorized together (48: two tasks for the
            paper's 93 validation runs, one per core of a 2-core machine).
            Results do not depend on the executor or worker count; another
            batch size can change them in the last digits.
        ljung_box_lags: lags of the Ljung-Box whiteness test.
        acf_lags: lags of the residual autocorrelation plot.
        weight_threshold: the true-lane weight that counts as "decided".
        error_window: seconds of the lateral-error-over-time figure.
    """

    population: str = "paper"
    seeds: tuple[int, ...] = DEFAULT_SEEDS
    drivers: int = 9
    runs: int = 10
    ill_runs: int | None = None
    duration: float = 30.0
    track: str = "straight"
    curved_runs: int = 1
    noise: Mapping[str, float] = field(default_factory=dict)
    recordings: str | None = None
    illustrative: str | None = None
    training_run: int = 0
    batch_size: int = 48
    ljung_box_lags: int = 20
    acf_lags: int = 50
    weight_threshold: float = 0.95
    error_window: float = 5.0

    def __post_init__(self) -> None:
        def positive_int(name: str, value: Any, low: int = 1) -> None:
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
                raise BenchmarkError(f"{name} must be an integer >= {low}, got {value!r}")

        positive_int("drivers", self.drivers)
        positive_int("runs", self.runs)
        seeds = tuple(self.seeds) if not isinstance(self.seeds, str | bytes) else ()
        if not seeds:
            raise BenchmarkError(
                f"seeds must be a non-empty list of integers >= 0, got {self.seeds!r}"
            )
        for seed in seeds:
            positive_int("seeds[i]", seed, 0)
        if len(set(seeds)) != len(seeds):
            raise BenchmarkError(f"seeds must not repeat, got {list(seeds)}")
        object.__setattr__(self, "seeds", tuple(int(s) for s in seeds))
        positive_int("curved_runs", self.curved_runs, 0)
        positive_int("training_run", self.training_run, 0)
        positive_int("batch_size", self.batch_size)
        positive_int("ljung_box_lags", self.ljung_box_lags)
        positive_int("acf_lags", self.acf_lags)
        if self.ill_runs is not None:
            positive_int("ill_runs", self.ill_runs)
        if self.recordings is None and self.training_run >= self.illustrative_runs:
            raise BenchmarkError(
                f"training_run {self.training_run} needs at least {self.training_run + 1} runs of "
                f"the illustrative driver, got ill_runs = {self.illustrative_runs}"
            )
        if not (math.isfinite(self.duration) and self.duration >= 1.0):
            raise BenchmarkError(f"duration must be at least 1 s, got {self.duration!r}")
        if self.track not in _ENV_IDS:
            raise BenchmarkError(f"track must be one of {sorted(_ENV_IDS)}, got {self.track!r}")
        if not 0.5 <= self.weight_threshold < 1.0:
            raise BenchmarkError(
                f"weight_threshold must be in [0.5, 1), got {self.weight_threshold!r}"
            )
        if not (math.isfinite(self.error_window) and self.error_window > 0):
            raise BenchmarkError(f"error_window must be > 0 s, got {self.error_window!r}")
        for key, value in dict(self.noise).items():
            if key not in _NOISE_KEYS:
                raise BenchmarkError(
                    f"unknown noise key {key!r}; allowed: {', '.join(_NOISE_KEYS)}"
                )
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise BenchmarkError(f"noise {key} must be a finite std >= 0, got {value!r}")

    @property
    def illustrative_runs(self) -> int:
        """Main-track runs of the illustrative driver (synthetic runs)."""
        return self.runs + 4 if self.ill_runs is None else self.ill_runs

    @property
    def run_seeds(self) -> tuple[int | None, ...]:
        """The seeds the protocol runs (recordings: one pass, seed None)."""
        return (None,) if self.recordings is not None else self.seeds

    def env_config(self) -> dict[str, Any]:
        """The env configuration of the synthetic runs (deep-merged onto the defaults): the
        population's study conditions (:attr:`hasa_env.drivers.PopulationSpec.env_config`:
        disturbances, the steering sensor of a wheel study), the run length, and the
        ``noise`` overrides."""
        population = POPULATIONS.get(self.population)
        config = deep_merge(dict(population.env_config) if population else {}, {})
        config["time_limit"] = float(self.duration)
        if self.noise:
            config = deep_merge(
                config, {"noise": {k: float(v) for k, v in dict(self.noise).items()}}
            )
        return config

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["noise"] = dict(self.noise)
        out["ill_runs"] = self.illustrative_runs if self.recordings is None else None
        out["seeds"] = list(self.seeds) if self.recordings is None else None
        return out
