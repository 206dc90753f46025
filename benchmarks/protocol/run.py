"""The paper's benchmark protocol (docs/design.md §9; Mai et al. sections 3.3 and 4.3).

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
   ``no_steering`` (speed + camera + IMU: the lanes cannot be told apart),
   ``lane_centring`` (the same weighing the lanes by a lane-centring prior fitted on
   the training run, :class:`estimators.lane_centring.LaneCentringEKF`) and
   ``oracle`` (the same filter told the true bias). Per run: RMSE of the
   mixture's lateral-offset estimate (m) over the whole run, and the steps
   until the weight of the true lane exceeds 0.95 for good; the decision
   state at the end, whether it ended with more than 0.95 on a wrong lane
   (``wrong_lane_confident``), the lateral NEES and each channel's NIS
   (docs/design.md §9.8). The curved-track runs get the same rows, the
   estimator given the road ahead (:mod:`estimators.road_geometry`).
   Before that each fitted model drives 4 cars itself for 30 s on the
   training run's conditions (:func:`benchmarks.protocol.models.check_lane_keeping`);
   one that leaves the road gets the no-steering estimator (docs/design.md
   §8.11). With ``stress`` the stress set of bad advisors
   (:mod:`benchmarks.stress`) is scored too; with ``compare_checks`` every
   model's estimator also runs without the evidence checks
   (:mod:`estimators.evidence`) and without the lane-keeping check.

Runs are grouped into tasks of at most ``batch_size`` consecutive runs of one
population seed, its curved runs first, the fewest near-equal ones (each track's
runs generated in one vectorized driver runner, every run of the task filtered in
one batch; measured on a 2-core machine, a task of 4 runs took about 9 s of CPU,
one of 48 runs 20 s and one of 93 runs 28 s: each filter step has a fixed cost)
and mapped, the largest first, over local processes or a Dask cluster
(:func:`benchmarks.executor.map_tasks`); the seeds' fits before them run on the
same executor (:func:`fit_seeds`). Every run is seeded on its own and
the tasks depend only on the protocol (never on the executor or the number
of workers), so results are identical on any executor and worker count. A
different ``batch_size`` can change per-run numbers by floating-point
rounding (batched arithmetic; in practice in their last digits).

:func:`run_protocol` is four stages, each a function of this module with typed
inputs and outputs: :func:`benchmarks.protocol.plan.make_plan` (which runs: a
:class:`~benchmarks.protocol.plan.Plan` per seed), :func:`fit_and_check` (fit
the models on the plan's training run and check that they keep a lane),
:func:`schedule` (the plans' runs in tasks, mapped over the executor) and
:func:`aggregate_result` (tables, verdict, figures: the
:class:`~benchmarks.protocol.results.BenchmarkResult`).

Why this module is long: it is the protocol's four stages end to end, each with its typed
result (the per-seed fits, serial or on the executor, beside the fit they run), and the
assembly of the result from them.

A user model that cannot be imported, does not implement
:class:`hasa_env.steering.SteeringModel`, raises while fitting, predicting
or filtering, or predicts NaN is reported in ``errors`` (naming the model
and what went wrong) and left out of the tables; every other model is still
scored.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.executor import NO_WORKER_TIMEOUT, ClusterLost, default_workers, map_tasks
from benchmarks.protocol.aggregate import (
    aggregate_estimation,
    aggregate_steering,
    summarize_seeds,
    verdict,
)
from benchmarks.protocol.config import (
    BASELINES,
    TRACK_ENV_IDS,
    UNCHECKED_SUFFIX,
    BenchmarkError,
    ProtocolConfig,
)
from benchmarks.protocol.models import (
    Candidate,
    FittedModel,
    ModelError,
    check_lane_keeping,
    describe,
    describe_trust,
    fit_models,
    load_models,
)
from benchmarks.protocol.plan import (
    Plan,
    RunRef,
    chunks,
    constant_speed_run,
    make_plan,
    training_frames,
)
from benchmarks.protocol.plots import plot_data
from benchmarks.protocol.results import BenchmarkResult, versions
from benchmarks.protocol.tasks import ChunkResult, ChunkTask, run_chunk
from estimators.lane_centring import LaneCentringParams, fit_lane_centring
from hasa_env.drivers import SpeedProfile

__all__ = [
    "FitJob",
    "FittedPlan",
    "Schedule",
    "aggregate_result",
    "builtin_model",
    "chunk_tasks",
    "fit_and_check",
    "fit_job",
    "fit_plans",
    "fit_seeds",
    "load_candidates",
    "map_on_executor",
    "run_protocol",
    "schedule",
]

Progress = Callable[[str, int, int], None]
"""``progress(phase, done, total)``: phase "fits" with done/total seeds fitted, "runs" with
done/total runs scored, or a message (total 0)."""


def run_protocol(
    config: ProtocolConfig | None = None,
    user_models: Sequence[str] = (),
    *,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Progress | None = None,
    no_worker_timeout: float = NO_WORKER_TIMEOUT,
    trust_model_modules: bool = False,
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
        no_worker_timeout: on a Dask cluster, give up when it has had no worker
            for this many seconds (:func:`benchmarks.executor.map_tasks`).
        trust_model_modules: a model file in ``user_models`` whose type is not
            registered imports the module its ``"class"`` names (``--trust-model-module``;
            importing runs that module's code).

    Returns:
        A :class:`BenchmarkResult`; failed user models are in ``errors``.

    Raises:
        BenchmarkError: the configuration or the data do not allow the
            protocol (nothing measured).
        ClusterLost: the Dask scheduler, or every worker, went away mid-run.
    """
    config = config or ProtocolConfig()
    say = progress or (lambda phase, done, total: None)
    start = time.perf_counter()
    errors: list[ModelError] = []
    # 0. every model loads before any run is generated: one that does not is an input error
    candidates = load_candidates(config, user_models, trust_model_modules)
    # 1.-2. per seed: the runs, the training run, the fits ("fits": seeds done of all)
    fits = fit_seeds(
        config,
        candidates,
        errors,
        say,
        workers=workers,
        scheduler=scheduler,
        no_worker_timeout=no_worker_timeout,
    )
    tasks = [task for i, fit in enumerate(fits) for task in chunk_tasks(config, fit, i == 0)]
    # 3. every seed's tasks at once
    done = schedule(
        tasks, workers=workers, scheduler=scheduler, say=say, no_worker_timeout=no_worker_timeout
    )
    # 4. aggregate
    say("aggregating", 0, 0)
    result = aggregate_result(config, user_models, candidates, errors, fits, done)
    result.timing = {"fit": sum(f.seconds for f in fits)} | done.timing
    result.timing["total"] = time.perf_counter() - start
    return result


@dataclass(frozen=True)
class FittedPlan:
    """A plan with its models fitted on its training run (stage 2's result).

    Attributes:
        plan: the runs.
        training: the run the models are trained on; validation: the other main-track
            runs (scored); train_frame: the training run's data.
        models: the fitted models (with their lane-keeping outcome when estimating);
            infos: their descriptions (``results.json`` ``models``), failed ones included.
        seconds: time spent fitting and checking (s).
        lane_centring: the lane-centring baseline's prior fitted on the training run
            (None: not estimating, or the run could not fit it; ``baseline_info`` says why).
        baseline_info: the fitted baselines (``results.json`` ``baselines``).
    """

    plan: Plan
    training: RunRef
    validation: list[RunRef]
    train_frame: pd.DataFrame
    models: list[FittedModel]
    infos: list[dict[str, Any]]
    seconds: float
    lane_centring: LaneCentringParams | None = None
    baseline_info: list[dict[str, Any]] = field(default_factory=list)

    @property
    def plot_run(self) -> RunRef:
        """The run of the figures: the illustrative driver's first validation run."""
        illustrative = self.plan.illustrative
        return next((r for r in self.validation if r.driver == illustrative), self.validation[0])


@dataclass(frozen=True)
class FitJob:
    """The fits of one plan, as a task of the executor (:func:`fit_plans`)."""

    config: ProtocolConfig
    plan: Plan
    candidates: tuple[Candidate, ...]


def fit_job(job: FitJob) -> tuple[FittedPlan, list[ModelError]]:
    """One plan fitted and checked (:func:`fit_and_check`) and its model errors."""
    errors: list[ModelError] = []
    fit = fit_and_check(job.config, job.plan, job.candidates, errors, lambda *_: None)
    return fit, errors


def map_on_executor(
    function: Callable[[Any], Any],
    items: Sequence[Any],
    what: str,
    workers: int | None,
    scheduler: Any,
    progress: Callable[[int], None],
    no_worker_timeout: float,
) -> list[Any]:
    """:func:`benchmarks.executor.map_tasks`, a Dask scheduler's OSError or timeout as a
    BenchmarkError saying what could not be done (``what``: "fit the models", ...);
    ClusterLost passes."""
    try:
        return map_tasks(
            function,
            items,
            workers=workers,
            scheduler=scheduler,
            progress=progress,
            no_worker_timeout=no_worker_timeout,
        )
    except ClusterLost:
        raise
    except (OSError, TimeoutError) as exc:
        if scheduler is None:
            raise
        raise BenchmarkError(
            f"cannot {what} on the Dask scheduler {scheduler!r}: {describe(exc)}"
        ) from None


def fit_seeds(
    config: ProtocolConfig,
    candidates: Sequence[Candidate],
    errors: list[ModelError],
    say: Progress,
    *,
    workers: int | None = None,
    scheduler: Any = None,
    no_worker_timeout: float = NO_WORKER_TIMEOUT,
) -> list[FittedPlan]:
    """Every seed's plan (:func:`~benchmarks.protocol.plan.make_plan`) fitted and checked
    (:func:`fit_and_check`), in ``config.run_seeds`` order. The first seed is fitted in this
    process (with its messages); the seeds are independent, so with more than two the others
    run in parallel on the executor of the tasks (:func:`benchmarks.executor.map_tasks`;
    ``workers=1``: in this process too). The model errors are appended to ``errors`` seed
    after seed, as one after another would.

    Raises:
        BenchmarkError: as :func:`fit_and_check`, or the Dask scheduler fails.
        ClusterLost: the scheduler, or every worker, went away mid-run.
    """
    fitted = fit_plans(
        [(config, make_plan(config, seed)) for seed in config.run_seeds],
        candidates,
        say,
        workers=workers,
        scheduler=scheduler,
        no_worker_timeout=no_worker_timeout,
    )
    for _, seed_errors in fitted:
        errors += seed_errors
    return [fit for fit, _ in fitted]


def fit_plans(
    jobs: Sequence[tuple[ProtocolConfig, Plan]],
    candidates: Sequence[Candidate],
    say: Progress,
    *,
    workers: int | None = None,
    scheduler: Any = None,
    no_worker_timeout: float = NO_WORKER_TIMEOUT,
) -> list[tuple[FittedPlan, list[ModelError]]]:
    """Each (config, plan) fitted and checked (:func:`fit_and_check`), with its model
    errors, in order (``say``: "fits" done of all). The first in this process (with its
    messages): it imports what the fits and the tasks use, which the worker processes
    (forked from this one) then inherit instead of importing it each. The plans are
    independent, so with more than two the others run in parallel on the executor of the
    tasks (:func:`benchmarks.executor.map_tasks`; ``workers=1``: in this process too).

    Raises:
        BenchmarkError: as :func:`fit_and_check`, or the Dask scheduler fails.
        ClusterLost: the scheduler, or every worker, went away mid-run.
    """
    say("fits", 0, len(jobs))
    serial = workers is not None and int(workers) <= 1 and scheduler is None
    done: list[tuple[FittedPlan, list[ModelError]]] = []
    for config, plan in jobs[: len(jobs) if serial or len(jobs) <= 2 else 1]:
        errors: list[ModelError] = []
        done.append((fit_and_check(config, plan, candidates, errors, say), errors))
        say("fits", len(done), len(jobs))
    if len(done) == len(jobs):
        return done
    rest = [FitJob(config, plan, tuple(candidates)) for config, plan in jobs[1:]]
    return done + map_on_executor(
        fit_job, rest, "fit the models", workers, scheduler,
        lambda count: say("fits", 1 + count, len(jobs)), no_worker_timeout,
    )  # fmt: skip


def fit_and_check(
    config: ProtocolConfig,
    plan: Plan,
    candidates: Sequence[Candidate],
    errors: list[ModelError],
    say: Progress,
) -> FittedPlan:
    """Fit every candidate on the plan's training run and, when estimating, let each drive
    (:func:`~benchmarks.protocol.models.check_lane_keeping`). A user model that fails is
    appended to ``errors``; a built-in one that fails raises BenchmarkError, as does a plan
    without a training run or without validation runs."""
    seed = plan.seed
    trainings = plan.trainings()
    training = trainings[0]
    validation = plan.validation()
    say(f"seed {seed}: generating the training run and fitting the models" if seed is not None
        else "loading the training run and fitting the models", 0, 0)  # fmt: skip
    train_env = plan.training_env_config or plan.env_config
    train_frames = training_frames(plan)
    train_frame = train_frames[0]
    t0 = time.perf_counter()
    sensor_std = float(train_frame.attrs["config"]["noise"]["steering"])
    constant_speed = (
        constant_speed_run(training, config.track, train_env, plan.params)
        if config.stress and seed is not None
        else None
    )
    fitted, fit_info = fit_models(
        train_frames if len(train_frames) > 1 else train_frame,
        candidates,
        errors,
        seed=seed,
        sensor_std=sensor_std,
        constant_speed_train=constant_speed,
        time_limit=config.model_time_limit,
        generalized_orders=config.generalized_orders,
        equation_error_order=config.equation_error_order,
        speed_scaled_error=config.speed_scaled_error,
    )
    if config.estimate:  # can each model drive? (no lane evidence from one that cannot)
        speed = plan.params[plan.illustrative].speed if seed is not None else SpeedProfile.hold()
        fitted = check_lane_keeping(
            fitted,
            fit_info,
            env_id=TRACK_ENV_IDS[config.track],
            config=train_frame.attrs["config"],
            speed=speed,
            seed=seed,
            time_limit=config.model_time_limit,
        )
        describe_trust(fitted, fit_info, config.filter_settings)
    lane_centring, baseline_info = _fit_baselines(config, train_frames, seed)
    seconds = time.perf_counter() - t0
    return FittedPlan(
        plan, training, validation, train_frame, fitted, fit_info, seconds, lane_centring,
        baseline_info,
    )  # fmt: skip


def builtin_model(
    seed: int, name: str = "generalized", scenario: str = "paper"
) -> tuple[ProtocolConfig, Plan, FittedModel]:
    """The protocol's default config and plan of population ``seed`` in ``scenario``, and its
    built-in model ``name`` fitted and checked as ``hasa-bench paper`` does
    (:func:`fit_and_check`; the fit's collinearity warnings silenced: hasa-bench reports them
    in its results). For examples and studies of one model
    (``benchmarks.protocol.tasks.model_estimator`` gives its filter)."""
    config = ProtocolConfig(seeds=(seed,), scenario=scenario)
    plan = make_plan(config, seed)
    errors: list[ModelError] = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted = fit_and_check(config, plan, load_models([], errors), errors, lambda *_: None)
    named = [fm for fm in fitted.models if fm.name == name]
    if not named:
        known = ", ".join(fm.name for fm in fitted.models)
        raise ValueError(f"no built-in model {name!r} (the protocol fits: {known})")
    return config, plan, named[0]


def _fit_baselines(
    config: ProtocolConfig, train_frames: Sequence[pd.DataFrame], seed: int | None
) -> tuple[LaneCentringParams | None, list[dict[str, Any]]]:
    """The lane-centring prior fitted on the training runs (when estimating) and its
    description; runs it cannot be fitted on leave that baseline out, with the reason."""
    if not config.estimate:
        return None, []
    info: dict[str, Any] = {"name": "lane_centring", "seed": seed}
    try:
        params = fit_lane_centring(list(train_frames))
    except ValueError as exc:
        return None, [info | {"params": None, "error": str(exc)}]
    return params, [info | {"params": params.to_dict(), "error": None}]


def chunk_tasks(config: ProtocolConfig, fit: FittedPlan, detailed: bool) -> list[ChunkTask]:
    """The tasks of one fitted plan: its curved runs and its validation runs, in that order,
    in the fewest near-equal chunks of at most ``config.batch_size`` runs (:func:`~benchmarks.
    protocol.plan.chunks`; a chunk may hold runs of both tracks: each track's runs are
    generated in their own vector env and filtered in one batch, the road of each run its
    own). A ``detailed`` plan (the first seed's) also records the figures' traces (of its
    plot run and first curved run) and the illustrative driver's details."""
    plan = fit.plan
    trace_runs = {fit.plot_run.key} | ({plan.curved[0].key} if plan.curved else set())

    def task(runs: Sequence[RunRef]) -> ChunkTask:
        return ChunkTask(
            runs=tuple(runs),
            estimate=config.estimate,
            seed=plan.seed,
            env_config=plan.env_config,
            driver_params=plan.params,
            models=tuple(fit.models),
            ljung_box_lags=config.ljung_box_lags,
            acf_lags=config.acf_lags,
            weight_threshold=config.weight_threshold,
            error_window=config.error_window,
            trace_runs=frozenset(trace_runs) if detailed else frozenset(),
            detail_driver=plan.illustrative if detailed else "",
            compare_checks=config.compare_checks,
            filter_settings=dict(config.filter_settings),
            time_limit=config.model_time_limit,
            lane_centring=fit.lane_centring,
        )

    return [task(chunk) for chunk in chunks([*plan.curved, *fit.validation], config.batch_size)]


def load_candidates(
    config: ProtocolConfig, user_models: Sequence[str], trust_model_modules: bool = False
) -> list[Candidate]:
    """Every model the protocol scores (:func:`~benchmarks.protocol.models.load_models`),
    before any run is generated.

    Raises:
        BenchmarkError: a user model cannot be used (each one named): nothing is run.
    """
    errors: list[ModelError] = []
    candidates = load_models(
        user_models,
        errors,
        time_limit=config.model_time_limit,
        stress=config.stress,
        trust_module=trust_model_modules,
    )
    if errors:
        raise BenchmarkError(
            f"{len(errors)} of {len(user_models)} user model(s) cannot be used; nothing was "
            "run:\n" + "\n".join(f"  {e}" for e in errors)
        )
    return candidates


@dataclass(frozen=True)
class Schedule:
    """The tasks run (stage 3's result).

    Attributes:
        results: one :class:`ChunkResult` per task, in the tasks' order.
        timing: ``tasks`` (wall time, s) and ``task_cpu_seconds`` (summed over tasks).
        executor: how they ran (``kind``, ``workers``, ``scheduler``, ``tasks``; the
            batch size is added by :func:`aggregate_result`).
    """

    results: list[ChunkResult]
    timing: dict[str, float]
    executor: dict[str, Any]


def schedule(
    tasks: Sequence[ChunkTask],
    *,
    workers: int | None,
    scheduler: Any,
    say: Progress,
    no_worker_timeout: float = NO_WORKER_TIMEOUT,
) -> Schedule:
    """Run every task (:func:`run_chunk`) on local processes or the Dask ``scheduler``,
    the largest first, reporting the runs done to ``say``; the results in the tasks' order.

    Raises:
        BenchmarkError: the Dask scheduler fails (an OSError or a timeout on it).
        ClusterLost: the scheduler, or every worker, went away mid-run.
    """
    n_workers = default_workers() if workers is None else max(1, int(workers))
    # the largest tasks first: the small ones (a seed's few curved runs) fill the workers'
    # last gaps instead of one worker running a large task alone at the end
    order = sorted(range(len(tasks)), key=lambda i: -len(tasks[i].runs))
    total_runs = sum(len(t.runs) for t in tasks)
    done_runs = np.cumsum([len(tasks[i].runs) for i in order])
    say("runs", 0, total_runs)

    def on_task(done: int) -> None:
        say("runs", int(done_runs[done - 1]), total_runs)

    t_tasks = time.perf_counter()
    ordered: list[ChunkResult] = map_on_executor(
        run_chunk, [tasks[i] for i in order], "run the tasks", workers, scheduler, on_task,
        no_worker_timeout,
    )  # fmt: skip
    by_task = dict(zip(order, ordered, strict=True))
    results = [by_task[i] for i in range(len(tasks))]
    timing = {
        "tasks": time.perf_counter() - t_tasks,
        "task_cpu_seconds": float(sum(c.seconds for c in results)),
    }
    executor = {
        "kind": "dask" if scheduler is not None else "processes",
        "workers": None if scheduler is not None else n_workers,
        "scheduler": None
        if scheduler is None
        else str(getattr(scheduler, "scheduler_address", scheduler)),
        "tasks": len(tasks),
    }
    return Schedule(results, timing, executor)


def _failures(
    errors: Sequence[ModelError], results: Sequence[ChunkResult]
) -> dict[str, ModelError]:
    """Each failed model's first failure: load and fit failures (whichever seed failed
    first), then those of the tasks."""
    failed: dict[str, ModelError] = {}
    for error in errors:
        failed.setdefault(error.model, error)
    for chunk in results:
        for failure in chunk.failures:
            failed.setdefault(failure.model, failure)
    return failed


def _estimators(
    config: ProtocolConfig, candidates: Sequence[Candidate], ok_models: list[str]
) -> tuple[list[str], dict[str, str]]:
    """The estimators scored (the models that did not fail, and with ``compare_checks``
    each of them without its checks) and every name's kind."""
    kinds = {c.name: c.kind for c in candidates}
    estimators = list(ok_models)
    if config.compare_checks:
        unchecked = [f"{n}{UNCHECKED_SUFFIX}" for n in ok_models]
        kinds |= {u: "unchecked" for u in unchecked}
        estimators += unchecked
    return estimators, kinds


def _result_config(
    config: ProtocolConfig, plan: Plan, user_models: Sequence[str]
) -> dict[str, Any]:
    """The results' ``config``: the protocol's settings, the illustrative driver, the user
    models and the scenario scored (a recording plan's is its training run's)."""
    return config.to_dict() | {
        "illustrative": plan.illustrative,
        "user_models": list(user_models),
        "scenario": plan.scenario,
    }


def aggregate_result(
    config: ProtocolConfig,
    user_models: Sequence[str],
    candidates: Sequence[Candidate],
    errors: Sequence[ModelError],
    fits: Sequence[FittedPlan],
    done: Schedule,
) -> BenchmarkResult:
    """The result of the tasks: per-run rows of the models that did not fail, sorted
    (seed, driver, track, model, run); the steering and estimation tables, the per-seed
    summary and the verdict (:mod:`benchmarks.protocol.aggregate`); the figures' data of
    the first seed. ``timing`` is left for the caller."""
    failed = _failures(errors, done.results)
    model_info = [info for fit in fits for info in fit.infos]
    for info in model_info:
        if info["name"] in failed and info.get("error") is None:
            info["error"] = str(failed[info["name"]])
    ok_models = [c.name for c in candidates if c.name not in failed]
    estimators, kinds = _estimators(config, candidates, ok_models)
    first = fits[0]
    seeds = [fit.plan.seed for fit in fits]
    order = _row_order(seeds, first.plan.driver_order, estimators + list(BASELINES))
    chunk_rows = done.results
    runs_steering = sorted(
        (row for c in chunk_rows for row in c.steering if row["model"] not in failed), key=order
    )
    runs_estimation = sorted(
        (row for c in chunk_rows for row in c.estimation if row["model"] not in failed),
        key=order,
    )
    steering_rows, curved_rows, estimation_rows, curved_estimation_rows = _tables(
        config.track, runs_steering, runs_estimation, ok_models
    )
    paths = {
        r.key: r.path
        for fit in fits
        for r in fit.validation + fit.plan.curved
        if r.path is not None
    }
    seed_summary = summarize_seeds(
        steering_rows, estimation_rows, estimators, kinds, curved_estimation_rows
    )
    plots = plot_data(
        [c for c in chunk_rows if c.traces or c.acf or c.early_errors],
        first.models,
        failed,
        first.plot_run,
        first.plan.curved,
        first.train_frame,
        config,
    )
    return BenchmarkResult(
        config=_result_config(config, first.plan, user_models),
        models=model_info,
        steering=steering_rows,
        curved=curved_rows,
        estimation=estimation_rows,
        curved_estimation=curved_estimation_rows,
        seed_summary=seed_summary,
        summary=verdict(
            seed_summary,
            estimators,
            kinds,
            steering=steering_rows,
            estimation=estimation_rows,
            curved_estimation=curved_estimation_rows,
            runs_estimation=[r for r in runs_estimation if r["track"] == config.track],
        ),
        runs_steering=runs_steering,
        runs_estimation=runs_estimation,
        errors=[e.to_dict() for e in failed.values()],
        drivers=[d for fit in fits for d in fit.plan.drivers],
        plots=plots,
        timing={},
        executor=done.executor | {"batch_size": config.batch_size},
        versions=versions(),
        notes=[n for fit in fits for n in fit.plan.notes],
        skipped=[s for fit in fits for s in fit.plan.skipped],
        degenerate=_degenerate_runs(runs_steering + runs_estimation, paths),
        baselines=[info for fit in fits for info in fit.baseline_info],
    )


def _tables(
    track: str,
    runs_steering: Sequence[dict[str, Any]],
    runs_estimation: Sequence[dict[str, Any]],
    models: Sequence[str],
) -> tuple[list[dict[str, Any]], ...]:
    """The per-driver tables of the per-run rows: steering on the main ``track``, steering on
    the curved track (none when it is the main track), estimation on the main track and on
    the other one."""
    steering_rows = aggregate_steering([r for r in runs_steering if r["track"] == track], models)
    curved_rows = (
        aggregate_steering([r for r in runs_steering if r["track"] == "curved"], models)
        if track != "curved"
        else []
    )
    estimation_all = aggregate_estimation(list(runs_estimation))
    estimation_rows = [r for r in estimation_all if r["track"] == track]
    curved_estimation_rows = [r for r in estimation_all if r["track"] != track]
    return steering_rows, curved_rows, estimation_rows, curved_estimation_rows


def _degenerate_runs(
    rows: Sequence[dict[str, Any]], paths: dict[tuple[int | None, str, str, int], str]
) -> list[dict[str, Any]]:
    """One entry per run left out of the means as degenerate (its key, file and reason)."""
    seen: dict[tuple[int | None, str, str, int], dict[str, Any]] = {}
    for row in rows:
        reason = row.get("degenerate")
        key = (row.get("seed"), row["driver"], row["track"], row["run"])
        if reason and key not in seen:
            seen[key] = {
                "seed": key[0], "driver": key[1], "track": key[2], "run": key[3],
                "file": paths.get(key), "reason": reason,
            }  # fmt: skip
    return list(seen.values())


def _row_order(
    seeds: Sequence[int | None], drivers: Sequence[str], models: Sequence[str]
) -> Callable[[dict], tuple]:
    s_rank = {s: i for i, s in enumerate(seeds)}
    d_rank = {d: i for i, d in enumerate(drivers)}
    m_rank = {m: i for i, m in enumerate(models)}
    return lambda row: (
        s_rank.get(row.get("seed"), len(s_rank)),
        d_rank.get(row["driver"], len(d_rank)),
        row["driver"],
        row.get("track", ""),
        m_rank.get(row["model"], len(m_rank)),
        row["run"],
    )
