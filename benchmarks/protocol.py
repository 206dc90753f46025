"""The paper's benchmark protocol (DESIGN.md section 6; Mai et al. sections 4.3 and 5.3).

:func:`run_protocol` does, end to end:

1. **Runs.** Synthetic: a seeded population (:func:`hasa_env.drivers.population`,
   drivers "Ill", "1", ..., "8" by default); every driver drives ``runs``
   runs of ``duration`` s on the main track ("Ill" drives ``ill_runs``, 14 by
   default), plus ``curved_runs`` runs of "Ill" on the curved track; start at
   15 m/s, y = -0.5 m, two equally likely lane centres 1.8 m apart, the true
   one drawn per run by the env. Each run has its own seeds
   (:func:`hasa_env.drivers.run_seeds`, key "<driver>/<track>"), so a run
   is the same whichever task, process or machine produces it. Or: recorded
   drives (``recordings``), one recording per run.
2. **Fit** the two-point and the generalized model (the paper's orders), and
   any user model, on ONE run: run ``training_run`` of the illustrative
   driver on the main track (least squares, :meth:`SteeringModel.fit`).
3. **Score steering** (paper table 1) on every other run: one-step-ahead
   prediction with the measured past steering; per run RMSE (rad), R^2 on
   delta, R^2 on the increments delta(k) - delta(k-1), Ljung-Box p-value of
   the residuals (:func:`hasa_env.steering.score_runs`); per driver the mean
   over runs. The curved-track runs of "Ill" get their own rows.
4. **Estimate** (paper table 2) on the same main-track runs: the
   Gaussian-mixture EKF (:class:`estimators.gm_ekf.GaussianMixtureEKF`)
   with each ARX model, batched over runs, its steering-residual level set
   from the training run (:func:`estimators.tuning.steering_residual_std`)
   and its sensor noise from the run's env config; baselines
   ``no_steering`` (speed + camera + IMU: the lanes cannot be told apart) and
   ``oracle`` (the same filter told the true bias). Per run: RMSE of the
   mixture's lateral-offset estimate (m) over the whole run, and the steps
   until the weight of the true lane exceeds 0.95 for good.

Runs are grouped into tasks of ``batch_size`` consecutive runs (the
vectorized driver runner and the estimator batched over the task's runs;
measured on a 2-core machine, 48 runs in one vector env take 1.1-1.7 s
against about 1 s per run one after another, and one filter over 48 runs
1.0-1.5 s against about 0.5 s per run) and mapped
over local processes or a Dask cluster
(:func:`benchmarks.executor.map_tasks`). Every run is seeded on its own and
the tasks depend only on the protocol (never on the executor or the number
of workers), so results are identical on any executor and worker count. A
different ``batch_size`` can change per-run numbers by floating-point
rounding (batched arithmetic; in practice in their last digits).

A user model that cannot be imported, does not implement
:class:`hasa_env.steering.SteeringModel`, raises while fitting, predicting
or filtering, or predicts NaN is reported in ``errors`` (naming the model
and what went wrong) and left out of the tables; every other model is still
scored.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import math
import os
import pickle
import platform
import subprocess
import time
import traceback
import warnings
from collections import defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from benchmarks import paper_values

__all__ = [
    "BUILTIN_MODELS",
    "BASELINES",
    "BenchmarkError",
    "BenchmarkResult",
    "ModelError",
    "ProtocolConfig",
    "load_user_model",
    "run_protocol",
]

BUILTIN_MODELS = ("two_point", "generalized")
"""Names of the built-in steering models in the results."""

BASELINES = ("no_steering", "oracle")
"""Names of the estimation baselines in the results."""

ILLUSTRATIVE = "Ill"
_ENV_IDS = {"straight": "hasa_env/LaneKeeping-v0", "curved": "hasa_env/LaneKeepingCurved-v0"}
_NOISE_KEYS = ("speed", "camera", "camera_heading", "imu", "steering")
_TABLE_1_KEYS = (
    "two_point_rmse", "two_point_r2_acc", "generalized_rmse", "generalized_r2_acc", "rmse_decrease"
)  # fmt: skip
_TABLE_2_KEYS = ("two_point_mean", "two_point_std", "generalized_mean", "generalized_std")


class BenchmarkError(RuntimeError):
    """The protocol cannot run (invalid configuration or data); nothing was measured."""


class ModelError(Exception):
    """A user model failed; the message names the model and what went wrong.

    Attributes:
        model: the model's name (or its import path if it never loaded).
        stage: "import", "interface", "fit", "predict" or "estimate".
        detail: what went wrong.
    """

    def __init__(self, model: str, stage: str, detail: str) -> None:
        self.model = model
        self.stage = stage
        self.detail = detail
        super().__init__(f"model {model!r} failed ({stage}): {detail}")

    def __reduce__(self) -> tuple[Any, tuple[str, str, str]]:
        # picklable, so it can come back from a worker process
        return (type(self), (self.model, self.stage, self.detail))

    def to_dict(self) -> dict[str, str]:
        return {"model": self.model, "stage": self.stage, "message": str(self)}


# ----------------------------------------------------------------- configuration
@dataclass(frozen=True)
class ProtocolConfig:
    """What :func:`run_protocol` runs (defaults: the paper's protocol).

    Attributes:
        population: name of the synthetic population (:data:`hasa_env.drivers.POPULATIONS`).
        population_seed: seed of the population's driver parameters (None: ``seed``).
        seed: base seed of the runs (each run's seeds derive from it, the
            driver's name, the track and the run index).
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
    population_seed: int | None = None
    seed: int = 0
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
        positive_int("seed", self.seed, 0)
        positive_int("curved_runs", self.curved_runs, 0)
        positive_int("training_run", self.training_run, 0)
        positive_int("batch_size", self.batch_size)
        positive_int("ljung_box_lags", self.ljung_box_lags)
        positive_int("acf_lags", self.acf_lags)
        if self.population_seed is not None:
            positive_int("population_seed", self.population_seed, 0)
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
    def effective_population_seed(self) -> int:
        return self.seed if self.population_seed is None else self.population_seed

    def env_config(self) -> dict[str, Any]:
        """The env configuration of the synthetic runs (deep-merged onto the defaults)."""
        config: dict[str, Any] = {"time_limit": float(self.duration)}
        if self.noise:
            config["noise"] = {k: float(v) for k, v in dict(self.noise).items()}
        return config

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["noise"] = dict(self.noise)
        out["ill_runs"] = self.illustrative_runs if self.recordings is None else None
        out["population_seed"] = self.effective_population_seed
        return out


# -------------------------------------------------------------------- user models
def load_user_model(spec: str) -> Any:
    """Import ``"package.module:Name"`` and return an unfitted steering model.

    ``Name`` may be a :class:`hasa_env.steering.SteeringModel` subclass
    (instantiated without arguments), an instance of one, or a function
    returning one.

    Raises:
        ModelError: naming ``spec``, with stage "import" (module or attribute
            not found, or the module raised) or "interface" (not a steering model).
    """
    from hasa_env.steering import SteeringModel

    if not isinstance(spec, str) or spec.count(":") != 1 or not all(spec.split(":")):
        raise ModelError(
            str(spec),
            "import",
            "expected 'package.module:ClassName' (a module path, a colon, a name in the module)",
        )
    module_name, attribute = spec.split(":")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # noqa: BLE001 - any error in the user's module
        raise ModelError(
            spec, "import", f"cannot import module {module_name!r}: {_describe(exc)}"
        ) from None
    obj: Any = module
    for part in attribute.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise ModelError(
                spec, "import", f"module {module_name!r} has no attribute {attribute!r}"
            ) from None
    hint = (
        "a steering model must subclass hasa_env.steering.SteeringModel "
        "(see its docstring and examples/custom_steering_model.py)"
    )
    if isinstance(obj, SteeringModel):
        model = obj
    elif isinstance(obj, type):
        if not issubclass(obj, SteeringModel):
            raise ModelError(
                spec, "interface", f"{obj.__qualname__} is not a SteeringModel; {hint}"
            )
        try:
            model = obj()
        except TypeError as exc:
            raise ModelError(
                spec, "interface", f"cannot create {obj.__qualname__}(): {_describe(exc)}"
            ) from None
        except Exception as exc:  # noqa: BLE001
            raise ModelError(
                spec, "interface", f"{obj.__qualname__}() raised {_describe(exc)}"
            ) from None
    elif callable(obj):
        try:
            model = obj()
        except Exception as exc:  # noqa: BLE001
            raise ModelError(spec, "interface", f"{attribute}() raised {_describe(exc)}") from None
        if not isinstance(model, SteeringModel):
            raise ModelError(
                spec, "interface", f"{attribute}() returned {type(model).__name__}; {hint}"
            )
    else:
        raise ModelError(spec, "interface", f"{attribute} is a {type(obj).__name__}; {hint}")
    return model


def _describe(exc: BaseException) -> str:
    """``Type: message (file:line)`` of an exception, the line being its innermost frame."""
    text = f"{type(exc).__name__}: {exc}"
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if not f.filename.startswith("<")]
    if frames:
        last = frames[-1]
        text += f" (at {Path(last.filename).name}:{last.lineno} in {last.name})"
    return text


# ---------------------------------------------------------------------- run lists
@dataclass(frozen=True)
class RunRef:
    """One run: synthetic (seeds) or recorded (path).

    Attributes:
        driver: driver name; track: "straight" or "curved"; index: run index
            of this driver on this track; env_seed/driver_seed: seeds of a
            synthetic run; path: CSV of a recorded run.
    """

    driver: str
    track: str
    index: int
    env_seed: int | None = None
    driver_seed: int | None = None
    path: str | None = None

    @property
    def key(self) -> tuple[str, str, int]:
        return (self.driver, self.track, self.index)


@dataclass(frozen=True)
class FittedModel:
    """A fitted model as the tasks receive it.

    Attributes:
        name: the name in the results; kind: "builtin" or "user";
        model: the fitted :class:`SteeringModel`; residual_std: its one-step
        residual level on the training run for the filter (rad; None: no
        ARX form, no estimation).
    """

    name: str
    kind: str
    model: Any
    residual_std: float | None


@dataclass(frozen=True)
class ChunkTask:
    """The work of one task: a batch of runs of one track."""

    runs: tuple[RunRef, ...]
    track: str
    env_config: Mapping[str, Any]
    driver_params: Mapping[str, Any]
    models: tuple[FittedModel, ...]
    estimate: bool
    ljung_box_lags: int
    acf_lags: int
    weight_threshold: float
    error_window: float
    trace_runs: frozenset[tuple[str, str, int]]
    detail_driver: str


@dataclass
class ChunkResult:
    """What a task returns: per-run rows, model failures, plot data."""

    steering: list[dict[str, Any]] = field(default_factory=list)
    estimation: list[dict[str, Any]] = field(default_factory=list)
    failures: list[ModelError] = field(default_factory=list)
    traces: dict[tuple[str, str, int], dict[str, Any]] = field(default_factory=dict)
    early_errors: dict[str, list[np.ndarray]] = field(default_factory=dict)
    acf: dict[str, list[np.ndarray]] = field(default_factory=dict)
    seconds: float = 0.0


# --------------------------------------------------------------------- the result
@dataclass
class BenchmarkResult:
    """Everything :func:`run_protocol` measured (see :meth:`to_json_dict`).

    Attributes:
        config: the protocol configuration (dict).
        models: per model: name, kind, spec, parameters, fit statistics, notes.
        steering: rows per (driver, model), main track (paper table 1).
        curved: rows per (driver, model) on the curved track.
        estimation: rows per (driver, model) incl. the baselines (paper table 2).
        summary: per model, means over drivers (and the rank for ``score``).
        runs_steering, runs_estimation: per-run rows.
        errors: failed user models (:meth:`ModelError.to_dict`).
        drivers: the drivers (synthetic parameters or recording files).
        plots: data of the figures (not written to results.json).
        timing: wall-clock seconds per phase; executor: how tasks ran.
    """

    config: dict[str, Any]
    models: list[dict[str, Any]]
    steering: list[dict[str, Any]]
    curved: list[dict[str, Any]]
    estimation: list[dict[str, Any]]
    summary: list[dict[str, Any]]
    runs_steering: list[dict[str, Any]]
    runs_estimation: list[dict[str, Any]]
    errors: list[dict[str, str]]
    drivers: list[dict[str, Any]]
    plots: dict[str, Any]
    timing: dict[str, float]
    executor: dict[str, Any]
    versions: dict[str, str]
    notes: list[str] = field(default_factory=list)

    @property
    def model_names(self) -> list[str]:
        """Steering models that were scored, built-ins first."""
        return [m["name"] for m in self.models if m.get("error") is None]

    def to_json_dict(self) -> dict[str, Any]:
        """The JSON document of ``results.json`` (NaN and infinities become null)."""
        doc = {
            "format": "hasa_bench.results",
            "format_version": 1,
            "config": self.config,
            "versions": self.versions,
            "executor": self.executor,
            "timing_seconds": self.timing,
            "drivers": self.drivers,
            "models": self.models,
            "steering": self.steering,
            "curved": self.curved,
            "estimation": self.estimation,
            "summary": self.summary,
            "runs_steering": self.runs_steering,
            "runs_estimation": self.runs_estimation,
            "errors": self.errors,
            "notes": self.notes,
            "paper": {
                "table_1": {
                    d: dict(zip(_TABLE_1_KEYS, v, strict=True))
                    for d, v in paper_values.TABLE_1.items()
                },
                "table_2": {
                    d: dict(zip(_TABLE_2_KEYS, v, strict=True))
                    for d, v in paper_values.TABLE_2.items()
                },
                "curved": {k: {"r2": v[0], "rmse": v[1]} for k, v in paper_values.CURVED.items()},
                "no_steering_lateral_rmse": paper_values.NO_STEERING_LATERAL_RMSE,
            },
        }
        return _json_clean(doc)


def _json_clean(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _json_clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_clean(value.tolist())
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    return value


# ------------------------------------------------------------------- the protocol
def run_protocol(
    config: ProtocolConfig | None = None,
    user_models: Sequence[str] = (),
    *,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> BenchmarkResult:
    """Run the benchmark protocol (see the module docstring).

    Args:
        config: the protocol (default: the paper's).
        user_models: import paths ``"package.module:Name"`` of user steering
            models to score next to the built-in ones.
        workers: local worker processes (None: one per CPU; 1: in this process).
        scheduler: a Dask scheduler address (``"tcp://host:8786"``) or an
            object with ``scheduler_address``; tasks then run on that cluster
            (its workers must be able to import the user models).
        progress: called as ``progress(phase, done, total)``; phases
            "runs" (done/total runs) and messages with total 0.

    Returns:
        A :class:`BenchmarkResult`; failed user models are in ``errors``.

    Raises:
        BenchmarkError: the configuration or the data do not allow the
            protocol (nothing measured).
    """
    config = config or ProtocolConfig()
    say = progress or (lambda phase, done, total: None)
    timing: dict[str, float] = {}
    start = time.perf_counter()
    errors: list[ModelError] = []
    notes: list[str] = []

    # 1. the runs
    if config.recordings is not None:
        plan = _recording_plan(config)
    else:
        plan = _synthetic_plan(config)
    illustrative = plan["illustrative"]
    main_runs: list[RunRef] = plan["main"]
    curved_runs: list[RunRef] = plan["curved"]
    training = next(
        (r for r in main_runs if r.driver == illustrative and r.index == config.training_run), None
    )
    if training is None:
        raise BenchmarkError(
            f"no run {config.training_run} of the illustrative driver {illustrative!r} on the "
            f"{config.track} track to train on"
        )
    validation = [r for r in main_runs if r is not training]
    if not validation:
        raise BenchmarkError(
            f"no validation runs: found only the training run ({len(main_runs)} run(s) on the "
            f"{config.track} track); the protocol scores the models on the other runs"
        )
    notes.extend(plan.get("notes", []))

    # 2. fit on the training run
    say("generating the training run and fitting the models", 0, 0)
    train_frame = _load_frames([training], config.track, plan["env_config"], plan["params"])[0]
    timing["training_run"] = time.perf_counter() - start
    t_fit = time.perf_counter()
    fitted, model_info = _fit_models(train_frame, user_models, errors)
    timing["fit"] = time.perf_counter() - t_fit

    # 3. tasks
    trace_runs = set()
    plot_run = next((r for r in validation if r.driver == illustrative), validation[0])
    trace_runs.add(plot_run.key)
    if curved_runs:
        trace_runs.add(curved_runs[0].key)
    common = {
        "env_config": plan["env_config"],
        "driver_params": plan["params"],
        "models": tuple(fitted),
        "ljung_box_lags": config.ljung_box_lags,
        "acf_lags": config.acf_lags,
        "weight_threshold": config.weight_threshold,
        "error_window": config.error_window,
        "trace_runs": frozenset(trace_runs),
        "detail_driver": illustrative,
    }
    from benchmarks.executor import default_workers, map_tasks

    n_workers = default_workers() if workers is None else max(1, int(workers))
    batch = config.batch_size
    tasks = [
        ChunkTask(runs=tuple(chunk), track="curved", estimate=False, **common)
        for chunk in _chunks(curved_runs, batch)
    ]
    tasks += [
        ChunkTask(runs=tuple(chunk), track=config.track, estimate=True, **common)
        for chunk in _chunks(validation, batch)
    ]
    total_runs = sum(len(t.runs) for t in tasks)
    done_runs = np.cumsum([len(t.runs) for t in tasks])
    say("runs", 0, total_runs)

    def on_task(done: int) -> None:
        say("runs", int(done_runs[done - 1]), total_runs)

    t_tasks = time.perf_counter()
    try:
        chunk_results: list[ChunkResult] = map_tasks(
            run_chunk, tasks, workers=workers, scheduler=scheduler, progress=on_task
        )
    except (OSError, TimeoutError) as exc:
        if scheduler is None:
            raise
        raise BenchmarkError(
            f"cannot run the tasks on the Dask scheduler {scheduler!r}: {_describe(exc)}"
        ) from None
    timing["tasks"] = time.perf_counter() - t_tasks
    timing["task_cpu_seconds"] = float(sum(c.seconds for c in chunk_results))

    # 4. aggregate
    say("aggregating", 0, 0)
    failed: dict[str, ModelError] = {}
    for chunk in chunk_results:
        for failure in chunk.failures:
            failed.setdefault(failure.model, failure)
    errors.extend(failed.values())
    for info in model_info:
        if info["name"] in failed:
            info["error"] = str(failed[info["name"]])
    ok_models = [m.name for m in fitted if m.name not in failed]
    runs_steering = sorted(
        (row for c in chunk_results for row in c.steering if row["model"] not in failed),
        key=_row_order(plan["driver_order"], ok_models),
    )
    estimator_names = [
        m.name for m in fitted if m.residual_std is not None and m.name not in failed
    ] + list(BASELINES)
    runs_estimation = sorted(
        (row for c in chunk_results for row in c.estimation if row["model"] not in failed),
        key=_row_order(plan["driver_order"], estimator_names),
    )
    steering_rows = _aggregate_steering(
        [r for r in runs_steering if r["track"] == config.track], ok_models
    )
    curved_rows = (
        _aggregate_steering([r for r in runs_steering if r["track"] == "curved"], ok_models)
        if config.track != "curved"
        else []
    )
    estimation_rows = _aggregate_estimation(runs_estimation)
    summary = _summary(steering_rows, estimation_rows, ok_models)
    plots = _plot_data(chunk_results, fitted, failed, plot_run, curved_runs, train_frame, config)
    timing["total"] = time.perf_counter() - start
    executor = {
        "kind": "dask" if scheduler is not None else "processes",
        "workers": None if scheduler is not None else n_workers,
        "scheduler": None
        if scheduler is None
        else str(getattr(scheduler, "scheduler_address", scheduler)),
        "tasks": len(tasks),
        "batch_size": batch,
    }
    return BenchmarkResult(
        config=config.to_dict() | {"illustrative": illustrative, "user_models": list(user_models)},
        models=model_info,
        steering=steering_rows,
        curved=curved_rows,
        estimation=estimation_rows,
        summary=summary,
        runs_steering=runs_steering,
        runs_estimation=runs_estimation,
        errors=[e.to_dict() for e in errors],
        drivers=plan["drivers"],
        plots=plots,
        timing=timing,
        executor=executor,
        versions=_versions(),
        notes=notes,
    )


def _chunks(items: Sequence[RunRef], size: int) -> list[list[RunRef]]:
    return [list(items[i : i + size]) for i in range(0, len(items), size)]


def _row_order(drivers: Sequence[str], models: Sequence[str]) -> Callable[[dict], tuple]:
    d_rank = {d: i for i, d in enumerate(drivers)}
    m_rank = {m: i for i, m in enumerate(models)}
    return lambda row: (
        d_rank.get(row["driver"], len(d_rank)),
        row["driver"],
        row.get("track", ""),
        m_rank.get(row["model"], len(m_rank)),
        row["run"],
    )


# ---------------------------------------------------------------------- planning
def _synthetic_plan(config: ProtocolConfig) -> dict[str, Any]:
    from hasa_env.drivers import population, run_seeds

    try:
        params = population(config.population, config.effective_population_seed, config.drivers)
    except ValueError as exc:
        raise BenchmarkError(str(exc)) from None
    by_name = {p.name: p for p in params}
    main: list[RunRef] = []
    for p in params:
        count = config.illustrative_runs if p.name == ILLUSTRATIVE else config.runs
        for i, (env_seed, driver_seed) in enumerate(
            run_seeds(config.seed, count, f"{p.name}/{config.track}")
        ):
            main.append(RunRef(p.name, config.track, i, env_seed, driver_seed))
    curved: list[RunRef] = []
    if config.track != "curved":
        for i, (env_seed, driver_seed) in enumerate(
            run_seeds(config.seed, config.curved_runs, f"{ILLUSTRATIVE}/curved")
        ):
            curved.append(RunRef(ILLUSTRATIVE, "curved", i, env_seed, driver_seed))
    drivers = [
        {
            "driver": p.name,
            "runs": config.illustrative_runs if p.name == ILLUSTRATIVE else config.runs,
            "curved_runs": len(curved) if p.name == ILLUSTRATIVE else 0,
            "parameters": p.to_dict(),
        }
        for p in params
    ]
    return {
        "illustrative": ILLUSTRATIVE,
        "main": main,
        "curved": curved,
        "params": by_name,
        "env_config": config.env_config(),
        "drivers": drivers,
        "driver_order": [p.name for p in params],
    }


def _recording_plan(config: ProtocolConfig) -> dict[str, Any]:
    root = Path(config.recordings or "")
    if not root.is_dir():
        raise BenchmarkError(f"recordings directory {str(root)!r} does not exist")
    found: dict[tuple[str, str], list[Path]] = defaultdict(list)
    skipped: list[str] = []
    for csv in sorted(root.rglob("*.csv")):
        sidecar = csv.with_suffix(".json")
        try:
            meta = json.loads(sidecar.read_text(encoding="utf-8"))
            track = str(meta["config"]["track"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            skipped.append(f"{csv}: no readable sidecar with config.track ({type(exc).__name__})")
            continue
        metadata = meta.get("metadata") or {}
        driver = metadata.get("driver") or metadata.get("participant")
        if not driver:
            relative = csv.parent.relative_to(root)
            driver = relative.parts[0] if relative.parts else "driver"
        found[(str(driver), track)].append(csv)
    if not found:
        raise BenchmarkError(f"no recordings (*.csv with a .json sidecar) in {str(root)!r}")
    names = sorted({d for d, _ in found})
    illustrative = config.illustrative or (ILLUSTRATIVE if ILLUSTRATIVE in names else names[0])
    if illustrative not in names:
        raise BenchmarkError(
            f"illustrative driver {illustrative!r} has no recordings in {str(root)!r}; "
            f"drivers: {', '.join(names)}"
        )
    order = [illustrative] + [n for n in names if n != illustrative]
    main, curved, drivers = [], [], []
    for name in order:
        main_paths = found.get((name, config.track), [])
        main += [RunRef(name, config.track, i, path=str(p)) for i, p in enumerate(main_paths)]
        curved_paths = found.get((name, "curved"), []) if config.track != "curved" else []
        if name == illustrative:
            curved += [RunRef(name, "curved", i, path=str(p)) for i, p in enumerate(curved_paths)]
        drivers.append(
            {
                "driver": name,
                "runs": len(main_paths),
                "curved_runs": len(curved_paths) if name == illustrative else 0,
                "recordings": [str(p) for p in main_paths + list(curved_paths)],
            }
        )
    notes = [f"recordings: {len(main) + len(curved)} runs of {len(names)} drivers from {root}"]
    notes += [f"skipped {s}" for s in skipped]
    return {
        "illustrative": illustrative,
        "main": main,
        "curved": curved,
        "params": {},
        "env_config": {},
        "drivers": drivers,
        "driver_order": order,
        "notes": notes,
    }


def _load_frames(
    runs: Sequence[RunRef],
    track: str,
    env_config: Mapping[str, Any],
    params: Mapping[str, Any],
) -> list[pd.DataFrame]:
    """The recordings of ``runs`` (all on ``track``): generated in one vector env, or loaded."""
    if not runs:
        return []
    if runs[0].path is not None:
        from hasa_env.recording import load_recording

        frames = []
        for ref in runs:
            rec = load_recording(ref.path)
            frame = rec.data
            frame.attrs = {
                "config": rec.meta["config"],
                "track": rec.meta["config"]["track"],
                "driver": ref.driver,
                "path": ref.path,
            }
            frames.append(frame)
        return frames
    from hasa_env.drivers import SyntheticDriver, run_drivers

    drivers: dict[str, Any] = {}
    cars = []
    for ref in runs:
        if ref.driver not in drivers:
            drivers[ref.driver] = SyntheticDriver(params[ref.driver])
        cars.append(drivers[ref.driver])
    seeds = [(int(r.env_seed), int(r.driver_seed)) for r in runs]  # type: ignore[arg-type]
    return run_drivers(cars, seeds, _ENV_IDS[track], dict(env_config))


# ----------------------------------------------------------------------- fitting
def _fit_models(
    train: pd.DataFrame, user_specs: Sequence[str], errors: list[ModelError]
) -> tuple[list[FittedModel], list[dict[str, Any]]]:
    from hasa_env.steering import GeneralizedModel, TwoPointModel
    from hasa_env.steering.features import steering_features

    dt = steering_features(train).attrs.get("dt", 0.01)
    candidates: list[tuple[str, str, str | None, Any]] = [
        ("two_point", "builtin", None, TwoPointModel(dt=dt)),
        ("generalized", "builtin", None, GeneralizedModel(dt=dt)),
    ]
    infos: list[dict[str, Any]] = []
    used = set(BUILTIN_MODELS) | set(BASELINES)
    for spec in user_specs:
        try:
            model = load_user_model(spec)
        except ModelError as exc:
            errors.append(exc)
            infos.append({"name": spec, "kind": "user", "spec": spec, "error": str(exc)})
            continue
        name = str(getattr(model, "name", "") or spec)
        if name in used:
            name = spec if spec not in used else f"{spec}#{len(used)}"
        used.add(name)
        candidates.append((name, "user", spec, model))
    fitted: list[FittedModel] = []
    for name, kind, spec, model in candidates:
        info: dict[str, Any] = {"name": name, "kind": kind, "spec": spec}
        try:
            model_fitted, info_fit = _fit_one(name, model, train)
        except ModelError as exc:
            if kind == "builtin":
                raise BenchmarkError(f"the built-in {exc}") from None
            errors.append(exc)
            info["error"] = str(exc)
            infos.append(info)
            continue
        info.update(info_fit)
        info["error"] = None
        fitted.append(FittedModel(name, kind, model_fitted, info_fit["filter_residual_std"]))
        infos.append(info)
    return fitted, infos


def _fit_one(name: str, model: Any, train: pd.DataFrame) -> tuple[Any, dict[str, Any]]:
    """Fit one model on the training run; its description; ModelError if it fails."""
    from estimators.tuning import steering_residual_std
    from hasa_env.steering import IdentifiabilityWarning, SteeringModel

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", IdentifiabilityWarning)
        try:
            fitted = model.fit(train)
        except Exception as exc:  # noqa: BLE001 - a user model may raise anything
            raise ModelError(name, "fit", f"fit() raised {_describe(exc)}") from None
    if not isinstance(fitted, SteeringModel):
        raise ModelError(
            name, "fit", f"fit() returned {type(fitted).__name__}, expected a fitted SteeringModel"
        )
    if not fitted.is_fitted:
        raise ModelError(name, "fit", "fit() returned a model without parameters")
    try:
        pickle.dumps(fitted)
    except Exception as exc:  # noqa: BLE001
        raise ModelError(
            name, "fit", f"the fitted model cannot be pickled for the workers: {_describe(exc)}"
        ) from None
    fitted.name = name
    result = fitted.fit_result
    info: dict[str, Any] = {
        "model_type": getattr(fitted, "model_type", ""),
        "parameters": fitted.parameters,
        "standard_errors": fitted.standard_errors,
        "training": None,
        "identifiability": None,
        "warnings": [str(w.message) for w in caught if issubclass(w.category, UserWarning)],
    }
    if result is not None:
        info["training"] = {
            "n_obs": result.n_obs,
            "residual_std": result.residual_std,
            "r2": result.r2,
            "r2_increments": result.r2_increments,
            "bic": result.bic,
        }
        if result.identifiability is not None:
            info["identifiability"] = {
                "static_lane_gain": result.identifiability.static_lane_gain,
                "identifiable": result.identifiability.ok,
                "message": result.identifiability.message,
            }
    try:
        arx = fitted.arx()
    except Exception as exc:  # noqa: BLE001
        raise ModelError(name, "fit", f"arx() raised {_describe(exc)}") from None
    residual = None
    if arx is not None:
        try:
            residual = steering_residual_std(arx, train, decision_lag=fitted.decision_lag)
        except Exception as exc:  # noqa: BLE001
            raise ModelError(
                name, "fit", f"its ARX form cannot predict the training run: {_describe(exc)}"
            ) from None
        if not (math.isfinite(residual) and residual >= 0):
            raise ModelError(name, "fit", f"its ARX form predicts non-finite steering ({residual})")
    info["arx"] = arx is not None
    info["filter_residual_std"] = residual
    if arx is None:
        info["note"] = "not an ARX model: scored on steering only (the estimator needs arx())"
    return fitted, info


# ------------------------------------------------------------------- the tasks
def run_chunk(task: ChunkTask) -> ChunkResult:
    """Score every model on a batch of runs (one task; runs in any process).

    Per run and model: steering scores (and, for the illustrative driver,
    residual autocorrelations); per run and estimator (main track only):
    lateral RMSE, steps to decide the lane, and the first seconds of lateral
    error. A user model that fails is reported in ``failures``.
    """
    start = time.process_time()
    frames = _load_frames(task.runs, task.track, task.env_config, task.driver_params)
    out = ChunkResult()
    failed: set[str] = set()
    predictions: dict[str, list[np.ndarray]] = {}
    for fm in task.models:
        try:
            predictions[fm.name] = _score_model(fm, task, frames, out)
        except ModelError as exc:
            if fm.kind == "builtin":
                raise RuntimeError(str(exc)) from None
            out.failures.append(exc)
            failed.add(fm.name)
            out.steering = [r for r in out.steering if r["model"] != fm.name]
    for ref, frame in zip(task.runs, frames, strict=True):
        if ref.key in task.trace_runs:
            trace = out.traces.setdefault(ref.key, {})
            trace["time"] = frame["time"].to_numpy()
            trace["steering"] = frame["steering"].to_numpy()
            trace["predictions"] = {
                name: preds[task.runs.index(ref)]
                for name, preds in predictions.items()
                if name not in failed
            }
    if task.estimate:
        _estimate(task, frames, failed, out)
    out.seconds = time.process_time() - start
    return out


def _warm_mask(features: pd.DataFrame, model: Any) -> np.ndarray:
    """Rows where every feature the model uses is finite at lags 0..max_lag."""
    try:
        used = sorted({r.feature for r in model.regressors} | {"delta"})
        lag = int(model.max_lag)
    except Exception:  # noqa: BLE001 - a broken regressors property
        used, lag = list(features.columns), 0
    used = [c for c in used if c in features.columns]
    finite = np.all(np.isfinite(features[used].to_numpy(dtype=np.float64)), axis=1)
    if lag > 0:
        window = np.lib.stride_tricks.sliding_window_view(
            np.concatenate([np.zeros(lag, bool), finite]), lag + 1
        )
        finite = window.all(axis=1)
    return finite


def _score_model(
    fm: FittedModel, task: ChunkTask, frames: Sequence[pd.DataFrame], out: ChunkResult
) -> list[np.ndarray]:
    from hasa_env.steering import residual_diagnostics, score_runs

    model = fm.model
    preds = []
    for ref, frame in zip(task.runs, frames, strict=True):
        where = f"driver {ref.driver!r} run {ref.index} ({ref.track})"
        try:
            features = model.features(frame)
            prediction = np.asarray(model.predict_features(features), dtype=np.float64)
        except Exception as exc:  # noqa: BLE001
            raise ModelError(fm.name, "predict", f"on {where}: {_describe(exc)}") from None
        if prediction.shape != (len(features),):
            raise ModelError(
                fm.name,
                "predict",
                f"on {where}: predict_features returned shape {prediction.shape}, "
                f"expected ({len(features)},)",
            )
        warm = _warm_mask(features, model)
        bad = warm & ~np.isfinite(prediction)
        if bad.any():
            raise ModelError(
                fm.name,
                "predict",
                f"predicted NaN or inf at {int(bad.sum())} of {int(warm.sum())} samples of "
                f"{where} (first at t = {float(frame['time'].iloc[int(np.argmax(bad))]):.2f} s)",
            )
        try:
            scores = score_runs(model, [features], lags=task.ljung_box_lags, free_run=False)
        except Exception as exc:  # noqa: BLE001
            raise ModelError(fm.name, "predict", f"scoring {where}: {_describe(exc)}") from None
        row = scores.iloc[0]
        out.steering.append(
            {
                "driver": ref.driver,
                "track": ref.track,
                "run": ref.index,
                "model": fm.name,
                "rmse": float(row["rmse"]),
                "r2": float(row["r2"]),
                "r2_increments": float(row["r2_increments"]),
                "ljung_box_p": float(row["ljung_box_p"]),
                "n": int(row["n"]),
            }
        )
        if task.estimate and ref.driver == task.detail_driver:
            residual = features["delta"].to_numpy(dtype=np.float64) - prediction
            diag = residual_diagnostics(residual[np.isfinite(residual)], lags=task.acf_lags)
            out.acf.setdefault(fm.name, []).append(diag.autocorrelation)
        preds.append(prediction)
    return preds


def _filter_key(frame: pd.DataFrame) -> str:
    config = frame.attrs.get("config") or {}
    keep = {
        "noise": config.get("noise"),
        "hypotheses": (config.get("markings") or {}).get("hypotheses"),
        "rate": (config.get("sim_frequency"), config.get("action_repeat")),
    }
    return json.dumps(keep, sort_keys=True, default=str)


def _settle_steps(true_weight: np.ndarray, valid: np.ndarray, threshold: float) -> np.ndarray:
    """(R,) first step from which the true-lane weight stays above ``threshold`` (NaN: never)."""
    above = (true_weight > threshold) | ~valid
    # last step that is below the threshold; settled from the next one on
    below = ~above
    any_below = below.any(axis=1)
    last_below = np.where(any_below, below.shape[1] - 1 - np.argmax(below[:, ::-1], axis=1), -1)
    steps = (last_below + 1).astype(np.float64)
    lengths = valid.sum(axis=1)
    steps[steps >= lengths] = np.nan
    return steps


def _estimate(
    task: ChunkTask, frames: Sequence[pd.DataFrame], failed: set[str], out: ChunkResult
) -> None:
    from estimators.baselines import NoSteeringEKF, OracleEKF
    from estimators.gm_ekf import FilterSettings, GaussianMixtureEKF
    from estimators.offline import run_estimator

    groups: dict[str, list[int]] = defaultdict(list)
    for i, frame in enumerate(frames):
        groups[_filter_key(frame)].append(i)
    estimators: list[tuple[str, str, Callable[[Any], Any]]] = []
    for fm in task.models:
        if fm.residual_std is None or fm.name in failed:
            continue

        def make(settings: Any, fm: FittedModel = fm) -> Any:
            return GaussianMixtureEKF(
                fm.model.arx(),
                replace(settings, steering_residual_std=max(fm.residual_std, 1e-9)),
                decision_lag=fm.model.decision_lag,
            )

        estimators.append((fm.name, fm.kind, make))
    estimators.append(("no_steering", "baseline", lambda s: NoSteeringEKF(s)))
    estimators.append(("oracle", "baseline", lambda s: OracleEKF(None, s)))
    for name, kind, make in estimators:
        rows: list[dict[str, Any]] = []
        try:
            for indices in groups.values():
                group = [frames[i] for i in indices]
                settings = FilterSettings.from_env_config(group[0].attrs["config"])
                result = run_estimator(make(settings), group)
                rows += _estimation_rows(task, indices, result, name, out)
        except ModelError:
            raise
        except Exception as exc:  # noqa: BLE001
            if kind != "user":
                raise
            out.failures.append(ModelError(name, "estimate", f"the filter raised {_describe(exc)}"))
            continue
        bad = [r for r in rows if not math.isfinite(r["lateral_rmse"])]
        if bad and kind == "user":
            out.failures.append(
                ModelError(
                    name,
                    "estimate",
                    f"the filter's lateral estimate became NaN or inf on {len(bad)} run(s), "
                    f"e.g. driver {bad[0]['driver']!r} run {bad[0]['run']}",
                )
            )
            continue
        out.estimation += rows


def _estimation_rows(
    task: ChunkTask, indices: Sequence[int], result: Any, name: str, out: ChunkResult
) -> list[dict[str, Any]]:
    refs = [task.runs[i] for i in indices]
    error = result.lateral_error()
    rmse = np.sqrt(np.nanmean(error * error, axis=1))
    bias0 = result.truth["bias"][:, 0]
    true_weight = result.true_lane_weight()  # (R, T): weight of the hypotheses equal to the bias
    steps = _settle_steps(true_weight, result.valid, task.weight_threshold)
    final_true = result.picked_true_lane()
    n_window = int(round(task.error_window / float(np.nanmedian(np.diff(result.time[0]))))) + 1
    rows = []
    for j, ref in enumerate(refs):
        rows.append(
            {
                "driver": ref.driver,
                "run": ref.index,
                "model": name,
                "lateral_rmse": float(rmse[j]),
                "steps_to_decide": None if not np.isfinite(steps[j]) else int(steps[j]),
                "true_lane_final": bool(final_true[j]),
                "bias": float(bias0[j]),
            }
        )
        if ref.driver == task.detail_driver:
            out.early_errors.setdefault(name, []).append(error[j, :n_window].copy())
        if ref.key in task.trace_runs:
            trace = out.traces.setdefault(ref.key, {})
            est = trace.setdefault("estimates", {})
            est[name] = {
                "lateral": result.mean[j, : result.lengths[j], 1].copy(),
                "true_weight": true_weight[j, : result.lengths[j]].copy(),
                "hypotheses": result.hypotheses[j].copy(),
            }
            trace["truth_lateral"] = result.truth["lateral_offset"][j, : result.lengths[j]].copy()
            trace["bias"] = float(bias0[j])
    return rows


# ------------------------------------------------------------------- aggregation
def _mean(values: Sequence[float]) -> float:
    arr = np.asarray(values, dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    return float(arr.mean()) if arr.size else float("nan")


def _std(values: Sequence[float]) -> float:
    arr = np.asarray(values, dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    return float(arr.std(ddof=1)) if arr.size > 1 else float("nan")


def _aggregate_steering(rows: Sequence[dict[str, Any]], models: Sequence[str]) -> list[dict]:
    """Per (driver, model): means over runs; RMSE decrease vs the two-point model; paper values."""
    grouped: dict[tuple[str, str], list[dict]] = defaultdict(list)
    order: list[str] = []
    for row in rows:
        if row["driver"] not in order:
            order.append(row["driver"])
        grouped[(row["driver"], row["model"])].append(row)
    out = []
    for driver in order:
        base = grouped.get((driver, "two_point"))
        base_rmse = _mean([r["rmse"] for r in base]) if base else float("nan")
        for model in models:
            runs = grouped.get((driver, model))
            if not runs:
                continue
            rmse = _mean([r["rmse"] for r in runs])
            p_values = np.array([r["ljung_box_p"] for r in runs], dtype=np.float64)
            finite_p = p_values[np.isfinite(p_values)]
            entry = {
                "driver": driver,
                "track": runs[0]["track"],
                "model": model,
                "n_runs": len(runs),
                "n_samples": int(sum(r["n"] for r in runs)),
                "rmse": rmse,
                "rmse_std": _std([r["rmse"] for r in runs]),
                "r2": _mean([r["r2"] for r in runs]),
                "r2_increments": _mean([r["r2_increments"] for r in runs]),
                "rmse_decrease_vs_two_point": (
                    None if model == "two_point" else 1.0 - rmse / base_rmse
                ),
                "ljung_box_p_median": float(np.median(finite_p)) if finite_p.size else None,
                "white_runs": int(np.sum(finite_p > 0.05)),
            }
            entry.update(_paper_steering(driver, model, runs[0]["track"]))
            out.append(entry)
    return out


def _paper_steering(driver: str, model: str, track: str) -> dict[str, Any]:
    keys = {"paper_rmse": None, "paper_r2": None, "paper_rmse_decrease": None}
    if track == "curved":
        if model in paper_values.CURVED and driver == ILLUSTRATIVE:
            r2, rmse = paper_values.CURVED[model]
            keys.update(paper_rmse=rmse, paper_r2=r2)
            if model == "generalized":
                base = paper_values.CURVED["two_point"][1]
                keys["paper_rmse_decrease"] = 1.0 - rmse / base
        return keys
    values = paper_values.TABLE_1.get(driver)
    if values is None or model not in BUILTIN_MODELS:
        return keys
    if model == "two_point":
        keys.update(paper_rmse=values[0], paper_r2=values[1])
    else:
        keys.update(paper_rmse=values[2], paper_r2=values[3], paper_rmse_decrease=values[4])
    return keys


def _aggregate_estimation(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    grouped: dict[tuple[str, str], list[dict]] = defaultdict(list)
    order: list[tuple[str, str]] = []
    for row in rows:
        key = (row["driver"], row["model"])
        if key not in grouped:
            order.append(key)
        grouped[key].append(row)
    out = []
    for driver, model in order:
        runs = grouped[(driver, model)]
        rmse = [r["lateral_rmse"] for r in runs]
        steps = np.array(
            [np.nan if r["steps_to_decide"] is None else r["steps_to_decide"] for r in runs]
        )
        decided = steps[np.isfinite(steps)]
        entry = {
            "driver": driver,
            "model": model,
            "n_runs": len(runs),
            "lateral_rmse_mean": _mean(rmse),
            "lateral_rmse_std": _std(rmse),
            "lateral_rmse_max": float(np.nanmax(rmse)) if runs else None,
            "steps_to_decide_median": float(np.median(decided)) if decided.size else None,
            "steps_to_decide_max": float(np.max(decided)) if decided.size else None,
            "decided_runs": int(decided.size),
            "true_lane_final_runs": int(sum(r["true_lane_final"] for r in runs)),
            "paper_lateral_rmse_mean": None,
            "paper_lateral_rmse_std": None,
        }
        paper = paper_values.TABLE_2.get(driver)
        if paper is not None and model in BUILTIN_MODELS:
            offset = 0 if model == "two_point" else 2
            entry["paper_lateral_rmse_mean"] = paper[offset]
            entry["paper_lateral_rmse_std"] = paper[offset + 1]
        elif model == "no_steering":
            entry["paper_lateral_rmse_mean"] = paper_values.NO_STEERING_LATERAL_RMSE
        out.append(entry)
    return out


def _summary(
    steering: Sequence[dict], estimation: Sequence[dict], models: Sequence[str]
) -> list[dict[str, Any]]:
    """Per model: means over drivers; ranks by lateral RMSE and by steering RMSE."""
    rows = []
    for name in list(models) + [b for b in BASELINES]:
        s = [r for r in steering if r["model"] == name]
        e = [r for r in estimation if r["model"] == name]
        if not s and not e:
            continue
        rows.append(
            {
                "model": name,
                "kind": "builtin"
                if name in BUILTIN_MODELS
                else ("baseline" if name in BASELINES else "user"),
                "drivers": len({r["driver"] for r in (s or e)}),
                "rmse": _mean([r["rmse"] for r in s]) if s else None,
                "r2_increments": _mean([r["r2_increments"] for r in s]) if s else None,
                "rmse_decrease_vs_two_point": _mean(
                    [r["rmse_decrease_vs_two_point"] for r in s if r["model"] != "two_point"]
                )
                if s and name != "two_point"
                else None,
                "white_runs": int(sum(r["white_runs"] for r in s)) if s else None,
                "runs": int(sum(r["n_runs"] for r in s)) if s else int(sum(r["n_runs"] for r in e)),
                "lateral_rmse": _mean([r["lateral_rmse_mean"] for r in e]) if e else None,
                "decided_runs": int(sum(r["decided_runs"] for r in e)) if e else None,
                "estimated_runs": int(sum(r["n_runs"] for r in e)) if e else None,
            }
        )
    for key, rank_key in (("rmse", "rank_steering"), ("lateral_rmse", "rank_lateral")):
        ranked = sorted(
            (r for r in rows if r["kind"] != "baseline" and _finite(r[key])),
            key=lambda r, key=key: r[key],
        )
        for i, r in enumerate(ranked, start=1):
            r[rank_key] = i
        for r in rows:
            r.setdefault(rank_key, None)
    return rows


def _finite(value: Any) -> bool:
    return value is not None and isinstance(value, int | float) and math.isfinite(value)


def _plot_data(
    chunks: Sequence[ChunkResult],
    fitted: Sequence[FittedModel],
    failed: Mapping[str, ModelError],
    plot_run: RunRef,
    curved_runs: Sequence[RunRef],
    train: pd.DataFrame,
    config: ProtocolConfig,
) -> dict[str, Any]:
    from hasa_env.steering import residual_diagnostics

    traces: dict[tuple, dict] = {}
    early: dict[str, list[np.ndarray]] = defaultdict(list)
    acf: dict[str, list[np.ndarray]] = defaultdict(list)
    for chunk in chunks:
        for key, trace in chunk.traces.items():
            traces.setdefault(key, {}).update(trace)
        for name, arrays in chunk.early_errors.items():
            early[name] += arrays
        for name, arrays in chunk.acf.items():
            acf[name] += arrays
    ok = [m for m in fitted if m.name not in failed]
    training_acf = {}
    for m in ok:
        result = m.model.fit_result
        if result is not None:
            training_acf[m.name] = residual_diagnostics(result.residuals, lags=config.acf_lags)
    validation_acf = {}
    for name, arrays in acf.items():
        if name in failed or not arrays:
            continue
        size = min(len(a) for a in arrays)
        validation_acf[name] = np.nanmean(np.stack([a[:size] for a in arrays]), axis=0)
    plot_trace = traces.get(plot_run.key, {})
    if "predictions" in plot_trace:
        plot_trace["predictions"] = {
            k: v for k, v in plot_trace["predictions"].items() if k not in failed
        }
    if "estimates" in plot_trace:
        plot_trace["estimates"] = {
            k: v for k, v in plot_trace["estimates"].items() if k not in failed
        }
    curved_trace = traces.get(curved_runs[0].key, {}) if curved_runs else {}
    if "predictions" in curved_trace:
        curved_trace["predictions"] = {
            k: v for k, v in curved_trace["predictions"].items() if k not in failed
        }
    early_stats = {}
    for name, arrays in early.items():
        if name in failed or not arrays:
            continue
        size = min(len(a) for a in arrays)
        stack = np.abs(np.stack([a[:size] for a in arrays]))
        early_stats[name] = {
            "mean": np.nanmean(stack, axis=0),
            "std": np.nanstd(stack, axis=0),
            "runs": len(arrays),
        }
    dt = float(np.median(np.diff(train["time"].to_numpy()))) if len(train) > 1 else 0.01
    return {
        "plot_run": {"driver": plot_run.driver, "track": plot_run.track, "run": plot_run.index},
        "trace": plot_trace,
        "curved_trace": curved_trace,
        "curved_run": None
        if not curved_runs
        else {"driver": curved_runs[0].driver, "run": curved_runs[0].index},
        "training_acf": {
            k: {"acf": v.autocorrelation, "band": v.confidence_band, "n": v.n}
            for k, v in training_acf.items()
        },
        "validation_acf": validation_acf,
        "early_error": early_stats,
        "dt": dt,
        "detail_driver": plot_run.driver,
    }


# ---------------------------------------------------------------------- versions
def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version(), "platform": platform.platform()}
    for name in (
        "hasa-env",
        "numpy",
        "scipy",
        "pandas",
        "gymnasium",
        "statsmodels",
        "matplotlib",
        "distributed",
    ):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        root = Path(__file__).resolve().parent.parent
        commit = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        ).stdout.strip()
        if commit:
            out["git_commit"] = commit
    out["cpus"] = str(os.cpu_count())
    return out
