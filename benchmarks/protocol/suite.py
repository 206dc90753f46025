"""The protocol in several scenarios at once (``hasa-bench paper --scenario all``).

:func:`run_suite` gives, for each scenario's :class:`~benchmarks.protocol.config.
ProtocolConfig`, the :class:`~benchmarks.protocol.results.BenchmarkResult` that
:func:`~benchmarks.protocol.run.run_protocol` gives for it alone (the same tasks, so the same
numbers), with less work and fewer idle workers (docs/design.md §9.5.3):

- **One fit per distinct training run.** The models are trained on the illustrative
  driver's runs in the ``paper`` scenario whatever the scenario scored
  (:meth:`~benchmarks.protocol.config.ProtocolConfig.env_config`), so a seed's fits are the
  same in every scenario that leaves the drivers as they are. A fit is reused where every
  input of :func:`~benchmarks.protocol.run.fit_and_check` is equal (:func:`fit_key`: the
  seed, the training runs and their env config, the drivers' parameters); a scenario that
  changes the drivers (``off_centre_drivers``: their preferred offsets) gets its own.
- **One pass over the executor.** The fits of every scenario and seed run in one map, then
  the tasks of every scenario in one more, the largest first: with five seeds on two
  workers a scenario alone leaves a worker idle in its last round; together the rounds fill.

Each result's ``timing`` holds ``fit`` (the fits done for that scenario: 0 for fits reused
from an earlier one), its own ``task_cpu_seconds``, and ``tasks`` and ``total``, the wall
times of the whole suite's task pass and of the whole suite (the scenarios' tasks share the
workers, so their wall times cannot be told apart).
"""

from __future__ import annotations

import copy
import dataclasses
import json
import time
from collections.abc import Mapping, Sequence
from typing import Any

from benchmarks.executor import NO_WORKER_TIMEOUT
from benchmarks.protocol.config import BenchmarkError, ProtocolConfig
from benchmarks.protocol.models import ModelError
from benchmarks.protocol.plan import Plan, make_plan
from benchmarks.protocol.results import BenchmarkResult
from benchmarks.protocol.run import (
    FittedPlan,
    Progress,
    Schedule,
    aggregate_result,
    chunk_tasks,
    fit_plans,
    load_candidates,
    schedule,
)

__all__ = ["fit_key", "run_suite"]


def fit_key(plan: Plan) -> str:
    """Every input of a seed's fits that a scenario can change, as text: the seed, the
    training runs (their seeds), the extra training speeds and training drivers, the
    training runs' env config and every driver's parameters. Two plans of one suite (the
    same protocol settings but the scenario) with the same key get the same fits."""
    trainings = [dataclasses.astuple(ref) for ref in plan.trainings()]
    drivers = {name: params.to_dict() for name, params in plan.params.items()}
    return json.dumps(
        [
            plan.seed,
            trainings,
            list(plan.training_speeds),
            [params.to_dict() for params in plan.training_drivers],
            plan.training_env_config,
            drivers,
        ],
        sort_keys=True,
        default=repr,
    )


def run_suite(
    configs: Mapping[str, ProtocolConfig],
    user_models: Sequence[str] = (),
    *,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Progress | None = None,
    no_worker_timeout: float = NO_WORKER_TIMEOUT,
    trust_model_modules: bool = False,
) -> dict[str, BenchmarkResult]:
    """Run the protocol for every scenario's config (the module docstring): the results by
    scenario name, in ``configs``' order. The configs must differ in their scenario only
    (synthetic runs). Arguments as :func:`~benchmarks.protocol.run.run_protocol`.

    Raises:
        BenchmarkError: as :func:`~benchmarks.protocol.run.run_protocol`, or configs that
            differ in more than their scenario, or use recordings.
        ClusterLost: the Dask scheduler, or every worker, went away mid-run.
    """
    if not configs:
        raise BenchmarkError("the suite has no scenario to run")
    first = next(iter(configs.values()))
    _check_configs(configs, first)
    say = progress or (lambda phase, done, total: None)
    start = time.perf_counter()
    candidates = load_candidates(first, user_models, trust_model_modules)
    fits, errors, fit_seconds = _fit_suite(
        configs, candidates, say, workers, scheduler, no_worker_timeout
    )
    tasks = {
        name: [t for i, fit in enumerate(fits[name]) for t in chunk_tasks(config, fit, i == 0)]
        for name, config in configs.items()
    }
    every = [t for name in configs for t in tasks[name]]
    done = schedule(
        every, workers=workers, scheduler=scheduler, say=say, no_worker_timeout=no_worker_timeout
    )
    say("aggregating", 0, 0)
    results: dict[str, BenchmarkResult] = {}
    offset = 0
    for name, config in configs.items():
        own = done.results[offset : offset + len(tasks[name])]
        offset += len(tasks[name])
        part = Schedule(
            own,
            done.timing | {"task_cpu_seconds": float(sum(c.seconds for c in own))},
            done.executor | {"tasks": len(own)},
        )
        result = aggregate_result(config, user_models, candidates, errors[name], fits[name], part)
        result.timing = {"fit": fit_seconds[name]} | part.timing
        results[name] = result
    total = time.perf_counter() - start
    for result in results.values():
        result.timing["total"] = total
    return results


def _check_configs(configs: Mapping[str, ProtocolConfig], first: ProtocolConfig) -> None:
    """Configs of one suite: synthetic, and equal but for their scenario."""
    for name, config in configs.items():
        if config.recordings is not None:
            raise BenchmarkError("a scenario suite runs synthetic runs, not recordings")
        if dataclasses.replace(config, scenario=first.scenario) != first:
            raise BenchmarkError(
                f"the suite's configs differ in more than their scenario ({name!r})"
            )


def _fit_suite(
    configs: Mapping[str, ProtocolConfig],
    candidates: Sequence[Any],
    say: Progress,
    workers: int | None,
    scheduler: Any,
    no_worker_timeout: float,
) -> tuple[dict[str, list[FittedPlan]], dict[str, list[ModelError]], dict[str, float]]:
    """Every scenario's fitted plans (in its seeds' order), model errors and fit seconds;
    each distinct :func:`fit_key` fitted once (:func:`~benchmarks.protocol.run.fit_plans`)."""
    plans = {
        name: [make_plan(config, seed) for seed in config.run_seeds]
        for name, config in configs.items()
    }
    owner: dict[str, tuple[str, int]] = {}  # fit key -> (scenario, seed index) that fits it
    for name, scenario_plans in plans.items():
        for i, plan in enumerate(scenario_plans):
            owner.setdefault(fit_key(plan), (name, i))
    jobs = list(owner.values())
    done = fit_plans(
        [(configs[name], plans[name][i]) for name, i in jobs],
        candidates,
        say,
        workers=workers,
        scheduler=scheduler,
        no_worker_timeout=no_worker_timeout,
    )
    fitted = dict(zip(jobs, done, strict=True))
    fits: dict[str, list[FittedPlan]] = {}
    errors: dict[str, list[ModelError]] = {}
    seconds: dict[str, float] = {}
    for name, scenario_plans in plans.items():
        fits[name], errors[name], seconds[name] = [], [], 0.0
        for i, plan in enumerate(scenario_plans):
            source = owner[fit_key(plan)]
            fit, fit_errors = fitted[source]
            if source == (name, i):
                seconds[name] += fit.seconds
            else:  # another scenario's fit of the same training run, for this plan's runs
                fit = _reused(fit, plan)
            fits[name].append(fit)
            errors[name] += fit_errors
    return fits, errors, seconds


def _reused(fit: FittedPlan, plan: Plan) -> FittedPlan:
    """``fit`` (of another scenario's plan with the same :func:`fit_key`) for ``plan``: its
    models and baselines with this plan's runs; the descriptions copied, since the
    aggregation writes into them."""
    return dataclasses.replace(
        fit,
        plan=plan,
        training=plan.trainings()[0],
        validation=plan.validation(),
        infos=copy.deepcopy(fit.infos),
        baseline_info=copy.deepcopy(fit.baseline_info),
        seconds=0.0,
    )
