"""Can a steering model drive? Its lane-keeping check in closed loop.

A steering model describes how a driver keeps the car in the lane: its
bearing and lateral-velocity terms say which way the driver steers when the
car drifts. The mixture estimator reads the lane off exactly those terms
(docs/design.md §8.11), and a model whose terms point the wrong way, or are
not identified, still predicts the steering well while it leads the
estimator to the wrong lane. Letting the model drive shows it at once: a
driver that steers away from the lane centre leaves the road within
seconds.

:func:`lane_keeping_check` puts the model in the driver's seat
(:class:`~hasa_env.drivers.ModelDriver`, no equation noise, so the model's
own dynamics are tested) on ``runs`` cars of the given env and config (the
config's disturbances and initial states included) for the config's
``time_limit``; the model passes when no car leaves the road (the env's
termination: past a road edge by more than ``road.offroad_margin``).

Measured on the benchmark's fits (docs/design.md §8.11, 15 population seeds,
4 runs of 30 s on the training run's conditions): the generalized and the
two-point models pass on every seed (largest |y| 0.5-1.2 m); the
sign-flipped stress model leaves the road within 1.5-4.1 s on every seed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from hasa_env.drivers.base import SpeedProfile
from hasa_env.drivers.model_driver import ModelDriver
from hasa_env.drivers.runner import DEFAULT_ENV_ID, run_drivers, run_seeds
from hasa_env.steering.base import SteeringModel

__all__ = [
    "LANE_CHECK_CONFIG",
    "LaneKeepingCheck",
    "lane_keeping_check",
    "lane_keeping_checks",
    "require_lane_keeping",
]

LANE_CHECK_CONFIG: dict[str, Any] = {"time_limit": 30.0}
"""The command-line programs' and the advisor task's check: 4 cars on the default straight
track for 30 s (the benchmark drives the training run's conditions instead)."""


@dataclass(frozen=True)
class LaneKeepingCheck:
    """The outcome of :func:`lane_keeping_check`.

    Attributes:
        passed: no car left the road.
        runs: cars driven; runs_left_road: of those, how many left the road.
        duration: the time limit of each run (s).
        first_exit: the earliest time a car left the road (s; ``math.inf``: none did).
        max_abs_lateral_offset: the largest |lateral offset| of any car (m).
    """

    passed: bool
    runs: int
    runs_left_road: int
    duration: float
    first_exit: float
    max_abs_lateral_offset: float

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (``first_exit`` None where no car left the road)."""
        out = asdict(self)
        out["first_exit"] = None if math.isinf(self.first_exit) else self.first_exit
        return out

    def describe(self) -> str:
        """One line: "keeps its lane (|y| <= 0.83 m, 4 runs of 30 s)" or why not."""
        if self.passed:
            return (
                f"keeps the car on the road (|y| <= {self.max_abs_lateral_offset:.2f} m, "
                f"{self.runs} runs of {self.duration:g} s)"
            )
        return (
            f"drives off the road in {self.runs_left_road} of {self.runs} runs "
            f"(first after {self.first_exit:.1f} s)"
        )


def lane_keeping_check(
    model: SteeringModel,
    *,
    env_id: str = DEFAULT_ENV_ID,
    config: Mapping[str, Any] | None = None,
    speed: SpeedProfile | None = None,
    runs: int = 4,
    seed: int = 0,
    steering_ratio: float = 1.0,
) -> LaneKeepingCheck:
    """Let ``model`` drive ``runs`` cars and see whether it keeps them on the road.

    Args:
        model: a fitted steering model (any :class:`SteeringModel`).
        env_id: the env to drive (e.g. the training run's track).
        config: its config (default: the env's defaults); ``time_limit`` sets how long (s).
        speed: the speed behaviour (default: hold the initial speed); it must have no
            pedal noise (:class:`ModelDriver`).
        runs: number of cars (>= 1), env and driver seeds from :func:`run_seeds`.
        seed: the seed they are derived from.
        steering_ratio: the model's output per road-wheel angle (:class:`ModelDriver`).

    Raises:
        ValueError: ``runs`` < 1, or what :class:`ModelDriver` refuses (an unfitted model,
            a speed profile with pedal noise, a model of another sample time).
    """
    return lane_keeping_checks(
        [model], env_id=env_id, config=config, speed=speed, runs=runs, seed=seed,
        steering_ratio=steering_ratio,
    )[0]  # fmt: skip


def lane_keeping_checks(
    models: Sequence[SteeringModel],
    *,
    env_id: str = DEFAULT_ENV_ID,
    config: Mapping[str, Any] | None = None,
    speed: SpeedProfile | None = None,
    runs: int = 4,
    seed: int = 0,
    steering_ratio: float = 1.0,
) -> list[LaneKeepingCheck]:
    """:func:`lane_keeping_check` of several models at once, all cars in one vector env
    (each model's cars get the same seeds as alone, so its outcome is the same)."""
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ValueError(f"lane_keeping_check: runs must be an integer >= 1, got {runs!r}")
    if not models:
        return []
    drivers = [
        ModelDriver(model, noise_std=0.0, steering_ratio=steering_ratio, speed=speed)
        for model in models
    ]
    seeds = run_seeds(seed, runs, "lane-keeping-check")
    frames = run_drivers(
        [d for d in drivers for _ in range(runs)], seeds * len(drivers), env_id, dict(config or {})
    )
    duration = float(frames[0].attrs["config"]["time_limit"])
    checks = []
    for first in range(0, len(frames), runs):
        exits = []
        largest = 0.0
        for frame in frames[first : first + runs]:
            offset = np.abs(frame["lateral_offset"].to_numpy(dtype=np.float64))
            largest = max(largest, float(np.nanmax(offset)) if offset.size else 0.0)
            if bool(frame["terminated"].any()):
                exits.append(float(frame["time"].iloc[-1]))
        checks.append(
            LaneKeepingCheck(
                passed=not exits,
                runs=runs,
                runs_left_road=len(exits),
                duration=duration,
                first_exit=min(exits) if exits else math.inf,
                max_abs_lateral_offset=largest,
            )
        )
    return checks


def require_lane_keeping(
    model: SteeringModel,
    *,
    steering_ratio: float = 1.0,
    env_id: str = DEFAULT_ENV_ID,
    config: Mapping[str, Any] | None = None,
    what: str = "the steering model",
) -> LaneKeepingCheck:
    """:func:`lane_keeping_check` that raises when it fails (default ``config``:
    :data:`LANE_CHECK_CONFIG` at the model's own sample rate).

    For the tools that give a model's steering to the estimator: a model that cannot keep
    the car on the road has lane terms that do not keep a lane, and the estimator would read
    the lane from them (docs/design.md §8.11).

    Raises:
        ValueError: the model drives off the road (the message says how, and ``what`` it is),
            or it cannot drive this env (e.g. another sample time).
    """
    if config is None:  # the model drives at its own sample rate
        config = LANE_CHECK_CONFIG | {"sim_frequency": round(1.0 / model.dt), "action_repeat": 1}
    try:
        check = lane_keeping_check(
            model, env_id=env_id, config=config, steering_ratio=steering_ratio
        )
    except ValueError as exc:
        raise ValueError(f"{what} cannot be checked by driving: {exc}") from None
    if not check.passed:
        raise ValueError(
            f"{what} ({model.name!r}) {check.describe()} when it steers the car itself "
            f"(hasa_env.drivers.lane_keeping_check on {env_id}): its lane terms do not keep "
            "a lane, so the estimator would take the lane from wrong evidence"
        )
    return check
