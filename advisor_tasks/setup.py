"""What the advisor task's single and vector env share: the set-up derived from the
configuration, the observation and info layout, the estimate's readout and the wheel
sensor's noise (docs/design.md §12).

The task (``hasa_env/LaneKeepingAdvisor-v0``, :mod:`advisor_tasks.env`): a policy
drives; a synthetic human of a named population sits at the wheel, sees the true
markings and steers as it would drive; its measured steering feeds the human-as-advisor
estimator at the simulation rate; the policy observes the estimate and the raw sensors.

The configuration and the estimator: :mod:`advisor_tasks.config`.

Why a separate module in ``estimators``: the task needs the estimator, and
``hasa_env`` never imports ``estimators`` (docs/design.md §2.1); ``hasa_env`` registers
the ids with entry-point *strings*, which gymnasium imports only at ``gym.make``.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from advisor_tasks.config import (
    default_config,
    describe_config,
    driver_index,
    estimator_factory,
    split_config,
)
from estimators.base import Estimate, LaneEstimator
from estimators.evidence import DECISIONS
from estimators.road_geometry import lane_points_ahead, look_ahead_distances
from estimators.wrappers import estimate_info_keys
from hasa_env.drivers import POPULATIONS, population
from hasa_env.drivers.archetypes import HumanParams
from hasa_env.sim.config import deep_merge
from hasa_env.sim.sensors import SENSOR_NAMES
from hasa_env.sim.setup import INFO_KEYS, RESET_OPTIONS, EnvSetup, build_setup, physical_action
from hasa_env.validation import did_you_mean

__all__ = [
    "ADVISOR_INFO_KEYS",
    "AdvisorSetup",
    "WheelNoise",
    "build_advisor_setup",
    "default_config",
    "describe_config",
    "estimate_readout",
    "observation_names",
    "observation_rows",
    "pop_advisor_option",
]

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
    """The observation's entries in order (see :class:`advisor_tasks.env.LaneKeepingAdvisorEnv`)."""
    return (
        *OBSERVATION_ESTIMATE,
        *(f"estimate_weight_{i}" for i in range(num_hypotheses)),
        *(f"estimate_{name}" for name in DECISIONS),
        "estimate_model_error",
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
        drivers: the population's drivers as they drive in the env's ``scenario``
            (:func:`hasa_env.scenarios.scenario_drivers` with the population seed: the
            scenario's preferred lateral offsets, e.g. ``off_centre_drivers``).
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
        d = len(DECISIONS)
        lo = np.concatenate(
            [[-60.0, 0.0, -math.pi, 0.0], np.zeros(h + d), [0.0], sensor_lo, [-wheel]]
        )
        hi = np.concatenate(
            [[60.0, 100.0, math.pi, 200.0], np.ones(h + d), [100.0], sensor_hi, [wheel]]
        )
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
                if not math.isfinite(action[0]):  # named as the one element it has
                    raise ValueError(f"action must be finite, got [steering={float(action[0])!r}]")
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
    env_part, own = split_config(config)
    advisor = own["advisor"]
    if advisor["study_conditions"]:
        env_part = deep_merge(dict(POPULATIONS[advisor["population"]].env_config), env_part)
    env = build_setup(env_part, track)
    sample = dataclasses.replace(env, action_repeat=1)
    drivers = tuple(
        population(
            advisor["population"],
            advisor["population_seed"],
            advisor["population_size"],
            scenario=env.config["scenario"],
        )
    )
    fixed = driver_index(advisor["driver"], list(drivers))
    make_estimator = estimator_factory(own, env.config)
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
    n_runs = w.shape[0]
    decision = np.broadcast_to(np.asarray(est.decision, dtype=str), (n_runs,))
    code = np.select([decision == name for name in DECISIONS], range(len(DECISIONS)), -1)
    values = (
        mean[:, 1],
        std[:, 1],
        vy,
        vx,
        mean[:, 3],
        np.argmax(lanes, axis=1),
        lanes,
        mean,
        std,
        decision.copy(),
        code,
        np.broadcast_to(np.asarray(est.model_error, dtype=np.float64), (n_runs,)).copy(),
        np.broadcast_to(np.asarray(est.evidence_scale, dtype=np.float64), (n_runs,)).copy(),
    )
    out = dict(zip(estimate_info_keys(), values, strict=True))
    out["estimate_heading"] = np.arctan2(vy, vx)
    out["estimate_speed"] = np.hypot(vx, vy)
    return out


def observation_rows(
    readout: Mapping[str, np.ndarray], sensors: np.ndarray, wheel: np.ndarray, bounds: tuple
) -> np.ndarray:
    """(R, D) float32 observations: the estimate, the lane weights, the six raw sensors
    (``sensors`` (R, 6)) and the advisor's measured steering ``wheel`` (R,), saturated at
    ``bounds``."""
    code = readout["estimate_decision_code"]
    model_error = readout["estimate_model_error"]
    values = np.column_stack(
        [
            readout["estimate_lateral_offset"],
            readout["estimate_lateral_offset_std"],
            readout["estimate_heading"],
            readout["estimate_speed"],
            readout["estimate_weights"],
            *(code == i for i in range(len(DECISIONS))),
            np.where(np.isnan(model_error), 1.0, model_error),
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


def pop_advisor_option(options: dict[str, Any], count: int) -> int | None:
    """Pop and check the ``advisor_index`` reset option (None when absent); an unknown
    option is named with every option this task allows, ``advisor_index`` among them."""
    allowed = sorted((*RESET_OPTIONS, "advisor_index"))
    for name in options:
        if name not in allowed:
            raise ValueError(
                f"unknown reset option {name!r} (allowed keys here: {', '.join(allowed)})"
                + did_you_mean(str(name), allowed)
            )
    if "advisor_index" not in options:
        return None
    value = options.pop("advisor_index")
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not 0 <= value < count:
        raise ValueError(
            f"reset option 'advisor_index' = {value!r} is out of range: allowed integers "
            f"0..{count - 1} (one per driver of the population)"
        )
    return int(value)
