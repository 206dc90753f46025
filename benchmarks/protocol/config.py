"""What the protocol runs: :class:`ProtocolConfig`, its errors and names."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from benchmarks.defaults import (
    DEFAULT_EQUATION_ERROR_ORDER,
    DEFAULT_MODEL_TIME_LIMIT,
    DEFAULT_SEEDS,
    DEFAULT_TRAINING_DRIVERS,
    GENERALIZED_ORDERS,
)
from estimators.settings import FilterSettings
from hasa_env.drivers import POPULATIONS
from hasa_env.scenarios import SCENARIOS
from hasa_env.sim.config import ConfigError, deep_merge, make_config
from hasa_env.steering.equation_error import MAX_EQUATION_ERROR_ORDER
from hasa_env.validation import ABSENT, Field, did_you_mean, schema, validate_fields

__all__ = [
    "BASELINES",
    "BUILTIN_MODELS",
    "DEFAULT_MODEL_TIME_LIMIT",
    "DEFAULT_SEEDS",
    "ILLUSTRATIVE",
    "BenchmarkError",
    "ProtocolConfig",
    "STEERING_BASELINE",
    "STEERING_FREE_BASELINES",
    "UNCHECKED_SUFFIX",
]


BUILTIN_MODELS = ("two_point", "generalized")
"""Names of the built-in steering models in the results."""

BASELINES = ("no_steering", "lane_centring", "oracle")
"""Names of the estimation baselines in the results: the steering-free ones
(:data:`STEERING_FREE_BASELINES`) and the oracle, told the true lane."""

STEERING_FREE_BASELINES = ("no_steering", "lane_centring")
"""The baselines that use no steering model: the mixture filter on speed and camera alone,
and the same weighing the lanes by a lane-centring prior fitted on the training run
(:class:`estimators.lane_centring.LaneCentringEKF`). A steering model is worth its gain
over the best of them."""

STEERING_BASELINE = "road_blind"
"""The steering baseline: an AR(2) model of the steering's own past, fitted like the others,
blind to the road (:class:`hasa_env.steering.RoadBlindModel`, the generalized model's na = 2
without bearing or v_y terms). A steering model's one-step score means something only beside
it; its road information is ``1 - SSE_model / SSE_road_blind`` (docs/design.md §6.3)."""

UNCHECKED_SUFFIX = " (no checks)"
"""Appended to a model's name for its estimator without the evidence checks
(``compare_checks``; :mod:`estimators.evidence`)."""

ILLUSTRATIVE = "Ill"
TRACK_ENV_IDS = {"straight": "hasa_env/LaneKeeping-v0", "curved": "hasa_env/LaneKeepingCurved-v0"}
"""Gymnasium env id of each main track."""
_NOISE_UNITS = {"speed": "m/s", "camera": "m", "camera_heading": "rad", "imu": "m/s^2",
                "steering": "rad"}  # fmt: skip


class BenchmarkError(RuntimeError):
    """The protocol cannot run (invalid configuration or data); nothing was measured."""


def _count(doc: str, low: int, optional: bool = False) -> Field:
    return Field("integer", doc=doc, low=low, optional=optional)


_SCHEMA = schema(
    {
        "population": Field("string", doc="Synthetic population name.", non_empty=True),
        "seeds": Field(
            "integers", doc="Population seeds, one protocol pass each.", low=0, non_empty=True,
            unique=True,
        ),
        "drivers": _count("Number of drivers.", 1),
        "runs": _count("Runs per driver on the main track.", 1),
        "ill_runs": _count("Runs of the illustrative driver (null: runs + 4).", 1, True),
        "duration": Field("number", doc="Length of each run.", unit="s", low=1.0),
        "track": Field("choice", doc="The main track.", choices=tuple(TRACK_ENV_IDS)),
        "curved_runs": _count("Runs on the curved track.", 0),
        "noise": Field(
            "mapping",
            fields={
                key: Field("number", ABSENT, f"Sensor noise std ({unit}).", unit=unit, low=0.0)
                for key, unit in _NOISE_UNITS.items()
            },
        ),
        "recordings": Field("string", doc="Directory of recordings.", optional=True),
        "illustrative": Field("string", doc="The training driver.", optional=True),
        "training_run": _count("Index of the training run.", 0),
        "training_runs": _count("Runs of the illustrative driver that train the models.", 1),
        "training_drivers": _count(
            "Extra drivers of the population, one run each, that also train the models "
            f"(null: {DEFAULT_TRAINING_DRIVERS} for synthetic runs, 0 with recordings).",
            0,
            True,
        ),
        "training_speeds": Field(
            "numbers", doc="Start speeds of extra training runs of the illustrative driver.",
            unit="m/s", low=1.0, high=150.0, unique=True,
        ),
        "equation_error_order": Field(
            "integer", doc="Lags of the built-in generalized model's equation-error "
            "autoregression (0: white, the paper's).", low=0, high=MAX_EQUATION_ERROR_ORDER,
        ),
        "speed_scaled_error": Field(
            "bool", doc="Fit the built-in generalized model's equation error as a coloured "
            "part scaled by (15 / v)^2 plus a white part, carried as a filter state "
            "(docs/design.md §8.34).",
        ),
        "generalized_orders": Field(
            "choice", doc="Orders of the built-in generalized model: 'bic' (selected on the "
            "training runs) or 'paper' (na=2, nb=4, nc=1, nd=2).", choices=GENERALIZED_ORDERS,
        ),
        "batch_size": _count("Runs per task.", 1),
        "ljung_box_lags": _count("Lags of the Ljung-Box test.", 1),
        "acf_lags": _count("Lags of the autocorrelation plot.", 1),
        "weight_threshold": Field(
            "number", doc="True-lane weight that counts as decided.", low=0.5, high=1.0,
            high_open=True,
        ),
        "error_window": Field(
            "number", doc="Length of the error-over-time figure.", unit="s", low=0.0,
            low_open=True,
        ),
        "stress": Field("bool", doc="Also score the stress set of bad advisors."),
        "scenario": Field(
            "choice", doc="The scenario of the synthetic runs (hasa_env.scenarios).",
            choices=tuple(SCENARIOS),
        ),
        "estimate": Field("bool", doc="Run the lane estimation (table 2)."),
        "filter_settings": Field(
            "mapping", doc="FilterSettings fields for every estimator.", each=Field("json")
        ),
        "compare_checks": Field(
            "bool", doc="Also run the estimators without the evidence and lane-keeping checks."
        ),
        "min_duration": Field(
            "number", doc="Shortest recording that is scored.", unit="s", low=0.0
        ),
        "allow_incomplete": Field("bool", doc="Score recordings whose writer stopped early."),
        "training_file": Field(
            "string", doc="The recording that trains the models.", optional=True, non_empty=True
        ),
        "model_time_limit": Field(
            "number", doc="Time limit of one call into a user model (null: none, in-process).",
            unit="s", low=0.0, low_open=True, optional=True,
        ),
    }
)  # fmt: skip


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
        scenario: the scenario of the synthetic runs (:data:`hasa_env.scenarios.SCENARIOS`):
            the env config it sets (under ``noise``) and its drivers' preferred offsets
            (:func:`hasa_env.scenarios.scenario_drivers`); the scored runs are driven in
            it, the training run in ``paper`` (:meth:`env_config`). Recordings carry their
            own: the training recording's is scored (:func:`benchmarks.protocol.plan.
            recording_plan`), and the results' config names it.
        track: the main track, "straight" or "curved".
        curved_runs: extra runs of the illustrative driver on the curved
            track (steering scores and estimation with the road ahead as a
            known input; 0: none).
        noise: sensor noise std overrides {speed (m/s), camera (m),
            camera_heading (rad), imu (m/s^2), steering (rad)}.
        recordings: a directory of recordings (hasa_env recording format) to
            use instead of synthetic runs; the generation options above are
            then ignored.
        illustrative: the driver whose run trains the models (recordings:
            default "Ill" if present, else the first driver by name).
        training_run: index of the training run among the illustrative
            driver's main-track runs.
        training_runs: how many of its main-track runs, from ``training_run`` on, train the
            models (1: the paper's one-run protocol; more: several runs and the speeds they
            reach, each a separate run for the fit, so lags never cross between them).
        training_drivers: extra drivers drawn from the same population (a draw of their own,
            :func:`~benchmarks.protocol.plan.training_population`), one run each in the
            training scenario, that also train the models and are scored nowhere (synthetic
            runs only): a model fitted on several drivers meets the scored drivers' steering
            with residuals nearer its own level (docs/design.md §8.20). None (the default):
            :data:`~benchmarks.defaults.DEFAULT_TRAINING_DRIVERS` (8) for synthetic runs, 0
            with ``recordings`` (§8.21); 0: the paper's protocol (the illustrative driver
            only).
        training_speeds: start speeds (m/s) of extra runs of the illustrative driver that
            also train the models, one run each, driven in the training scenario from its
            own seeds and scored nowhere (synthetic runs only): a model fitted at the
            speeds people drive is trusted there (the speed rule's range is that of every
            training run, :mod:`estimators.trust`). Empty: the paper's protocol.
        generalized_orders: how the built-in generalized model's orders are chosen
            (:data:`~benchmarks.defaults.GENERALIZED_ORDERS`): ``"paper"`` (the default):
            the paper's orders (2, 4, 1, 2), as its table 1 fitted them; ``"bic"``
            selects (na, nb, nc, nd) by BIC on the training runs, on the training side only
            (:func:`hasa_env.steering.order.select_order`, its default grid up to (4, 6, 3, 3);
            docs/design.md §8.26).
        equation_error_order: lags of the autoregression the built-in generalized model's
            fit estimates for its equation error (:data:`~benchmarks.defaults.DEFAULT_EQUATION_ERROR_ORDER`,
            2); the estimator compares the steering whitened by it (docs/design.md §8.32). 0:
            white, the paper's model as it is.
        speed_scaled_error: the built-in generalized model's equation error fitted as a
            coloured part scaled by ``(15 / v)^2`` plus a white part, the coloured part a state
            of its filter (docs/design.md §8.34); it replaces the whitening by the
            autoregression above in the filter.
        batch_size: most runs per task, vectorized together; a seed's curved and
            validation runs together are cut into the fewest near-equal tasks (100: one
            task of the 4 curved and the 93 validation runs per seed, filtered in one
            batch. A filter step costs about as much for 4 runs as for 93, so fewer,
            larger batches cost less in all; the tasks run largest first:
            docs/design.md §9.5). Results do not depend on the executor or worker count;
            another batch size can change them in the last digits.
        ljung_box_lags: lags of the Ljung-Box whiteness test.
        acf_lags: lags of the residual autocorrelation plot.
        weight_threshold: the true-lane weight that counts as "decided".
        error_window: seconds of the lateral-error-over-time figure.
        stress: also score the stress set of bad advisors
            (:mod:`benchmarks.stress`) on the same runs.
        compare_checks: also run every model's estimator without the
            evidence checks (``FilterSettings.evidence_checks=False``), named
            ``"<model> (no checks)"``: what the checks cost or buy.
        estimate: run the lane estimation (paper table 2); False: steering
            scores and driving statistics only (the population calibration,
            :mod:`benchmarks.population_tuning`).
        filter_settings: fields of :class:`estimators.settings.FilterSettings`
            for every estimator (e.g. ``{"forgetting_time": 10.0}``), over the
            run's sensor noise; the steering residual level stays the fitted
            model's.
        min_duration: recordings shorter than this (s) are skipped, each
            named with its reason (a crash or an early stop is no run to
            train on or to score).
        allow_incomplete: also use recordings whose writer stopped before
            finalizing them (a crash, a failed write); skipped by default.
        training_file: the recording that trains the models (recordings;
            overrides ``illustrative`` and ``training_run``).
        model_time_limit: the longest one call into a user model may take (s):
            importing it, one fit, scoring one batch of runs; each call runs
            isolated in its own process, so a model that hangs, exits or
            crashes fails alone (:func:`benchmarks.protocol.isolation.run_isolated`).
            None: no limit, user code runs in the benchmark's processes.
    """

    population: str = "paper"
    seeds: tuple[int, ...] = DEFAULT_SEEDS
    drivers: int = 9
    runs: int = 10
    ill_runs: int | None = None
    duration: float = 30.0
    scenario: str = "paper"
    track: str = "straight"
    curved_runs: int = 4
    noise: Mapping[str, float] = field(default_factory=dict)
    recordings: str | None = None
    illustrative: str | None = None
    training_run: int = 0
    training_runs: int = 1
    training_drivers: int | None = None
    training_speeds: tuple[float, ...] = ()
    generalized_orders: str = "paper"
    equation_error_order: int = DEFAULT_EQUATION_ERROR_ORDER
    speed_scaled_error: bool = True
    batch_size: int = 100
    ljung_box_lags: int = 20
    acf_lags: int = 50
    weight_threshold: float = 0.95
    error_window: float = 5.0
    stress: bool = False
    compare_checks: bool = False
    estimate: bool = True
    filter_settings: Mapping[str, Any] = field(default_factory=dict)
    min_duration: float = 5.0
    allow_incomplete: bool = False
    training_file: str | None = None
    model_time_limit: float | None = DEFAULT_MODEL_TIME_LIMIT

    def __post_init__(self) -> None:
        """Validate every setting (shared validator) and keep the converted values.

        Raises:
            BenchmarkError: naming the setting and its allowed range.
        """
        for name in ("recordings", "training_file"):
            if isinstance(getattr(self, name), os.PathLike):
                object.__setattr__(self, name, os.fspath(getattr(self, name)))
        validate_fields(
            self,
            _SCHEMA,
            describe=lambda path: f"protocol setting '{path}'",
            error=lambda path, message: BenchmarkError(message),
        )
        object.__setattr__(self, "seeds", tuple(self.seeds))
        if self.training_drivers is None:  # the default: several drivers, unless recorded
            default = 0 if self.recordings is not None else DEFAULT_TRAINING_DRIVERS
            object.__setattr__(self, "training_drivers", default)
        object.__setattr__(self, "training_speeds", tuple(float(v) for v in self.training_speeds))
        object.__setattr__(self, "filter_settings", dict(self.filter_settings))
        names = [f.name for f in fields(FilterSettings)]
        for name in self.filter_settings:
            if name not in names:
                raise BenchmarkError(
                    f"protocol setting 'filter_settings': unknown FilterSettings field "
                    f"{name!r} (allowed: {', '.join(names)})" + did_you_mean(name, names)
                )
        try:
            FilterSettings(**self.filter_settings)
        except (TypeError, ValueError) as exc:
            raise BenchmarkError(f"protocol setting 'filter_settings': {exc}") from None
        if self.recordings is None:  # the env's own ranges (noise, run length), named
            try:
                make_config(self.env_config())
            except ConfigError as exc:
                raise BenchmarkError(f"protocol setting: {exc}") from None
        last = self.training_run + self.training_runs - 1
        if self.recordings is None and last >= self.illustrative_runs:
            raise BenchmarkError(
                f"protocol settings 'training_run' = {self.training_run} and 'training_runs' = "
                f"{self.training_runs} need at least {last + 1} runs of the illustrative "
                f"driver, got 'ill_runs' = {self.illustrative_runs}"
            )
        if self.training_drivers and self.recordings is not None:
            raise BenchmarkError(
                "protocol setting 'training_drivers' drives extra synthetic training runs; "
                "with 'recordings' it must be 0 or left unset, its default there (recorded "
                "models train on the illustrative participant's recordings: 'illustrative', "
                "'training_runs')"
            )
        if self.training_speeds and self.recordings is not None:
            raise BenchmarkError(
                "protocol setting 'training_speeds' drives extra synthetic training runs; "
                "with 'recordings' it must be empty (record runs at those speeds instead)"
            )
        for speed in self.training_speeds if self.recordings is None else ():
            try:
                make_config(self.training_speed_config(speed))
            except ConfigError as exc:
                raise BenchmarkError(
                    f"protocol setting 'training_speeds': {speed:g} m/s: {exc}"
                ) from None
        if self.training_file is not None and self.training_runs > 1:
            raise BenchmarkError(
                "protocol setting 'training_runs' > 1 takes the illustrative driver's runs; "
                "with 'training_file' (one recording) it must be 1"
            )

    @property
    def illustrative_runs(self) -> int:
        """Main-track runs of the illustrative driver (synthetic runs)."""
        return self.runs + 4 if self.ill_runs is None else self.ill_runs

    @property
    def run_seeds(self) -> tuple[int | None, ...]:
        """The seeds the protocol runs (recordings: one pass, seed None)."""
        return (None,) if self.recordings is not None else self.seeds

    def training_speed_config(self, speed: float) -> dict[str, Any]:
        """The env config of the extra training run that starts at ``speed`` (m/s): the
        training run's (:meth:`env_config`) with ``initial_state.speed`` set."""
        return deep_merge(self.env_config(training=True), {"initial_state": {"speed": speed}})

    def env_config(self, training: bool = False) -> dict[str, Any]:
        """The env configuration of the synthetic runs (deep-merged onto the defaults): the
        population's study conditions (:attr:`hasa_env.drivers.PopulationSpec.env_config`:
        disturbances, the steering sensor of a wheel study), the run length, the scenario
        (``training``: the training run's, always ``paper``) and the ``noise`` overrides."""
        population = POPULATIONS.get(self.population)
        config = deep_merge(dict(population.env_config) if population else {}, {})
        config["time_limit"] = float(self.duration)
        config["scenario"] = "paper" if training else self.scenario
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
