"""What the single and the vector env share: set-up from a config, episode
draws, noise blocks, actions, spaces, and the info/observation layout.

Both envs draw their randomness through these functions from one
``numpy.random.Generator`` per car, in the same order, so the vector env
reproduces N single envs exactly (docs/design.md §3). The transition itself
is :func:`hasa_env.sim.transition.env_step`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any, SupportsFloat

import numpy as np
from gymnasium import spaces

from hasa_env.sim.config import make_config
from hasa_env.sim.disturbance import Disturbance
from hasa_env.sim.dynamics import ARRAY_OPS, SCALAR_OPS, VehicleParams, VehicleState
from hasa_env.sim.road import (
    Road,
    curvature_lookup_scalar,
    make_road,
    nearest_other_hypothesis,
)
from hasa_env.sim.sensors import SENSOR_NAMES, SENSOR_NOISE_KEYS, Sensors, sensor_bounds
from hasa_env.validation import ABSENT, Field, schema, validate

__all__ = [
    "EnvSetup",
    "INFO_KEYS",
    "RECORDING_COLUMNS",
    "recording_row",
    "STATE_NAMES",
    "RESET_BIAS_LIMIT",
    "RESET_HEADING_LIMIT",
    "RESET_LATERAL_LIMIT",
    "RESET_OPTIONS",
    "build_setup",
    "check_reset_options",
    "draw_episode",
]

STATE_NAMES = ("lateral_offset", "heading", "speed", "steering", "road_curvature")
"""True-state observation channels (units: m, rad, m/s, rad, 1/m)."""

INFO_KEYS = (
    "time",
    "station",
    "lateral_offset",
    "heading",
    "speed",
    "steering",
    "acceleration",
    "road_curvature",
    "longitudinal_velocity",
    "lateral_velocity",
    "bias",
    "bias_index",
    *(f"sensor_{name}" for name in SENSOR_NAMES),
)
"""Keys of ``info``, identical at ``reset`` and every ``step`` (all floats, bias_index an int)."""

RECORDING_COLUMNS = ("step", *INFO_KEYS, "reward", "terminated", "truncated")
"""Columns of a recording CSV (one row per env step; row 0 is the reset state).

``steering`` and ``acceleration`` of row k are the physical action applied over
the step that ended at row k (row 0: the initial steering and 0), so replaying
rows 1..n's (steering, acceleration) with ``action.type = "physical"``
reproduces the run.
"""


def recording_row(
    step: int, info: Mapping[str, Any], reward: SupportsFloat, terminated: bool, truncated: bool
) -> list:
    """One recording row (values in :data:`RECORDING_COLUMNS` order) from an env's ``info``."""
    return [
        int(step),
        *(info[k] for k in INFO_KEYS),
        float(reward),
        bool(terminated),
        bool(truncated),
    ]


RESET_OPTIONS = ("bias", "bias_index", "lateral_offset", "heading", "speed", "steering")
"""Keys accepted in ``reset(options=...)``."""


def _zero_curvature(station: Any) -> float:
    """kappa(s) of a straight road: 0.0 (broadcasts against arrays, same arithmetic for both backends)."""
    return 0.0


# lets step_vehicle drop the curvature terms (mypy cannot declare a function's attribute)
_zero_curvature.is_zero = True  # type: ignore[attr-defined]


@dataclass(frozen=True, eq=False)
class EnvSetup:
    """Everything derived once from a validated config."""

    config: dict[str, Any]
    road: Road
    params: VehicleParams
    hypotheses: tuple[float, ...]
    cumulative_probabilities: tuple[float, ...]
    noise_std: Sensors
    """Each sensor channel's noise standard deviation (:mod:`hasa_env.sim.sensors`)."""
    noise_block: int
    lower_edge: float
    upper_edge: float
    steering_limit: float
    acceleration_limits: tuple[float, float]
    normalized_actions: bool
    action_repeat: int
    max_sim_steps: int
    observation_type: str
    reward_weights: tuple[float, float, float]
    """(lateral_weight, steering_rate_weight, offroad_penalty) of the reward."""
    disturbance: Disturbance | None = None
    """Crosswind and camber (:mod:`hasa_env.sim.disturbance`); None when off."""

    @property
    def dt(self) -> float:
        """Simulation sample time Ts (s)."""
        return self.params.dt

    @property
    def env_step_duration(self) -> float:
        """Time between two observations (s): action_repeat * Ts."""
        return self.action_repeat * self.params.dt

    def curvature_scalar(self) -> Callable[[float], float]:
        """kappa(s) for one car (Python float in, float out); a constant 0.0 on a straight road."""
        if self.road.is_straight:
            return _zero_curvature
        return partial(curvature_lookup_scalar, self.road.curvature_list, 1.0 / self.road.spacing)

    def curvature_array(self) -> Callable[[np.ndarray], np.ndarray | float]:
        """kappa(s) for N cars (array in, array out); a constant 0.0 on a straight road."""
        if self.road.is_straight:
            return _zero_curvature
        return self.road.curvature_lookup

    # ----- spaces -------------------------------------------------------------
    def action_space(self) -> spaces.Box:
        if self.normalized_actions:
            return spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        lo = np.array([-self.steering_limit, self.acceleration_limits[0]], dtype=np.float32)
        hi = np.array([self.steering_limit, self.acceleration_limits[1]], dtype=np.float32)
        return spaces.Box(lo, hi, dtype=np.float32)

    def sensor_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of the ``"sensors"`` observation (:func:`hasa_env.sim.sensors.sensor_bounds`)."""
        return sensor_bounds(self.params.max_speed, self.steering_limit)

    def state_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [-50.0, -math.pi, 0.0, -self.steering_limit, -1.0]
        hi = [50.0, math.pi, self.params.max_speed, self.steering_limit, 1.0]
        return np.array(lo, dtype=np.float32), np.array(hi, dtype=np.float32)

    def observation_space(self) -> spaces.Space:
        sensors = spaces.Box(*self.sensor_bounds(), dtype=np.float32)
        state = spaces.Box(*self.state_bounds(), dtype=np.float32)
        if self.observation_type == "sensors":
            return sensors
        if self.observation_type == "state":
            return state
        return spaces.Dict({"sensors": sensors, "state": state})


def build_setup(config: Mapping[str, Any] | None, track: str | None = None) -> EnvSetup:
    """Validate ``config`` (deep-merged onto the defaults) and derive the set-up.

    ``track`` sets the default track of a registered id; an explicit
    ``config["track"]`` wins.
    """
    if track is not None and (config is None or isinstance(config, Mapping)):
        if config is None or "track" not in config:
            config = {**(config or {}), "track": track}
    cfg = make_config(config)  # a config that is not a mapping is a ConfigError there
    road_cfg = cfg["road"]
    width = road_cfg["lane_width"]
    hyps = tuple(cfg["markings"]["hypotheses"])
    road = make_road(
        cfg["track"], lane_width=width, lane_shifts=road_cfg["lane_shifts"], hypotheses=hyps
    )
    dt = 1.0 / cfg["sim_frequency"]
    params = VehicleParams(cfg["vehicle"]["wheelbase"], cfg["vehicle"]["max_speed"], dt)
    probs = cfg["markings"]["probabilities"] or [1.0 / len(hyps)] * len(hyps)
    cum = tuple(float(c) for c in np.cumsum(probs))
    noise = cfg["noise"]
    noise_std = Sensors(*(float(noise[key]) for key in SENSOR_NOISE_KEYS))
    margin = road_cfg["offroad_margin"]
    lower = -width / 2 - road_cfg["lanes_right"] * width - margin
    upper = width / 2 + road_cfg["lanes_left"] * width + margin
    act = cfg["action"]
    return EnvSetup(
        config=cfg,
        road=road,
        params=params,
        hypotheses=hyps,
        cumulative_probabilities=cum,
        noise_std=noise_std,
        noise_block=int(noise["block_size"]),
        lower_edge=lower,
        upper_edge=upper,
        steering_limit=act["max_steering"],
        acceleration_limits=(act["min_acceleration"], act["max_acceleration"]),
        normalized_actions=act["type"] == "normalized",
        action_repeat=int(cfg["action_repeat"]),
        max_sim_steps=max(1, round(cfg["time_limit"] * cfg["sim_frequency"])),
        observation_type=cfg["observation"]["type"],
        reward_weights=(
            float(cfg["reward"]["lateral_weight"]),
            float(cfg["reward"]["steering_rate_weight"]),
            float(cfg["reward"]["offroad_penalty"]),
        ),
        disturbance=Disturbance.from_config(cfg),
    )


RESET_LATERAL_LIMIT = 30.0
"""Largest |lateral_offset| (m) a reset option may set."""

RESET_HEADING_LIMIT = 0.5 * math.pi
"""Largest |heading| (rad) a reset option may set."""

RESET_BIAS_LIMIT = 20.0
"""Largest |bias| (m) a reset option may set (the range of ``markings.hypotheses``)."""


def check_reset_options(options: Any, setup: EnvSetup) -> dict[str, Any]:
    """The reset options, validated and converted (shared validator), before anything is drawn.

    ``options`` is None or a mapping of :data:`RESET_OPTIONS` keys: ``bias``
    (m, within +-20; one that is none of ``markings.hypotheses`` gives ``bias_index`` -1:
    a true lane the estimator's hypotheses do not contain), ``bias_index`` (0 .. number of
    hypotheses - 1; given with ``bias``, the two must agree),
    ``lateral_offset`` (m, +-30), ``heading`` (rad, +-pi/2), ``speed`` (m/s,
    0 .. ``vehicle.max_speed``), ``steering`` (rad, within the steering limit).

    Raises:
        ValueError: naming the option and its allowed range (or that the
            options are not a mapping); nothing has been drawn or changed.
    """
    limit = setup.steering_limit
    spec = schema(
        {
            "bias": Field("number", ABSENT, unit="m", low=-RESET_BIAS_LIMIT, high=RESET_BIAS_LIMIT),
            "bias_index": Field(
                "integer", ABSENT, low=0, high=len(setup.hypotheses) - 1,
                hint="one per markings.hypotheses",
            ),
            "lateral_offset": Field(
                "number", ABSENT, unit="m", low=-RESET_LATERAL_LIMIT, high=RESET_LATERAL_LIMIT
            ),
            "heading": Field(
                "number", ABSENT, unit="rad", low=-RESET_HEADING_LIMIT, high=RESET_HEADING_LIMIT
            ),
            "speed": Field("number", ABSENT, unit="m/s", low=0.0, high=setup.params.max_speed),
            "steering": Field("number", ABSENT, unit="rad", low=-limit, high=limit),
        }
    )  # fmt: skip
    checked = validate(
        {} if options is None else options,
        spec,
        describe=lambda path: f"reset option '{path}'" if path else "reset options",
        error=lambda path, message: ValueError(message),
    )
    if "bias" in checked and "bias_index" in checked:
        chosen = setup.hypotheses[checked["bias_index"]]
        if chosen != checked["bias"]:
            raise ValueError(
                f"reset options 'bias' = {checked['bias']!r} and 'bias_index' = "
                f"{checked['bias_index']} disagree: hypothesis {checked['bias_index']} is "
                f"{chosen!r} m; give one of them"
            )
    return checked


def draw_episode(
    rng: np.random.Generator, setup: EnvSetup, options: Mapping[str, Any] | None
) -> tuple[VehicleState, int, float, np.ndarray, list[float]]:
    """Draw one episode's start: state, true-hypothesis index, bias (m), noise block,
    disturbance phases (rad; empty without a disturbance).

    Draw order (fixed, whatever the options): one uniform for the bias, three
    normals for the initial-state randomisation, the first noise block, then
    (only with a disturbance) one uniform phase per disturbance sine.
    """
    options = check_reset_options(options, setup)  # before any draw: a refused reset draws nothing
    u = float(rng.random())
    jitter = rng.standard_normal(3)
    block = draw_noise_block(rng, setup)
    cum = setup.cumulative_probabilities
    index = next((i for i, c in enumerate(cum) if u < c), len(cum) - 1)
    bias = setup.hypotheses[index]
    if "bias_index" in options:
        index = options["bias_index"]
        bias = setup.hypotheses[index]
    if "bias" in options:
        bias = options["bias"]
        matches = [i for i, h in enumerate(setup.hypotheses) if h == bias]
        index = matches[0] if matches else -1
    init = setup.config["initial_state"]
    ghost = _ghost_centre(bias, setup.hypotheses)
    y = init["lateral_offset"]
    if init["between_hypotheses"] and ghost is not None:
        y = 0.5 * ghost  # halfway between the true centre (y = 0) and the ghost's
    y = y + init["lateral_offset_std"] * float(jitter[0])
    th = init["heading"] + init["heading_std"] * float(jitter[1])
    if init["heading_toward_other"] and ghost is not None:  # two hypotheses: config check
        th += math.copysign(init["heading_toward_other"], ghost)
    v = init["speed"] + init["speed_std"] * float(jitter[2])
    v = min(max(v, 0.0), setup.params.max_speed)
    delta = init["steering"]
    y = options.get("lateral_offset", y)
    th = options.get("heading", th)
    v = options.get("speed", v)
    delta = options.get("steering", delta)
    phases: list[float] = []
    if setup.disturbance is not None:
        phases = rng.uniform(0.0, 2.0 * math.pi, setup.disturbance.n_phases).tolist()
    return VehicleState(0.0, y, th, v, delta), index, bias, block, phases


def _ghost_centre(bias: float, hypotheses: Sequence[float]) -> float | None:
    """Where the nearest other hypothesis b_j puts the lane's centre relative to the true
    one, ``y = b_j - b`` (m); None when there is no other hypothesis. Used by
    ``initial_state.between_hypotheses`` (start at half of it) and
    ``initial_state.heading_toward_other`` (turn toward its side)."""
    nearest = nearest_other_hypothesis(bias, hypotheses)
    return None if nearest is None else nearest - bias


def draw_noise_block(rng: np.random.Generator, setup: EnvSetup) -> np.ndarray:
    """The next block of standard-normal sensor noise, shape (block_size, 6)."""
    return rng.standard_normal((setup.noise_block, len(setup.noise_std)))


def physical_action(setup: EnvSetup, action: Any, num_envs: int | None = None) -> tuple[Any, Any]:
    """Validate an action and map it to (steering rad, acceleration m/s^2), clipped to the limits.

    ``num_envs`` None: one car, ``action`` of shape (2,), returns two floats;
    an int N: N cars, ``action`` of shape (N, 2), returns two (N,) arrays.
    The same arithmetic for both (the backends of :mod:`hasa_env.sim.dynamics`).
    """
    single = num_envs is None
    expected = (2,) if num_envs is None else (num_envs, 2)
    arr = _action_array(action, expected)
    if single:
        steer, acc = arr.tolist()
        if not (math.isfinite(steer) and math.isfinite(acc)):
            raise ValueError(
                f"action must be finite, got [steering={steer!r}, acceleration={acc!r}]"
            )
        ops = SCALAR_OPS
    else:
        if not np.all(np.isfinite(arr)):
            bad = int(np.argwhere(~np.isfinite(arr))[0][0])
            raise ValueError(f"actions must be finite; env {bad} got {arr[bad].tolist()}")
        steer, acc = arr[:, 0], arr[:, 1]
        ops = ARRAY_OPS
    lo, hi = setup.acceleration_limits
    limit = setup.steering_limit
    if setup.normalized_actions:
        steer = ops.minimum(ops.maximum(steer, -1.0), 1.0) * limit
        acc = ops.minimum(ops.maximum(acc, -1.0), 1.0)
        return steer, lo + (acc + 1.0) * 0.5 * (hi - lo)
    return ops.minimum(ops.maximum(steer, -limit), limit), ops.minimum(ops.maximum(acc, lo), hi)


def _action_array(action: Any, expected: tuple[int, ...]) -> np.ndarray:
    """``action`` as a float64 array of shape ``expected``, or a ValueError saying why not.

    Only real numbers are actions: strings, complex numbers, dates, masked
    arrays and other objects are refused rather than converted.
    """
    if type(action) is np.ndarray and action.dtype.kind == "f" and action.shape == expected:
        return action.astype(np.float64, copy=False)  # the common case, checked cheaply
    what = "action" if len(expected) == 1 else "actions"
    layout = (
        "[steering, acceleration]"
        if len(expected) == 1
        else "one [steering, acceleration] row per env"
    )
    if isinstance(action, np.ma.MaskedArray):
        raise ValueError(f"{what} must be a plain array of numbers, got a masked array")
    try:
        raw = np.asarray(action)
    except (ValueError, TypeError, OverflowError):  # ragged lists, mixed str/bytes, ...
        raise ValueError(
            f"{what} must be an array of real numbers of shape {expected} ({layout}), got "
            f"{type(action).__name__} {action!r:.80}"
        ) from None
    if raw.dtype.kind not in "iuf":
        raise ValueError(
            f"{what} must be real numbers (int or float), got dtype {raw.dtype} ({action!r:.80})"
        )
    arr = raw.astype(np.float64, copy=False)
    if arr.shape != expected:
        raise ValueError(f"{what} must have shape {expected} ({layout}), got shape {arr.shape}")
    return arr
