"""Configuration of the lane-keeping environment.

The configuration is a nested ``dict``. :func:`default_config` returns the
documented defaults; :func:`make_config` deep-merges a user's (partial)
configuration onto them and validates every value. An unknown key or a value
outside its allowed range raises :class:`ConfigError` naming the key path
(``"noise.camera"``) and the allowed range, so ``gym.make(id, config={...})``
never silently ignores a typo.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["ConfigError", "default_config", "make_config", "deep_merge", "describe_config"]


class ConfigError(ValueError):
    """An unknown configuration key or a value outside its allowed range."""


@dataclass(frozen=True)
class _Spec:
    """Allowed values of one configuration leaf."""

    default: Any
    doc: str
    kind: str = "float"  # float | int | bool | choice | list | optional_list
    low: float | None = None
    high: float | None = None
    choices: tuple[Any, ...] = ()
    low_open: bool = False  # True: value must be strictly greater than low

    def allowed(self) -> str:
        if self.kind == "choice":
            return "one of " + ", ".join(repr(c) for c in self.choices)
        if self.kind == "bool":
            return "true or false"
        if self.kind in ("list", "optional_list"):
            rng = _range_text(self.low, self.high, self.low_open)
            base = f"a non-empty list of finite numbers{(' in ' + rng) if rng else ''}"
            return base + (" or null" if self.kind == "optional_list" else "")
        rng = _range_text(self.low, self.high, self.low_open)
        word = "an integer" if self.kind == "int" else "a finite number"
        return f"{word}{(' in ' + rng) if rng else ''}"


def _range_text(low: float | None, high: float | None, low_open: bool) -> str:
    if low is None and high is None:
        return ""
    left = "(" if low_open else "["
    lo = "-inf" if low is None else f"{low:g}"
    hi = "inf" if high is None else f"{high:g}"
    return f"{left}{lo}, {hi}]"


# The schema: every leaf of the configuration with its default, unit and range.
_SCHEMA: dict[str, Any] = {
    "track": _Spec(
        "straight",
        "Road: 'straight' or 'curved' (the shipped curved track, see hasa_env.sim.road).",
        kind="choice",
        choices=("straight", "curved"),
    ),
    "sim_frequency": _Spec(
        100.0, "Simulation rate (Hz); Ts = 1 / sim_frequency.", low=10.0, high=10000.0
    ),
    "action_repeat": _Spec(
        1,
        "Simulation steps per env step (policy rate = sim_frequency / action_repeat).",
        kind="int",
        low=1,
        high=1000,
    ),
    "time_limit": _Spec(
        30.0, "Episode length (s); then truncated=True.", low=0.0, high=1e6, low_open=True
    ),
    "vehicle": {
        "wheelbase": _Spec(2.8, "Wheelbase L (m).", low=0.5, high=20.0),
        "max_speed": _Spec(60.0, "Speed saturation (m/s).", low=1.0, high=150.0),
    },
    "road": {
        "lane_width": _Spec(3.6, "Lane width (m).", low=2.0, high=6.0),
        "lanes_left": _Spec(1, "Lanes left of the ego lane.", kind="int", low=0, high=5),
        "lanes_right": _Spec(0, "Lanes right of the ego lane.", kind="int", low=0, high=5),
        "offroad_margin": _Spec(
            0.5,
            "How far (m) the rear-axle centre may pass the road edge before termination.",
            low=0.0,
            high=10.0,
        ),
    },
    "initial_state": {
        "lateral_offset": _Spec(
            -0.5, "Initial lateral offset y (m, left positive).", low=-10.0, high=10.0
        ),
        "heading": _Spec(0.0, "Initial heading relative to the road (rad).", low=-1.0, high=1.0),
        "speed": _Spec(15.0, "Initial speed (m/s).", low=0.0, high=150.0),
        "steering": _Spec(0.0, "Initial road-wheel angle (rad).", low=-1.0, high=1.0),
        "lateral_offset_std": _Spec(
            0.0, "Std of a Gaussian added to the initial offset (m).", low=0.0, high=5.0
        ),
        "heading_std": _Spec(
            0.0, "Std of a Gaussian added to the initial heading (rad).", low=0.0, high=0.5
        ),
        "speed_std": _Spec(
            0.0, "Std of a Gaussian added to the initial speed (m/s).", low=0.0, high=20.0
        ),
    },
    "markings": {
        "hypotheses": _Spec(
            [0.0, -1.8],
            "Lane-centre hypotheses: the camera bias b (m) of each; camera reads y + b.",
            kind="list",
            low=-20.0,
            high=20.0,
        ),
        "probabilities": _Spec(
            None,
            "Probability of each hypothesis being true (null: uniform).",
            kind="optional_list",
            low=0.0,
            high=1.0,
        ),
    },
    "noise": {
        "speed": _Spec(0.05, "Speedometer noise std (m/s).", low=0.0, high=10.0),
        "camera": _Spec(0.05, "Camera lateral-offset noise std (m).", low=0.0, high=10.0),
        "camera_heading": _Spec(0.002, "Camera heading noise std (rad).", low=0.0, high=1.0),
        "imu": _Spec(0.05, "IMU acceleration noise std, both axes (m/s^2).", low=0.0, high=50.0),
        "steering": _Spec(1e-4, "Steering-sensor noise std (rad).", low=0.0, high=1.0),
        "block_size": _Spec(
            256,
            "Steps of noise drawn per generator call (same in single and vector env); each "
            "reset starts a new block, so short episodes favour small blocks.",
            kind="int",
            low=1,
            high=1_000_000,
        ),
    },
    "disturbance": {
        "crosswind": _Spec(
            0.0,
            "Crosswind gusts: std of their lateral acceleration (m/s^2); 0: none "
            "(see hasa_env.sim.disturbance).",
            low=0.0,
            high=10.0,
        ),
        "crosswind_bandwidth": _Spec(
            1.0, "Highest gust frequency (Hz); the lowest is 0.05 Hz.", low=0.05, high=20.0
        ),
        "camber": _Spec(
            0.0,
            "Road camber: std of its lateral acceleration along the road (m/s^2); 0: none.",
            low=0.0,
            high=10.0,
        ),
        "camber_wavelength": _Spec(
            40.0, "Shortest camber wavelength (m); the longest is 20 times it.", low=1.0, high=1e4
        ),
        "components": _Spec(8, "Sines in each of the two sums.", kind="int", low=1, high=64),
    },
    "action": {
        "type": _Spec(
            "normalized",
            "'normalized': Box(-1, 1, (2,)) mapped linearly onto the limits; 'physical': Box in rad, m/s^2.",
            kind="choice",
            choices=("normalized", "physical"),
        ),
        "max_steering": _Spec(
            0.5, "Road-wheel angle limit (rad), symmetric.", low=0.0, high=1.2, low_open=True
        ),
        "min_acceleration": _Spec(-6.0, "Lowest acceleration (m/s^2).", low=-30.0, high=0.0),
        "max_acceleration": _Spec(6.0, "Highest acceleration (m/s^2).", low=0.0, high=30.0),
    },
    "observation": {
        "type": _Spec(
            "sensors",
            "'sensors' (biased camera etc.), 'state' (true state, oracle) or 'both' (Dict).",
            kind="choice",
            choices=("sensors", "state", "both"),
        ),
    },
    "reward": {
        "lateral_weight": _Spec(1.0, "Weight of (y / half lane width)^2.", low=0.0, high=1e3),
        "steering_rate_weight": _Spec(
            0.5, "Weight of (change of steering per env step / max_steering)^2.", low=0.0, high=1e3
        ),
        "offroad_penalty": _Spec(
            10.0, "Subtracted once when the car leaves the road.", low=0.0, high=1e6
        ),
    },
    "render": {
        "width": _Spec(640, "Frame width (pixels).", kind="int", low=64, high=4096),
        "height": _Spec(480, "Frame height (pixels).", kind="int", low=64, high=4096),
        "pixels_per_metre": _Spec(12.0, "Top-down zoom.", low=0.5, high=200.0),
        "fps": _Spec(30, "Frame rate of render_mode='human'.", kind="int", low=1, high=240),
        "view": _Spec(
            "top_down",
            "'top_down' (map view following the car) or 'driver' (first-person perspective).",
            kind="choice",
            choices=("top_down", "driver"),
        ),
        "show_points": _Spec(
            False,
            "Driver view: draw the near (6.2 m) and far (20 m) lane-centre points.",
            kind="bool",
        ),
        "horizontal_field_of_view": _Spec(
            1.2, "Driver view: horizontal field of view (rad).", low=0.2, high=2.8
        ),
        "eye_height": _Spec(1.2, "Driver view: eye height above the road (m).", low=0.3, high=5.0),
    },
}


def _defaults(schema: Mapping[str, Any]) -> dict[str, Any]:
    return {
        k: (_defaults(v) if isinstance(v, Mapping) else copy.deepcopy(v.default))
        for k, v in schema.items()
    }


def default_config() -> dict[str, Any]:
    """Return a fresh copy of the default configuration.

    ==========================  =================================================
    key                         meaning (unit, default)
    ==========================  =================================================
    track                       'straight' | 'curved'
    sim_frequency               simulation rate (Hz, 100)
    action_repeat               sim steps per env step (1)
    time_limit                  episode length (s, 30)
    vehicle.wheelbase           L (m, 2.8)
    vehicle.max_speed           speed saturation (m/s, 60)
    road.lane_width             m, 3.6
    road.lanes_left/right       extra lanes beside the ego lane (1 / 0)
    road.offroad_margin         m past the edge before termination (0.5)
    initial_state.*             y (m, -0.5), heading (rad), speed (m/s, 15),
                                steering (rad), and *_std randomisation
    markings.hypotheses         camera biases b (m, [0, -1.8])
    markings.probabilities      prior of each (uniform)
    noise.*                     sensor noise std: speed, camera, camera_heading,
                                imu, steering; block_size
    disturbance.*               crosswind / camber std (m/s^2, 0 = off),
                                crosswind_bandwidth (Hz), camber_wavelength (m),
                                components
    action.type                 'normalized' | 'physical'
    action.max_steering         rad (0.5); min/max_acceleration m/s^2 (-6 / 6)
    observation.type            'sensors' | 'state' | 'both'
    reward.*                    lateral_weight, steering_rate_weight,
                                offroad_penalty
    render.*                    width, height, pixels_per_metre, fps, view
                                ('top_down' | 'driver'), show_points,
                                horizontal_field_of_view (rad), eye_height (m)
    ==========================  =================================================

    :func:`describe_config` prints every key with its documentation and range.
    """
    return _defaults(_SCHEMA)


def describe_config() -> str:
    """Every configuration key with its default, meaning and allowed range."""
    lines: list[str] = []

    def walk(schema: Mapping[str, Any], prefix: str) -> None:
        for key, spec in schema.items():
            path = f"{prefix}{key}"
            if isinstance(spec, Mapping):
                walk(spec, path + ".")
            else:
                lines.append(f"{path} = {spec.default!r}: {spec.doc} Allowed: {spec.allowed()}.")

    walk(_SCHEMA, "")
    return "\n".join(lines)


def deep_merge(base: Mapping[str, Any], update: Mapping[str, Any]) -> dict[str, Any]:
    """Recursively merge ``update`` into a copy of ``base`` (nested dicts merge, leaves replace)."""
    out = copy.deepcopy(dict(base))
    for key, value in update.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _check_number(path: str, value: Any, spec: _Spec) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"config key '{path}' must be {spec.allowed()}, got {value!r}")
    if not math.isfinite(value):
        raise ConfigError(f"config key '{path}' must be {spec.allowed()}, got {value!r}")
    bad_low = spec.low is not None and (value <= spec.low if spec.low_open else value < spec.low)
    bad_high = spec.high is not None and value > spec.high
    if bad_low or bad_high:
        raise ConfigError(
            f"config key '{path}' = {value!r} is out of range: allowed {spec.allowed()}"
        )
    return value


def _validate_leaf(path: str, value: Any, spec: _Spec) -> Any:
    if spec.kind == "choice":
        if value not in spec.choices:
            raise ConfigError(f"config key '{path}' = {value!r} is not allowed: {spec.allowed()}")
        return value
    if spec.kind == "bool":
        if not isinstance(value, bool):
            raise ConfigError(f"config key '{path}' must be {spec.allowed()}, got {value!r}")
        return value
    if spec.kind == "int":
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"config key '{path}' must be {spec.allowed()}, got {value!r}")
        _check_number(path, value, spec)
        return value
    if spec.kind in ("list", "optional_list"):
        if value is None and spec.kind == "optional_list":
            return None
        if isinstance(value, str | bytes) or not hasattr(value, "__iter__"):
            raise ConfigError(f"config key '{path}' must be {spec.allowed()}, got {value!r}")
        items = list(value)
        if not items:
            raise ConfigError(f"config key '{path}' must be {spec.allowed()}, got an empty list")
        return [float(_check_number(f"{path}[{i}]", v, spec)) for i, v in enumerate(items)]
    return float(_check_number(path, value, spec))


def _validate(config: Mapping[str, Any], schema: Mapping[str, Any], prefix: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    unknown = [k for k in config if k not in schema]
    if unknown:
        allowed = ", ".join(sorted(schema))
        raise ConfigError(
            f"unknown config key '{prefix}{unknown[0]}' (allowed keys here: {allowed})"
        )
    for key, spec in schema.items():
        path = f"{prefix}{key}"
        value = config[key]
        if isinstance(spec, Mapping):
            if not isinstance(value, Mapping):
                raise ConfigError(
                    f"config key '{path}' must be a mapping of {sorted(spec)}, got {value!r}"
                )
            out[key] = _validate(value, spec, path + ".")
        else:
            out[key] = _validate_leaf(path, value, spec)
    return out


def make_config(config: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Deep-merge ``config`` onto :func:`default_config` and validate the result.

    Raises:
        ConfigError: an unknown key, a value of the wrong type or out of its range,
            or inconsistent values (e.g. probabilities that do not match the
            hypotheses). The message names the key path and the allowed range.
    """
    if config is None:
        config = {}
    if not isinstance(config, Mapping):
        raise ConfigError(f"config must be a mapping (dict), got {type(config).__name__}")
    merged = deep_merge(default_config(), config)
    cfg = _validate(merged, _SCHEMA, "")
    probs = cfg["markings"]["probabilities"]
    hyps = cfg["markings"]["hypotheses"]
    if probs is not None:
        if len(probs) != len(hyps):
            raise ConfigError(
                f"config key 'markings.probabilities' has {len(probs)} entries but "
                f"'markings.hypotheses' has {len(hyps)}; give one probability per hypothesis"
            )
        if abs(sum(probs) - 1.0) > 1e-9:
            raise ConfigError(
                f"config key 'markings.probabilities' must sum to 1, sums to {sum(probs):.12g}"
            )
    if cfg["action"]["min_acceleration"] >= cfg["action"]["max_acceleration"]:
        raise ConfigError(
            "config keys 'action.min_acceleration' and 'action.max_acceleration' must satisfy min < max"
        )
    return cfg
