"""Configuration of the lane-keeping environment.

The configuration is a nested ``dict``. :func:`default_config` returns the
documented defaults; :func:`make_config` fills a user's (partial)
configuration in with them and validates every value through the shared
validator (:mod:`hasa_env.validation`). An unknown key or a value outside
its allowed range raises :class:`ConfigError` naming the key path
(``"noise.camera"``) and the allowed range with its unit, so
``gym.make(id, config={...})`` never silently ignores a typo.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from hasa_env.scenarios import SCENARIOS
from hasa_env.sim.road import SHIFT_TOWARD
from hasa_env.validation import Field, schema, validate

__all__ = ["ConfigError", "default_config", "make_config", "deep_merge", "describe_config"]


class ConfigError(ValueError):
    """An unknown configuration key or a value outside its allowed range."""


def _number(default: float, doc: str, low: float, high: float, unit: str, **kw: Any) -> Field:
    return Field("number", default, doc, unit=unit, low=low, high=high, **kw)


def _integer(default: int, doc: str, low: int, high: int) -> Field:
    return Field("integer", default, doc, low=low, high=high)


def _choice(default: str, doc: str, *choices: str) -> Field:
    return Field("choice", default, doc, choices=choices)


# The schema: every leaf of the configuration with its default, unit and range.
_SCHEMA: Field = schema(
    {
        "scenario": Field(
            "choice",
            "paper",
            "Named scenario (hasa_env.scenarios.SCENARIOS): the keys it sets lie under "
            "the user's own.",
            choices=tuple(SCENARIOS),
        ),
        "track": _choice(
            "straight",
            "Road: 'straight' or 'curved' (the shipped curved track, see hasa_env.sim.road).",
            "straight",
            "curved",
        ),
        "sim_frequency": _number(
            100.0, "Simulation rate (Hz); Ts = 1 / sim_frequency.", 10.0, 10000.0, "Hz"
        ),
        "action_repeat": _integer(
            1,
            "Simulation steps per env step (policy rate = sim_frequency / action_repeat).",
            1,
            1000,
        ),
        "time_limit": _number(
            30.0, "Episode length (s); then truncated=True.", 0.0, 1e6, "s", low_open=True
        ),
        "vehicle": {
            "wheelbase": _number(2.8, "Wheelbase L (m).", 0.5, 20.0, "m"),
            "max_speed": _number(60.0, "Speed saturation (m/s).", 1.0, 150.0, "m/s"),
        },
        "road": {
            "lane_width": _number(3.6, "Lane width (m).", 2.0, 6.0, "m"),
            "lanes_left": _integer(1, "Lanes left of the ego lane.", 0, 5),
            "lanes_right": _integer(0, "Lanes right of the ego lane.", 0, 5),
            "lane_shifts": Field(
                "json",
                [],
                "Sideways moves of the lane the human drives in, relative to the markings "
                "the camera reads: a list of {station (m, >= 0), length (m, > 0), offset (m), "
                "optional toward ('left': offset as given, the default; 'other_hypothesis': "
                "offset toward where the nearest other hypothesis puts the lane centre, per "
                "episode)}, each a half-cosine ramp (hasa_env.sim.road.Road.driven_offset).",
                max_depth=2,
                max_length=200,
            ),
            "offroad_margin": _number(
                0.5,
                "How far (m) the rear-axle centre may pass the road edge before termination.",
                0.0,
                10.0,
                "m",
            ),
        },
        "initial_state": {
            "lateral_offset": _number(
                -0.5, "Initial lateral offset y (m, left positive).", -10.0, 10.0, "m"
            ),
            "heading": _number(
                0.0, "Initial heading relative to the road (rad).", -1.0, 1.0, "rad"
            ),
            "speed": _number(
                15.0, "Initial speed (m/s), at most vehicle.max_speed.", 0.0, 150.0, "m/s"
            ),
            "steering": _number(0.0, "Initial road-wheel angle (rad).", -1.0, 1.0, "rad"),
            "between_hypotheses": Field(
                "bool",
                False,
                "Start halfway between the true lane's centre and the centre the nearest "
                "other hypothesis puts it at ((b_j - b) / 2, m) instead of at lateral_offset.",
            ),
            "heading_toward_other": _number(
                0.0,
                "Heading (rad) added to the initial heading toward the centre the nearest "
                "other hypothesis puts the lane at: sign(b_j - b) times this (a car drifting "
                "toward the ghost lane); needs two hypotheses when not 0.",
                0.0,
                0.5,
                "rad",
            ),
            "lateral_offset_std": _number(
                0.0, "Std of a Gaussian added to the initial offset (m).", 0.0, 5.0, "m"
            ),
            "heading_std": _number(
                0.0, "Std of a Gaussian added to the initial heading (rad).", 0.0, 0.5, "rad"
            ),
            "speed_std": _number(
                0.0, "Std of a Gaussian added to the initial speed (m/s).", 0.0, 20.0, "m/s"
            ),
        },
        "markings": {
            "hypotheses": Field(
                "numbers",
                [0.0, -1.8],
                "Lane-centre hypotheses: the camera bias b (m) of each; camera reads y + b.",
                unit="m",
                low=-20.0,
                high=20.0,
                non_empty=True,
                unique=True,
            ),
            "probabilities": Field(
                "numbers",
                None,
                "Probability of each hypothesis being true (null: uniform).",
                low=0.0,
                high=1.0,
                non_empty=True,
                optional=True,
            ),
        },
        "noise": {
            "speed": _number(0.05, "Speedometer noise std (m/s).", 0.0, 10.0, "m/s"),
            "camera": _number(0.05, "Camera lateral-offset noise std (m).", 0.0, 10.0, "m"),
            "camera_heading": _number(0.002, "Camera heading noise std (rad).", 0.0, 1.0, "rad"),
            "imu": _number(
                0.05, "IMU acceleration noise std, both axes (m/s^2).", 0.0, 50.0, "m/s^2"
            ),
            "steering": _number(1e-4, "Steering-sensor noise std (rad).", 0.0, 1.0, "rad"),
            "block_size": _integer(
                256,
                "Steps of noise drawn per generator call (same in single and vector env); each "
                "reset starts a new block, so short episodes favour small blocks.",
                1,
                1_000_000,
            ),
        },
        "disturbance": {
            "crosswind": _number(
                0.0,
                "Crosswind gusts: std of their lateral acceleration (m/s^2); 0: none "
                "(see hasa_env.sim.disturbance).",
                0.0,
                10.0,
                "m/s^2",
            ),
            "crosswind_bandwidth": _number(
                1.0, "Highest gust frequency (Hz); the lowest is 0.05 Hz.", 0.05, 20.0, "Hz"
            ),
            "camber": _number(
                0.0,
                "Road camber: std of its lateral acceleration along the road (m/s^2); 0: none.",
                0.0,
                10.0,
                "m/s^2",
            ),
            "camber_wavelength": _number(
                40.0, "Shortest camber wavelength (m); the longest is 20 times it.", 1.0, 1e4, "m"
            ),
            "components": _integer(8, "Sines in each of the two sums.", 1, 64),
        },
        "action": {
            "type": _choice(
                "normalized",
                "'normalized': Box(-1, 1, (2,)) mapped linearly onto the limits; 'physical': Box in rad, m/s^2.",
                "normalized",
                "physical",
            ),
            "max_steering": _number(
                0.5, "Road-wheel angle limit (rad), symmetric.", 0.0, 1.2, "rad", low_open=True
            ),
            "min_acceleration": _number(-6.0, "Lowest acceleration (m/s^2).", -30.0, 0.0, "m/s^2"),
            "max_acceleration": _number(6.0, "Highest acceleration (m/s^2).", 0.0, 30.0, "m/s^2"),
        },
        "observation": {
            "type": _choice(
                "sensors",
                "'sensors' (biased camera etc.), 'state' (true state, oracle) or 'both' (Dict).",
                "sensors",
                "state",
                "both",
            ),
        },
        "reward": {
            "lateral_weight": _number(1.0, "Weight of (y / half lane width)^2.", 0.0, 1e3, ""),
            "steering_rate_weight": _number(
                0.5,
                "Weight of (change of steering per env step / max_steering)^2.",
                0.0,
                1e3,
                "",
            ),
            "offroad_penalty": _number(
                10.0, "Subtracted once when the car leaves the road.", 0.0, 1e6, ""
            ),
        },
        "render": {
            "width": _integer(640, "Frame width (pixels).", 64, 4096),
            "height": _integer(480, "Frame height (pixels).", 64, 4096),
            "pixels_per_metre": _number(12.0, "Top-down zoom.", 0.5, 200.0, "pixels/m"),
            "fps": _integer(30, "Frame rate of render_mode='human'.", 1, 240),
            "view": _choice(
                "top_down",
                "'top_down' (map view following the car) or 'driver' (first-person perspective).",
                "top_down",
                "driver",
            ),
            "show_points": Field(
                "bool",
                False,
                "Driver view: draw the near (6.2 m) and far (20 m) lane-centre points.",
            ),
            "horizontal_field_of_view": _number(
                1.2, "Driver view: horizontal field of view (rad).", 0.2, 2.8, "rad"
            ),
            "eye_height": _number(
                1.2, "Driver view: eye height above the road (m).", 0.3, 5.0, "m"
            ),
        },
    }
)


def _describe(path: str) -> str:
    return f"config key '{path}'" if path else "config"


def _error(path: str, message: str) -> ConfigError:
    return ConfigError(message)


def default_config() -> dict[str, Any]:
    """Return a fresh copy of the default configuration.

    ==========================  =================================================
    key                         meaning (unit, default)
    ==========================  =================================================
    scenario                    named scenario (hasa_env.scenarios, 'paper'); its
                                keys lie under the user's
    track                       'straight' | 'curved'
    sim_frequency               simulation rate (Hz, 100)
    action_repeat               sim steps per env step (1)
    time_limit                  episode length (s, 30)
    vehicle.wheelbase           L (m, 2.8)
    vehicle.max_speed           speed saturation (m/s, 60)
    road.lane_width             m, 3.6
    road.lanes_left/right       extra lanes beside the ego lane (1 / 0)
    road.offroad_margin         m past the edge before termination (0.5)
    road.lane_shifts            sideways moves of the driven lane ([]): list of
                                {station, length, offset} (m), optional toward
                                ('left' | 'other_hypothesis')
    initial_state.*             y (m, -0.5), heading (rad), speed (m/s, 15),
                                steering (rad), and *_std randomisation;
                                between_hypotheses (false), heading_toward_other
                                (rad, 0; added toward the ghost centre)
    markings.hypotheses         camera biases b (m, [0, -1.8]), distinct
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
    return validate({}, _SCHEMA, describe=_describe, error=_error)


def describe_config() -> str:
    """Every configuration key with its default, meaning and allowed range (with its unit)."""
    return "\n".join(
        f"{path} = {spec.default!r}: {spec.doc} Allowed: {spec.allowed()}."
        for path, spec in _SCHEMA.leaves()
    )


def deep_merge(base: Mapping[str, Any], update: Mapping[str, Any]) -> dict[str, Any]:
    """Recursively merge ``update`` into a copy of ``base`` (nested dicts merge, leaves replace)."""
    out = copy.deepcopy(dict(base))
    for key, value in update.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _under(keys: Mapping[str, Any], config: Mapping[str, Any]) -> dict[str, Any]:
    """``config`` with ``keys`` (a scenario's, trusted and shallow) filled in where the user
    gave none; the user's values are neither copied nor walked beyond the scenario's own
    depth (a hostile, deeply nested config reaches the validator as it was given)."""
    out = dict(config)
    for key, value in keys.items():
        if key not in out:
            out[key] = copy.deepcopy(value)
        elif isinstance(value, Mapping) and isinstance(out[key], Mapping):
            out[key] = _under(value, out[key])
    return out


_SHIFT_RANGES = {"station": (0.0, 1e6), "length": (0.1, 1e4), "offset": (-20.0, 20.0)}
_SHIFT_KEYS = {*_SHIFT_RANGES, "toward"}


def _check_lane_shifts(shifts: Any, hypotheses: list[float]) -> None:
    """Each entry of ``road.lane_shifts`` is {station, length, offset} with numbers in range
    and optionally ``toward``, one of :data:`hasa_env.sim.road.SHIFT_TOWARD`;
    ``"other_hypothesis"`` needs at least two ``markings.hypotheses``."""
    if not isinstance(shifts, list):
        raise ConfigError(
            f"config key 'road.lane_shifts' must be a list of {{station, length, offset}}, "
            f"got {type(shifts).__name__}"
        )
    for i, shift in enumerate(shifts):
        where = f"config key 'road.lane_shifts[{i}]"
        keys = set(shift) if isinstance(shift, dict) else set()
        if not isinstance(shift, dict) or not set(_SHIFT_RANGES) <= keys <= _SHIFT_KEYS:
            raise ConfigError(
                f"{where}' must be an object with exactly the keys station, length, offset "
                f"(m) and optionally toward, got {shift!r}"
            )
        for key, (low, high) in _SHIFT_RANGES.items():
            value = shift[key]
            ok = isinstance(value, int | float) and not isinstance(value, bool)
            if not (ok and low <= value <= high):
                raise ConfigError(
                    f"{where}.{key}' must be a number in [{low:g}, {high:g}] m, got {value!r}"
                )
            shift[key] = float(value)
        if "toward" not in shift:
            continue
        if shift["toward"] not in SHIFT_TOWARD:
            allowed = ", ".join(repr(t) for t in SHIFT_TOWARD)
            raise ConfigError(f"{where}.toward' must be one of {allowed}, got {shift['toward']!r}")
        if shift["toward"] == "other_hypothesis" and len(hypotheses) < 2:
            raise ConfigError(
                f"{where}.toward' = 'other_hypothesis' needs at least two "
                f"'markings.hypotheses', got {len(hypotheses)}"
            )


def make_config(config: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Fill ``config`` in with :func:`default_config` (a deep merge) and validate the result.

    Accepts numpy scalars as numbers and integral floats for integer keys,
    and returns plain Python values (``float``, ``int``, ``list``).

    Raises:
        ConfigError: a ``config`` that is not a mapping, an unknown key, a value
            of the wrong type or out of its range, or inconsistent values (e.g.
            probabilities that do not match the hypotheses, an initial speed
            above ``vehicle.max_speed``). The message names the key path and
            the allowed range.
    """
    config = {} if config is None else config
    name = config.get("scenario", "paper") if isinstance(config, Mapping) else None
    if isinstance(name, str) and name in SCENARIOS:
        config = _under(SCENARIOS[name].config, config)
    cfg: dict[str, Any] = validate(config, _SCHEMA, describe=_describe, error=_error)
    _check_lane_shifts(cfg["road"]["lane_shifts"], cfg["markings"]["hypotheses"])
    probs = cfg["markings"]["probabilities"]
    hyps = cfg["markings"]["hypotheses"]
    if cfg["initial_state"]["heading_toward_other"] and len(hyps) < 2:
        raise ConfigError(
            "config key 'initial_state.heading_toward_other' turns the car toward the other "
            f"hypothesis's centre and needs at least two 'markings.hypotheses', got {len(hyps)}"
        )
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
    speed, max_speed = cfg["initial_state"]["speed"], cfg["vehicle"]["max_speed"]
    if speed > max_speed:
        raise ConfigError(
            f"config key 'initial_state.speed' = {speed!r} m/s is above 'vehicle.max_speed' = "
            f"{max_speed!r} m/s; the car cannot start faster than its speed saturation"
        )
    return cfg
