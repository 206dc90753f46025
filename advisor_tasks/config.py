"""The advisor task's configuration and its estimator (docs/design.md §12).

Configuration: the lane-keeping env's keys (:func:`hasa_env.default_config`, without
``observation``, which this task fixes) plus ``action.steering_only`` and two sections,
deep-merged onto :func:`default_config` and validated by the shared validator
(:mod:`hasa_env.validation`); an unknown key or a value out of range raises
:class:`hasa_env.ConfigError` naming the key path and what is allowed
(:func:`describe_config` lists every key):
==============================  ==========================================================
key                             meaning (default)
==============================  ==========================================================
action.steering_only            the action is the steering alone, Box(1,); the
                                acceleration is 0 m/s^2 (true)
scenario                        the env's named scenario (:mod:`hasa_env.scenarios`):
                                its env keys, and the advisors keep its preferred
                                lateral offsets (``scenario_drivers`` seeded with
                                advisor.population_seed) ('paper')
advisor.population              population of :data:`hasa_env.drivers.POPULATIONS` ('paper')
advisor.population_seed         its seed (0)
advisor.population_size         its number of drivers (9)
advisor.driver                  'random' (drawn per episode), a driver's name ('Ill',
                                '1', ...) or its index ('random')
advisor.drives                  'car': the policy's action drives, the human only
                                advises; 'human': the human's steering and speed drive
                                the car and the action is ignored ('car')
advisor.study_conditions        the population's study conditions
                                (``PopulationSpec.env_config``: disturbances, wheel-study
                                steering sensor) under the user's keys (true)
estimator.type                  'mixture' (GaussianMixtureEKF), 'no_steering',
                                'oracle' or 'single_hypothesis' ('mixture')
estimator.steering_model        'generalized' / 'two-point' (the paper's presets),
                                'fit:generalized' / 'fit:two-point' (fitted on one run
                                of the population's first driver, as hasa-bench does),
                                a saved model file or 'package.module:Name'
                                ('generalized': see below)
estimator.steering_ratio        model units per road-wheel radian; null: 15 for the
                                paper's presets, 1 otherwise (null)
estimator.steering_residual_std the model's residual std (rad, model units); null: the
                                fit's, else FilterSettings' 2e-3 (null)
estimator.outlier_gate          gate outlying measurements (FilterSettings.innovation_gate
                                6); off by default here, see docs/design.md §12.5 (false)
estimator.lane_check            refuse (ConfigError) a model that drives off the road
                                when it steers itself (4 cars, 30 s, straight track;
                                hasa_env.drivers.require_lane_keeping; only for the
                                'mixture' estimator); the two-point preset does, at
                                15 m/s (true)
estimator.settings              further FilterSettings fields by name ({}); each one
                                named wins over the rule of estimators.trust, which by
                                default sets steering_curvature_limit from the roads the
                                model was fitted on (presets and 'fit:' models: straight,
                                2e-4 1/m; no lane evidence from the steering on a bend,
                                docs/design.md §8.11; a 'fit:' model whose fit pins it
                                down gets the bends' steady steering as a feed-forward
                                instead, §8.28), and min_speed / steering_max_speed
                                from the speeds it was fitted at ('fit:' models; the
                                presets' are unknown; :func:`trusted_estimator` gives the
                                filter with the reasons)
==============================  ==========================================================

Why the generalized preset by default: with the "paper" population, a lane keeper on
the true state driving and the human advising, its estimate is the best of the four
(lateral RMSE 0.035 m over six 30 s episodes, all six decided for the true lane; fitted
generalized 0.191 m, six; fitted two-point 0.437 m, four, two undecided; two-point preset
0.803 m, none decided, refused by ``estimator.lane_check`` since it cannot keep the car
on the road), and with the human driving 0.070 m, six (fitted generalized 0.539 m, three,
three refused by the reversal rule; docs/design.md §12.4, ``examples/advisor_estimators.py``,
which before 2026-12-06 counted a refused episode's tie at 0.5 / 0.5 as the true lane).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
import math
from collections.abc import Callable, Mapping
from typing import Any

from estimators.base import LaneEstimator
from estimators.baselines import NoSteeringEKF, OracleEKF, SingleHypothesisEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.settings import FilterSettings
from estimators.timing import check_sample_time
from estimators.trust import TrainingRecord, TrustedFilter, trusted_filter
from hasa_env.drivers import (
    POPULATIONS,
    make_driver,
    population,
    require_lane_keeping,
    run_driver,
)
from hasa_env.drivers.archetypes import HumanParams
from hasa_env.sim.config import ConfigError, deep_merge
from hasa_env.sim.config import default_config as env_default_config
from hasa_env.sim.config import describe_config as env_describe_config
from hasa_env.steering.loading import default_steering_ratio, load_model
from hasa_env.steering.models import GeneralizedModel, TwoPointModel
from hasa_env.validation import Field, did_you_mean, schema, validate

__all__ = [
    "ESTIMATORS",
    "TRAINING_SEED",
    "default_config",
    "describe_config",
    "driver_index",
    "estimator_factory",
    "split_config",
    "trusted_estimator",
]

ESTIMATORS: dict[str, type] = {
    "mixture": GaussianMixtureEKF,
    "no_steering": NoSteeringEKF,
    "oracle": OracleEKF,
    "single_hypothesis": SingleHypothesisEKF,
}
"""``estimator.type`` -> estimator class."""

_FITTED = {"fit:generalized": GeneralizedModel, "fit:two-point": TwoPointModel}
TRAINING_SEED = 0
"""Seed of the training run of the ``fit:`` models (``run_driver(..., seed=0)``)."""


# ------------------------------------------------------------------ configuration
def _describe(path: str) -> str:
    return f"config key '{path}'" if path else "config"


def _error(path: str, message: str) -> ConfigError:
    return ConfigError(message)


_OWN = schema(
    {
        "advisor": {
            "population": Field(
                "choice",
                "paper",
                "The advisors' population (hasa_env.drivers.POPULATIONS).",
                choices=tuple(POPULATIONS),
            ),
            "population_seed": Field(
                "integer", 0, "Seed of the population.", low=0, high=2**31 - 1
            ),
            "population_size": Field("integer", 9, "Drivers in the population.", low=1, high=1000),
            "driver": Field(
                "json",
                "random",
                "The advisor: 'random' (drawn per episode from the car's generator), a "
                "driver's name ('Ill', '1', ...) or its index in the population.",
                max_depth=0,
            ),
            "drives": Field(
                "choice",
                "car",
                "'car': the policy's action drives and the human only advises; 'human': "
                "the human's steering and speed drive the car (the action is ignored).",
                choices=("car", "human"),
            ),
            "study_conditions": Field(
                "bool",
                True,
                "Apply the population's study conditions (PopulationSpec.env_config: "
                "disturbances, wheel-study steering sensor) under the user's keys.",
            ),
        },
        "estimator": {
            "type": Field(
                "choice",
                "mixture",
                "'mixture' (GaussianMixtureEKF), 'no_steering', 'oracle' or 'single_hypothesis'.",
                choices=tuple(ESTIMATORS),
            ),
            "steering_model": Field(
                "string",
                "generalized",
                "'generalized' or 'two-point' (the paper's presets), 'fit:generalized' or "
                "'fit:two-point' (fitted on one run of the population's first driver, as "
                "hasa-bench does), a saved model file, or 'package.module:Name'.",
                non_empty=True,
            ),
            "steering_ratio": Field(
                "number",
                None,
                "Model units per road-wheel radian; null: 15 for the paper's presets, else 1.",
                low=0.0,
                high=100.0,
                low_open=True,
                optional=True,
            ),
            "steering_residual_std": Field(
                "number",
                None,
                "The steering model's residual std (rad, model units); null: the fit's "
                "for 'fit:' models, else FilterSettings' default.",
                unit="rad",
                low=0.0,
                high=1.0,
                optional=True,
            ),
            "outlier_gate": Field(
                "bool",
                False,
                "Gate outlying measurements (FilterSettings.innovation_gate, 6); off in this "
                "task: under a learning policy's driving the gate can drop the camera for good "
                "and the estimate runs away (docs/design.md §12.5).",
            ),
            "lane_check": Field(
                "bool",
                True,
                "Refuse a steering model that cannot keep the car on the road when it steers "
                "itself (hasa_env.drivers.require_lane_keeping: 4 cars, 30 s, the default "
                "straight track): the mixture estimator would read the lane from wrong "
                "evidence (docs/design.md §8.11).",
            ),
            "settings": Field(
                "mapping",
                {},
                "Further FilterSettings fields by name (estimators.settings), e.g. "
                "{'innovation_gate': inf}.",
                each=Field("number", infinite=True, optional=True),
            ),
        },
    }
)
_STEERING_ONLY = Field(
    "bool", True, "The action is the steering alone (Box(1,)); the acceleration is 0 m/s^2."
)


def default_config() -> dict[str, Any]:
    """A fresh copy of the advisor task's default configuration (see the module docstring)."""
    config = env_default_config()
    del config["observation"]
    config["action"]["steering_only"] = _STEERING_ONLY.default
    config.update(validate({}, _OWN, describe=_describe, error=_error))
    return config


def describe_config() -> str:
    """Every configuration key of the advisor task with its default, meaning and range."""
    lines = [
        line for line in env_describe_config().splitlines() if not line.startswith("observation.")
    ]
    own = [("action.steering_only", _STEERING_ONLY), *_OWN.leaves()]
    for path, f in own:
        allowed = _DRIVER_ALLOWED if path == "advisor.driver" else f.allowed()
        lines.append(f"{path} = {f.default!r}: {f.doc} Allowed: {allowed}.")
    return "\n".join(lines)


def split_config(config: Mapping[str, Any] | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the lane-keeping env's part, the advisor's own keys validated and defaulted)."""
    if config is None:
        config = {}
    if not isinstance(config, Mapping):
        raise ConfigError(f"config must be a mapping (dict), got {type(config).__name__}")
    own_keys = _OWN.fields or {}
    env_part = {k: copy.deepcopy(v) for k, v in config.items() if k not in own_keys}
    if "observation" in env_part:
        raise ConfigError(
            "config key 'observation' does not apply to the advisor task: its observation is "
            "the estimate and the raw sensors (see help(advisor_tasks.env))"
        )
    own = validate(
        {k: v for k, v in config.items() if k in own_keys},
        _OWN,
        describe=_describe,
        error=_error,
    )
    own["steering_only"] = _STEERING_ONLY.default
    action = env_part.get("action")
    if isinstance(action, Mapping) and "steering_only" in action:
        action = dict(action)
        own["steering_only"] = validate(
            action.pop("steering_only"),
            _STEERING_ONLY,
            describe=_describe,
            error=_error,
            path="action.steering_only",
        )
        env_part["action"] = action
    return env_part, own


_DRIVER_ALLOWED = "'random', a driver's name in the population or its index"


def driver_index(value: Any, drivers: list[HumanParams]) -> int | None:
    """The configured advisor's index in the population (None: random per episode)."""
    names = [d.name for d in drivers]
    if value == "random":
        return None
    if not isinstance(value, str | int) or isinstance(value, bool):
        raise ConfigError(f"config key 'advisor.driver' must be {_DRIVER_ALLOWED}, got {value!r}")
    if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
        if value < len(drivers):
            return value
        raise ConfigError(
            f"config key 'advisor.driver' = {value!r} is out of range: allowed 'random', a "
            f"name of {names} or an index 0..{len(drivers) - 1}"
        )
    if value in names:
        return names.index(value)
    raise ConfigError(
        f"config key 'advisor.driver' = {value!r} is not allowed: 'random', a name of {names} "
        f"or an index 0..{len(drivers) - 1}"
    )


# ------------------------------------------------------------------ estimator
_LANE_CHECKS: dict[tuple[Any, ...], str | None] = {}
"""Lane-keeping checks done, by (spec, model class, parameters, ratio, dt): None or the refusal."""


@functools.lru_cache(maxsize=16)
def _fitted_model(kind: str, population_key: str, env_key: str) -> tuple[Any, TrainingRecord]:
    """(fitted model, its training record measured on the run:
    :meth:`~estimators.trust.TrainingRecord.measured`) of ``kind`` on one run of the
    population's first driver, as it drives in the scenario, in the task's env (cached: every
    env of a vector or an evaluation shares it)."""
    name, seed, size = json.loads(population_key)
    config = json.loads(env_key)
    trainer = population(name, seed, size, scenario=config["scenario"])[0]
    frame = run_driver(
        make_driver(trainer), "hasa_env/LaneKeeping-v0", runs=1, seed=TRAINING_SEED, config=config
    )[0]
    model = _FITTED[kind]().fit(frame, sensor_std=float(config["noise"]["steering"]))
    return model, TrainingRecord.measured(model, frame)  # as hasa-bench measures its models


def _steering_model(
    own: Mapping[str, Any], env_config: Mapping[str, Any]
) -> tuple[Any, float, TrainingRecord]:
    """(the configured steering model or None, its steering ratio, its training record)."""
    est = own["estimator"]
    if est["type"] == "no_steering":
        return None, 1.0, TrainingRecord()
    spec = est["steering_model"]
    dt = 1.0 / env_config["sim_frequency"]
    training = TrainingRecord()
    if spec in _FITTED:
        advisor = own["advisor"]
        population_key = json.dumps(
            [advisor["population"], advisor["population_seed"], advisor["population_size"]]
        )
        config = deep_merge(env_config, {"action_repeat": 1, "track": "straight"})
        config.pop("observation", None)
        model, training = _fitted_model(spec, population_key, json.dumps(config, sort_keys=True))
        ratio = 1.0
    else:
        try:
            model = load_model(spec, dt=dt)
        except (ValueError, OSError) as exc:
            raise ConfigError(f"config key 'estimator.steering_model' = {spec!r}: {exc}") from None
        ratio = default_steering_ratio(spec, fitted=False)
    if model.arx() is None:
        raise ConfigError(
            f"config key 'estimator.steering_model' = {spec!r}: the model has no ARX form "
            "(or no coefficients): the estimator needs one"
        )
    if est["steering_ratio"] is not None:
        ratio = est["steering_ratio"]
    if est["lane_check"] and est["type"] == "mixture":
        key = (spec, type(model).__qualname__, json.dumps(model.parameters), ratio, dt)
        if key not in _LANE_CHECKS:  # every env of a vector or an evaluation shares it
            try:
                require_lane_keeping(model, steering_ratio=ratio)
                _LANE_CHECKS[key] = None
            except ValueError as exc:
                _LANE_CHECKS[key] = str(exc)
        if _LANE_CHECKS[key] is not None:
            raise ConfigError(
                f"config key 'estimator.steering_model' = {spec!r}: {_LANE_CHECKS[key]} "
                "(set 'estimator.lane_check' to false to use it anyway)"
            )
        training = dataclasses.replace(training, keeps_lane=True)
    return model, ratio, training


def trusted_estimator(own: Mapping[str, Any], env_config: Mapping[str, Any]) -> TrustedFilter:
    """The configured steering model as :func:`estimators.trust.trusted_filter` trusts it, on
    the env's sensor noise, with ``estimator.settings`` (and ``estimator.steering_residual_std``,
    ``estimator.outlier_gate``) as the user's overrides; ConfigError for a bad setting."""
    model, ratio, training = _steering_model(own, env_config)
    est = own["estimator"]
    overrides = dict(est["settings"])
    names = {f.name for f in dataclasses.fields(FilterSettings)}
    unknown = [k for k in overrides if k not in names]
    if unknown:
        raise ConfigError(
            f"unknown config key 'estimator.settings.{unknown[0]}' (allowed keys here: "
            f"{', '.join(sorted(names))})" + did_you_mean(unknown[0], names)
        )
    if not est["outlier_gate"]:
        overrides.setdefault("innovation_gate", math.inf)
    if est["steering_residual_std"] is not None:
        overrides.setdefault("steering_residual_std", est["steering_residual_std"])
    try:
        return trusted_filter(
            model,
            FilterSettings.from_env_config(env_config),
            steering_ratio=ratio,
            training=training,
            overrides=overrides,
        )
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"config key 'estimator.settings': {exc}") from None


def estimator_factory(
    own: Mapping[str, Any], env_config: Mapping[str, Any]
) -> Callable[[], LaneEstimator]:
    """A maker of fresh estimators of the configured type on :func:`trusted_estimator`'s
    filter; ConfigError for a bad setting or a sample time the estimator cannot take."""
    trusted = trusted_estimator(own, env_config)
    settings, arx, lag = trusted.settings, trusted.arx, trusted.decision_lag
    est = own["estimator"]
    dt = 1.0 / env_config["sim_frequency"]
    kind = est["type"]

    def make() -> LaneEstimator:
        if kind == "no_steering":
            return NoSteeringEKF(settings, dt=dt)
        return ESTIMATORS[kind](arx, settings, dt=dt, decision_lag=lag)

    try:
        check_sample_time(
            make(),
            dt,
            source="the advisor task's simulation",
            sim_frequency=env_config["sim_frequency"],
            action_repeat=1,
        )
    except ValueError as exc:
        raise ConfigError(f"config key 'estimator.steering_model': {exc}") from None
    return make
