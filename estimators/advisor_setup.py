"""What the advisor task's single and vector env share: configuration, the estimator, the
humans, the observation and info layout (docs/design.md §12).

The task (``hasa_env/LaneKeepingAdvisor-v0``, :mod:`estimators.advisor_env`): a policy
drives; a synthetic human of a named population sits at the wheel, sees the true
markings and steers as it would drive; its measured steering feeds the human-as-advisor
estimator at the simulation rate; the policy observes the estimate and the raw sensors.

Configuration: the lane-keeping env's keys (:func:`hasa_env.default_config`, without
``observation``, which this task fixes) plus ``action.steering_only`` and two sections,
deep-merged onto :func:`default_config` and validated; an unknown key or a value out of
range raises :class:`hasa_env.ConfigError` naming the key path and what is allowed
(:func:`describe_config` lists every key):

==============================  ==========================================================
key                             meaning (default)
==============================  ==========================================================
action.steering_only            the action is the steering alone, Box(1,); the
                                acceleration is 0 m/s^2 (true)
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
estimator.settings              further FilterSettings fields by name ({})
==============================  ==========================================================

Why the generalized preset by default: with the "paper" population, a lane keeper on
the true state driving and the human advising, its estimate is the best of the four
(lateral RMSE 0.035 m over six 30 s episodes, true lane always found; fitted
generalized 0.13 m; two-point preset 0.38 m; fitted two-point ended on the wrong lane
in two of six), and with the human driving 0.078 m (``docs/design.md §12``).

Why a separate module in ``estimators``: the task needs the estimator, and
``hasa_env`` never imports ``estimators`` (docs/design.md §2.1); ``hasa_env`` registers
the ids with entry-point *strings*, which gymnasium imports only at ``gym.make``.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from estimators.base import Estimate, LaneEstimator
from estimators.baselines import NoSteeringEKF, OracleEKF, SingleHypothesisEKF
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.road_geometry import lane_points_ahead, look_ahead_distances
from estimators.settings import FilterSettings
from estimators.timing import check_sample_time
from estimators.tuning import steering_residual_std
from estimators.wrappers import estimate_info_keys
from hasa_env.drivers import POPULATIONS, make_driver, population, run_driver
from hasa_env.drivers.archetypes import HumanParams
from hasa_env.sim.config import ConfigError, deep_merge
from hasa_env.sim.config import default_config as env_default_config
from hasa_env.sim.config import describe_config as env_describe_config
from hasa_env.sim.dynamics import SENSOR_NAMES
from hasa_env.sim.setup import INFO_KEYS, EnvSetup, build_setup, physical_action
from hasa_env.steering.arx import ARXForm
from hasa_env.steering.loading import default_steering_ratio, load_model
from hasa_env.steering.models import GeneralizedModel, TwoPointModel
from hasa_env.validation import ANY_JSON, Field, schema, validate

__all__ = [
    "ADVISOR_INFO_KEYS",
    "AdvisorSetup",
    "ESTIMATORS",
    "WheelNoise",
    "build_advisor_setup",
    "default_config",
    "describe_config",
    "estimate_readout",
    "observation_names",
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
            "settings": Field(
                "mapping",
                {},
                "Further FilterSettings fields by name (estimators.settings).",
                each=ANY_JSON,
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


def _split_config(config: Mapping[str, Any] | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the lane-keeping env's part, the advisor's own keys validated and defaulted)."""
    if config is None:
        config = {}
    if not isinstance(config, Mapping):
        raise ConfigError(f"config must be a mapping (dict), got {type(config).__name__}")
    env_part = {k: copy.deepcopy(v) for k, v in config.items() if k not in _OWN.fields}
    if "observation" in env_part:
        raise ConfigError(
            "config key 'observation' does not apply to the advisor task: its observation is "
            "the estimate and the raw sensors (see help(estimators.advisor_env))"
        )
    own = validate(
        {k: v for k, v in config.items() if k in _OWN.fields},
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


def _driver_index(value: Any, drivers: list[HumanParams]) -> int | None:
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
@functools.lru_cache(maxsize=16)
def _fitted_model(kind: str, population_key: str, env_key: str) -> tuple[Any, float]:
    """(fitted model, residual std (rad)) of ``kind`` on one run of the population's first
    driver in the task's env (cached: every env of a vector or an evaluation shares it)."""
    name, seed, size = json.loads(population_key)
    config = json.loads(env_key)
    trainer = population(name, seed, size)[0]
    frame = run_driver(
        make_driver(trainer), "hasa_env/LaneKeeping-v0", runs=1, seed=TRAINING_SEED, config=config
    )[0]
    model = _FITTED[kind]().fit(frame, sensor_std=float(config["noise"]["steering"]))
    arx = model.arx()
    residual = steering_residual_std(arx, frame, decision_lag=model.decision_lag)
    return model, residual


def _steering_model(
    own: Mapping[str, Any], env_config: Mapping[str, Any]
) -> tuple[ARXForm | None, int, float, float | None]:
    """(ARX form, decision lag, steering ratio, residual std or None) of the configured model."""
    est = own["estimator"]
    if est["type"] == "no_steering":
        return None, 0, 1.0, est["steering_residual_std"]
    spec = est["steering_model"]
    dt = 1.0 / env_config["sim_frequency"]
    residual = est["steering_residual_std"]
    if spec in _FITTED:
        advisor = own["advisor"]
        population_key = json.dumps(
            [advisor["population"], advisor["population_seed"], advisor["population_size"]]
        )
        training = deep_merge(env_config, {"action_repeat": 1, "track": "straight"})
        training.pop("observation", None)
        model, fit_residual = _fitted_model(
            spec, population_key, json.dumps(training, sort_keys=True)
        )
        residual = fit_residual if residual is None else residual
        ratio = 1.0
    else:
        try:
            model = load_model(spec, dt=dt)
        except (ValueError, OSError) as exc:
            raise ConfigError(f"config key 'estimator.steering_model' = {spec!r}: {exc}") from None
        ratio = default_steering_ratio(spec, fitted=False)
    arx = model.arx()
    if arx is None:
        raise ConfigError(
            f"config key 'estimator.steering_model' = {spec!r}: the model has no ARX form "
            "(or no coefficients): the estimator needs one"
        )
    if est["steering_ratio"] is not None:
        ratio = est["steering_ratio"]
    return arx, int(getattr(model, "decision_lag", 1)), ratio, residual


def _estimator_factory(
    own: Mapping[str, Any], env_config: Mapping[str, Any]
) -> Callable[[], LaneEstimator]:
    arx, lag, ratio, residual = _steering_model(own, env_config)
    est = own["estimator"]
    overrides = dict(est["settings"])
    names = {f.name for f in dataclasses.fields(FilterSettings)}
    unknown = [k for k in overrides if k not in names]
    if unknown:
        raise ConfigError(
            f"unknown config key 'estimator.settings.{unknown[0]}' (allowed keys here: "
            f"{', '.join(sorted(names))})"
        )
    overrides.setdefault("steering_ratio", ratio)
    if residual is not None:
        overrides.setdefault("steering_residual_std", residual)
    try:
        settings = FilterSettings.from_env_config(env_config, **overrides)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"config key 'estimator.settings': {exc}") from None
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


# ------------------------------------------------------------------ layout
OBSERVATION_ESTIMATE = (
    "estimate_lateral_offset",
    "estimate_lateral_offset_std",
    "estimate_heading",
    "estimate_speed",
)
"""The estimate's entries at the start of the observation (m, m, rad, m/s)."""

ADVISOR_INFO_KEYS = (
    *INFO_KEYS,
    *estimate_info_keys(),
    "estimate_heading",
    "estimate_speed",
    "advisor_index",
    "advisor_steering",
    "sensor_advisor_steering",
    "policy_steering",
    "substep_lateral_offset",
)
"""Keys of the advisor task's ``info``, the same at ``reset`` and every ``step``."""


def observation_names(num_hypotheses: int) -> tuple[str, ...]:
    """The observation's entries in order (see :class:`estimators.advisor_env.LaneKeepingAdvisorEnv`)."""
    return (
        *OBSERVATION_ESTIMATE,
        *(f"estimate_weight_{i}" for i in range(num_hypotheses)),
        *(f"sensor_{name}" for name in SENSOR_NAMES),
        "sensor_advisor_steering",
    )


@dataclass(frozen=True, eq=False)
class AdvisorSetup:
    """Everything the advisor envs derive once from a validated configuration.

    Attributes:
        config: the full validated configuration (:func:`default_config` layout).
        env: the car's lane-keeping set-up (``action_repeat`` of the task).
        sample: the same set-up with ``action_repeat`` 1: one simulation sample, the
            step of :func:`hasa_env.sim.transition.env_step` inside an env step.
        drivers: the population's drivers.
        fixed_driver: index of the configured advisor, None for one drawn per episode.
        human_drives: the human's commands drive the car (``advisor.drives = 'human'``).
        steering_only: the action is the steering alone.
        make_estimator: a new estimator (stepping at the simulation rate).
        hypotheses: the lane hypotheses b_i (m), (H,).
        prior: their probabilities, or None (uniform).
        near, far: the estimator's look-ahead distances (m), for the road points.
        straight: the road is straight.
    """

    config: dict[str, Any]
    env: EnvSetup
    sample: EnvSetup
    drivers: tuple[HumanParams, ...]
    fixed_driver: int | None
    human_drives: bool
    steering_only: bool
    make_estimator: Callable[[], LaneEstimator]
    hypotheses: np.ndarray
    prior: np.ndarray | None
    near: float
    far: float
    straight: bool
    """The road is straight (no road points for the estimator)."""

    @property
    def dt(self) -> float:
        """Simulation sample time Ts (s): the humans' and the estimator's step."""
        return self.env.dt

    def action_space(self) -> spaces.Box:
        space = self.env.action_space()
        if self.steering_only:
            return spaces.Box(space.low[:1], space.high[:1], dtype=space.dtype)
        return space

    def observation_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        h = self.hypotheses.size
        sensor_lo, sensor_hi = (b.astype(np.float64) for b in self.env.sensor_bounds())
        wheel = self.env.steering_limit + 1.0
        lo = np.concatenate([[-60.0, 0.0, -math.pi, 0.0], np.zeros(h), sensor_lo, [-wheel]])
        hi = np.concatenate([[60.0, 100.0, math.pi, 200.0], np.ones(h), sensor_hi, [wheel]])
        return lo, hi

    def observation_space(self) -> spaces.Box:
        lo, hi = self.observation_bounds()
        return spaces.Box(lo.astype(np.float32), hi.astype(np.float32), dtype=np.float32)

    def road_points(self, station: np.ndarray) -> dict[str, np.ndarray]:
        """The estimator's ``road_points`` keyword for cars at ``station`` (m): none on a
        straight road."""
        if self.straight:
            return {}
        return {"road_points": lane_points_ahead(self.env.road, station, self.near, self.far)}

    @property
    def _neutral_action(self) -> float:
        """The action value meaning 0 m/s^2."""
        if not self.env.normalized_actions:
            return 0.0
        lo, hi = self.env.acceleration_limits
        return 2.0 * (0.0 - lo) / (hi - lo) - 1.0

    def action_to_physical(self, action: Any, num_envs: int | None) -> tuple[Any, Any]:
        """The policy's (steering rad, acceleration m/s^2), validated and clipped."""
        if self.steering_only and num_envs is None and isinstance(action, np.ndarray):
            if action.shape == (1,) and action.dtype.kind in "fi":
                action = np.array([action[0], self._neutral_action], dtype=np.float64)
                return physical_action(self.env, action, None)
        if self.steering_only:
            steer = np.asarray(action)
            shape = (1,) if num_envs is None else (num_envs, 1)
            if steer.shape == shape[:-1] and num_envs is not None:
                steer = steer[:, None]
            if steer.shape != shape:
                raise ValueError(
                    f"action must have shape {shape} (the steering), got {steer.shape}"
                )
            pad = np.full(shape, self._neutral_action, dtype=np.float64)
            action = np.concatenate([steer.astype(np.float64, copy=False), pad], axis=-1)
        return physical_action(self.env, action, num_envs)


def build_advisor_setup(config: Mapping[str, Any] | None, track: str | None = None) -> AdvisorSetup:
    """Validate ``config`` (deep-merged onto :func:`default_config`) and derive the set-up."""
    env_part, own = _split_config(config)
    advisor = own["advisor"]
    if advisor["study_conditions"]:
        env_part = deep_merge(dict(POPULATIONS[advisor["population"]].env_config), env_part)
    env = build_setup(env_part, track)
    sample = dataclasses.replace(env, action_repeat=1)
    drivers = tuple(
        population(advisor["population"], advisor["population_seed"], advisor["population_size"])
    )
    fixed = _driver_index(advisor["driver"], list(drivers))
    make_estimator = _estimator_factory(own, env.config)
    near, far = look_ahead_distances(make_estimator())
    markings = env.config["markings"]
    prior = markings["probabilities"]
    full = copy.deepcopy(env.config)
    del full["observation"]
    full["action"]["steering_only"] = own["steering_only"]
    full["advisor"], full["estimator"] = own["advisor"], own["estimator"]
    return AdvisorSetup(
        config=full,
        env=env,
        sample=sample,
        drivers=drivers,
        fixed_driver=fixed,
        human_drives=advisor["drives"] == "human",
        steering_only=own["steering_only"],
        make_estimator=make_estimator,
        hypotheses=np.asarray(markings["hypotheses"], dtype=np.float64),
        prior=None if prior is None else np.asarray(prior, dtype=np.float64),
        near=near,
        far=far,
        straight=env.road.is_straight,
    )


# ------------------------------------------------------------------ estimate readout
def estimate_readout(est: Estimate, hypotheses: np.ndarray) -> dict[str, np.ndarray]:
    """The estimate's info values (:func:`estimators.wrappers.estimate_info_keys` plus
    ``estimate_heading`` and ``estimate_speed``) for a batch of R runs, leading axis R.

    Mixture mean ``sum_c w_c x_c`` and variance ``sum_c w_c (P_c,ii + (x_c,i - mean_i)^2)``
    over the C components, by elementwise products and sums over the component axis
    only, so a run's values do not depend on the other runs of the batch. The weight of
    each of the env's H hypotheses sums the components whose bias is that hypothesis'
    (the oracle's and the single-hypothesis filter's one component too).
    """
    x, w = est.component_means, est.weights
    weighted = w[:, :, None]
    mean = (weighted * x).sum(axis=1)
    spread = x - mean[:, None, :]
    diagonal = np.diagonal(est.component_covariances, axis1=-2, axis2=-1)
    std = np.sqrt((weighted * (diagonal + spread * spread)).sum(axis=1))
    own = est.hypotheses
    if own.shape[1] == hypotheses.size and bool((own == hypotheses).all()):
        lanes = w
    else:
        match = np.abs(own[:, :, None] - hypotheses[None, None, :]) <= 1e-9
        lanes = np.where(match, weighted, 0.0).sum(axis=1)
    vx, vy = mean[:, 0], mean[:, 2]
    keys = estimate_info_keys()
    values = (mean[:, 1], std[:, 1], vy, vx, mean[:, 3], np.argmax(lanes, axis=1), lanes, mean, std)
    out = dict(zip(keys, values, strict=True))
    out["estimate_heading"] = np.arctan2(vy, vx)
    out["estimate_speed"] = np.hypot(vx, vy)
    return out


def observation_rows(
    readout: Mapping[str, np.ndarray], sensors: np.ndarray, wheel: np.ndarray, bounds: tuple
) -> np.ndarray:
    """(R, D) float32 observations: the estimate, the lane weights, the six raw sensors
    (``sensors`` (R, 6)) and the advisor's measured steering ``wheel`` (R,), saturated at
    ``bounds``."""
    values = np.column_stack(
        [
            readout["estimate_lateral_offset"],
            readout["estimate_lateral_offset_std"],
            readout["estimate_heading"],
            readout["estimate_speed"],
            readout["estimate_weights"],
            sensors,
            wheel,
        ]
    )
    return np.clip(values, bounds[0], bounds[1]).astype(np.float32)


class WheelNoise:
    """Standard normal draws of the wheel sensor of N cars, each from its own generator.

    Drawn in blocks of ``block_size`` per car (as the env's sensor noise), so a car's
    draws are the same alone or among others, whichever cars draw at a time.
    """

    def __init__(self, num_cars: int, block_size: int = 256) -> None:
        self.block_size = int(block_size)
        self._rngs: list[np.random.Generator | None] = [None] * num_cars
        self._block = np.zeros((num_cars, self.block_size))
        self._pos = np.full(num_cars, self.block_size, dtype=np.int64)
        self._all = np.arange(num_cars)

    def restart(self, cars: np.ndarray, seeds: list[int]) -> None:
        """Cars ``cars`` draw from ``default_rng(seed)`` (one seed each) from now on."""
        for car, seed in zip(np.asarray(cars).tolist(), seeds, strict=True):
            self._rngs[car] = np.random.default_rng(seed)
            self._pos[car] = self.block_size

    def draw(self, cars: np.ndarray | None = None) -> np.ndarray:
        """One draw for each car of ``cars`` (indices; None: all), shape (len(cars),)."""
        rows = self._all if cars is None else np.asarray(cars, dtype=np.int64)
        pos = self._pos[rows]
        if pos.max(initial=0) >= self.block_size:
            for car in rows[pos >= self.block_size].tolist():
                rng = self._rngs[car]
                if rng is None:
                    raise RuntimeError(f"car {car} has no wheel-noise generator: restart it first")
                self._block[car] = rng.standard_normal(self.block_size)
                self._pos[car] = 0
            pos = self._pos[rows]
        self._pos[rows] = pos + 1
        return self._block[rows, pos]
