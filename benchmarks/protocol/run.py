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
   ``no_steering`` (speed + camera + IMU: the lanes cannot be told apart) and
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

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from benchmarks.executor import default_workers, map_tasks
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
    FittedModel,
    ModelError,
    check_lane_keeping,
    describe,
    fit_models,
    load_models,
)
from benchmarks.protocol.plan import (
    RunRef,
    chunks,
    constant_speed_run,
    load_frames,
    recording_plan,
    synthetic_plan,
)
from benchmarks.protocol.plots import plot_data
from benchmarks.protocol.results import BenchmarkResult, versions
from benchmarks.protocol.tasks import ChunkResult, ChunkTask, run_chunk
from hasa_env.drivers import SpeedProfile

__all__ = ["run_protocol"]


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
    skipped: list[dict[str, str]] = []
    paths: dict[tuple[int | None, str, str, int], str] = {}

    # 0. every model loads before any run is generated: one that does not is an input error
    candidates = load_models(
        user_models, errors, time_limit=config.model_time_limit, stress=config.stress
    )
    if errors:
        raise BenchmarkError(
            f"{len(errors)} of {len(user_models)} user model(s) cannot be used; nothing was "
            "run:\n" + "\n".join(f"  {e}" for e in errors)
        )

    # 1.-2. per seed: the runs, the training run, the fits
    tasks: list[ChunkTask] = []
    fitted_by_seed: dict[int | None, list[FittedModel]] = {}
    model_info: list[dict[str, Any]] = []
    drivers: list[dict[str, Any]] = []
    first: dict[str, Any] = {}
    t_fit = 0.0
    seeds = config.run_seeds
    for seed in seeds:
        plan = recording_plan(config) if seed is None else synthetic_plan(config, seed)
        illustrative = plan["illustrative"]
        main_runs: list[RunRef] = plan["main"]
        curved_runs: list[RunRef] = plan["curved"]
        training_index = plan.get("training_run", config.training_run)
        training = next(
            (r for r in main_runs if r.driver == illustrative and r.index == training_index),
            None,
        )
        where = "" if seed is None else f" (seed {seed})"
        if training is None:
            raise BenchmarkError(
                f"no run {training_index} of the illustrative driver {illustrative!r} on "
                f"the {config.track} track to train on{where}"
            )
        validation = [r for r in main_runs if r is not training]
        if not validation:
            raise BenchmarkError(
                f"no validation runs: found only the training run ({len(main_runs)} run(s) on "
                f"the {config.track} track){where}; the protocol scores the models on the other runs"
            )
        notes.extend(plan.get("notes", []))
        say(f"seed {seed}: generating the training run and fitting the models" if seed is not None
            else "loading the training run and fitting the models", 0, 0)  # fmt: skip
        train_frame = load_frames([training], config.track, plan["env_config"], plan["params"])[0]
        t0 = time.perf_counter()
        sensor_std = float(train_frame.attrs["config"]["noise"]["steering"])
        constant_speed = (
            constant_speed_run(training, config.track, plan["env_config"], plan["params"])
            if config.stress and seed is not None
            else None
        )
        fitted, fit_info = fit_models(
            train_frame,
            candidates,
            errors,
            seed=seed,
            sensor_std=sensor_std,
            constant_speed_train=constant_speed,
            time_limit=config.model_time_limit,
        )
        if config.estimate:  # can each model drive? (no lane evidence from one that cannot)
            fitted = check_lane_keeping(
                fitted,
                fit_info,
                env_id=TRACK_ENV_IDS[config.track],
                config=train_frame.attrs["config"],
                speed=(
                    plan["params"][illustrative].speed if seed is not None else SpeedProfile.hold()
                ),
                seed=seed,
                time_limit=config.model_time_limit,
            )
        skipped += plan.get("skipped", [])
        t_fit += time.perf_counter() - t0
        fitted_by_seed[seed] = fitted
        model_info += fit_info
        drivers += plan["drivers"]
        is_first = not first
        plot_run = next((r for r in validation if r.driver == illustrative), validation[0])
        if is_first:
            first = {"plan": plan, "plot_run": plot_run, "curved": curved_runs,
                     "train": train_frame, "illustrative": illustrative}  # fmt: skip
        trace_runs = {plot_run.key} | ({curved_runs[0].key} if curved_runs else set())
        common = {
            "seed": seed,
            "env_config": plan["env_config"],
            "driver_params": plan["params"],
            "models": tuple(fitted),
            "ljung_box_lags": config.ljung_box_lags,
            "acf_lags": config.acf_lags,
            "weight_threshold": config.weight_threshold,
            "error_window": config.error_window,
            "trace_runs": frozenset(trace_runs) if is_first else frozenset(),
            "detail_driver": illustrative if is_first else "",
            "compare_checks": config.compare_checks,
            "filter_settings": dict(config.filter_settings),
            "time_limit": config.model_time_limit,
        }
        tasks += [
            ChunkTask(runs=tuple(chunk), track="curved", estimate=config.estimate, **common)
            for chunk in chunks(curved_runs, config.batch_size)
        ]
        tasks += [
            ChunkTask(runs=tuple(chunk), track=config.track, estimate=config.estimate, **common)
            for chunk in chunks(validation, config.batch_size)
        ]
        paths.update({r.key: r.path for r in validation + curved_runs if r.path is not None})
    timing["fit"] = t_fit

    # 3. every seed's tasks at once
    n_workers = default_workers() if workers is None else max(1, int(workers))
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
            f"cannot run the tasks on the Dask scheduler {scheduler!r}: {describe(exc)}"
        ) from None
    timing["tasks"] = time.perf_counter() - t_tasks
    timing["task_cpu_seconds"] = float(sum(c.seconds for c in chunk_results))

    # 4. aggregate
    say("aggregating", 0, 0)
    failed: dict[str, ModelError] = {}
    for error in errors:  # load and fit failures (one per model, whichever seed failed first)
        failed.setdefault(error.model, error)
    for chunk in chunk_results:
        for failure in chunk.failures:
            failed.setdefault(failure.model, failure)
    errors = list(failed.values())
    for info in model_info:
        if info["name"] in failed and info.get("error") is None:
            info["error"] = str(failed[info["name"]])
    names = [c.name for c in candidates]
    ok_models = [n for n in names if n not in failed]
    kinds = {c.name: c.kind for c in candidates}
    estimators = list(ok_models)
    if config.compare_checks:
        unchecked = [f"{n}{UNCHECKED_SUFFIX}" for n in ok_models]
        kinds |= {u: "unchecked" for u in unchecked}
        estimators += unchecked
    order = _row_order(seeds, first["plan"]["driver_order"], estimators + list(BASELINES))
    runs_steering = sorted(
        (row for c in chunk_results for row in c.steering if row["model"] not in failed), key=order
    )
    runs_estimation = sorted(
        (row for c in chunk_results for row in c.estimation if row["model"] not in failed),
        key=order,
    )
    steering_rows = aggregate_steering(
        [r for r in runs_steering if r["track"] == config.track], ok_models
    )
    curved_rows = (
        aggregate_steering([r for r in runs_steering if r["track"] == "curved"], ok_models)
        if config.track != "curved"
        else []
    )
    estimation_all = aggregate_estimation(runs_estimation)
    estimation_rows = [r for r in estimation_all if r["track"] == config.track]
    curved_estimation_rows = [r for r in estimation_all if r["track"] != config.track]
    degenerate = _degenerate_runs(runs_steering + runs_estimation, paths)
    seed_summary = summarize_seeds(
        steering_rows, estimation_rows, estimators, kinds, curved_estimation_rows
    )
    summary = verdict(
        seed_summary, estimators, kinds, steering=steering_rows, estimation=estimation_rows,
        curved_estimation=curved_estimation_rows,
        runs_estimation=[r for r in runs_estimation if r["track"] == config.track],
    )  # fmt: skip
    plots = plot_data(
        [c for c in chunk_results if c.traces or c.acf or c.early_errors],
        fitted_by_seed[seeds[0]],
        failed,
        first["plot_run"],
        first["curved"],
        first["train"],
        config,
    )
    timing["total"] = time.perf_counter() - start
    executor = {
        "kind": "dask" if scheduler is not None else "processes",
        "workers": None if scheduler is not None else n_workers,
        "scheduler": None
        if scheduler is None
        else str(getattr(scheduler, "scheduler_address", scheduler)),
        "tasks": len(tasks),
        "batch_size": config.batch_size,
    }
    return BenchmarkResult(
        config=config.to_dict()
        | {"illustrative": first["illustrative"], "user_models": list(user_models)},
        models=model_info,
        steering=steering_rows,
        curved=curved_rows,
        estimation=estimation_rows,
        curved_estimation=curved_estimation_rows,
        seed_summary=seed_summary,
        summary=summary,
        runs_steering=runs_steering,
        runs_estimation=runs_estimation,
        errors=[e.to_dict() for e in errors],
        drivers=drivers,
        plots=plots,
        timing=timing,
        executor=executor,
        versions=versions(),
        notes=notes,
        skipped=skipped,
        degenerate=degenerate,
    )


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
