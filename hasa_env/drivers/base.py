"""The driver protocol, speed profiles, and batches of drivers acting on arrays.

A :class:`Driver` is what sits behind the steering wheel: given the env's
*true* ``info`` (never the biased camera) and the road geometry, it returns a
physical action (road-wheel angle in rad, acceleration in m/s^2). Drivers are
seeded (``reset(seed)``) and reproducible.

To drive many cars at once in the native vector env, drivers act on arrays
through a :class:`BatchDriver`: :func:`make_batch` groups drivers of a class
that provides ``make_batch`` (the synthetic and model drivers do) into one
vectorized batch, and runs any other driver car by car.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from hasa_env.sim.road import Road

__all__ = [
    "Driver",
    "BatchDriver",
    "SpeedProfile",
    "LoopBatch",
    "CompositeBatch",
    "make_batch",
    "speed_command",
    "speed_profile_arrays",
    "info_arrays",
]


@runtime_checkable
class Driver(Protocol):
    """A seeded driver acting on the env's true state.

    ``reset(seed, dt=...)`` starts a new run (``dt`` is the env step, s);
    ``act(info, road)`` gets the env's ``info`` at time k (the dict of
    :data:`hasa_env.sim.setup.INFO_KEYS`, true state) and the road, and returns
    ``(steering, acceleration)``: the road-wheel angle (rad) and acceleration
    (m/s^2) to apply over the next step.
    """

    def reset(self, seed: int | None = None, *, dt: float = 0.01) -> None: ...

    def act(self, info: Mapping[str, Any], road: Road) -> tuple[float, float]: ...


@runtime_checkable
class BatchDriver(Protocol):
    """N drivers acting on N cars' info arrays at once (see :func:`make_batch`)."""

    num_cars: int

    def reset(self, seeds: Sequence[int | None], dt: float) -> None: ...

    def act(self, info: Mapping[str, np.ndarray], road: Road) -> tuple[np.ndarray, np.ndarray]: ...


@runtime_checkable
class PartialBatchDriver(BatchDriver, Protocol):
    """A :class:`BatchDriver` whose cars restart one by one (``reset(..., cars=...)``,
    one seed per entry of ``cars``) and whose steering can be asked alone: what a
    vector env with partial resets needs of its advisors (the archetypes'
    :class:`~hasa_env.drivers.human.HumanBatch`, :class:`LoopBatch`, :class:`CompositeBatch`)."""

    def reset(
        self, seeds: Sequence[int | None], dt: float, cars: Sequence[int] | np.ndarray | None = None
    ) -> None: ...

    def steer(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray: ...


# ---------------------------------------------------------------- speed
@dataclass(frozen=True)
class SpeedProfile:
    """How a driver chooses its speed.

    The reference speed is the speed at reset, v0, until ``start_time``; then
    it ramps at ``ramp_rate`` towards ``target_speed`` (None: hold v0). A
    proportional controller with feed-forward of the ramp tracks it. On a
    curved road the driver also slows for bends ahead: the speed at any point
    up to its braking distance ahead is kept below
    ``sqrt(max_lateral_acceleration / |curvature|)``, braking at
    ``comfortable_deceleration``.

    The foot is not a cruise control: a synthetic human (:class:`~hasa_env.drivers.human.HumanBatch`)
    adds a pedal remnant to the commanded acceleration, an Ornstein-Uhlenbeck process of
    stationary std ``pedal_noise`` (m/s^2) and time constant ``pedal_time_constant`` (s).
    Through the speed loop of gain g it moves a held speed by a std of
    ``pedal_noise * sqrt(tau / (g (1 + g tau)))`` (tau the time constant): 0.29 m/s for
    0.35 m/s^2, 2 s and g = 1. 0 (the default) is a perfectly held speed.

    Attributes:
        target_speed: m/s, or None to hold the initial speed.
        start_time: s when the ramp starts.
        ramp_rate: m/s^2 of the ramp (> 0).
        gain: 1/s of the speed controller.
        max_lateral_acceleration: m/s^2 the driver accepts in bends (inf: ignores bends).
        comfortable_deceleration: m/s^2 used to slow down before a bend.
        max_acceleration: m/s^2, limit of the speed controller (both ways).
        pedal_noise: m/s^2, stationary std of the pedal remnant (>= 0; 0: none).
        pedal_time_constant: s, time constant of the pedal remnant (> 0).
    """

    target_speed: float | None = None
    start_time: float = 0.0
    ramp_rate: float = 1.5
    gain: float = 1.0
    max_lateral_acceleration: float = math.inf
    comfortable_deceleration: float = 2.5
    max_acceleration: float = 4.0
    pedal_noise: float = 0.0
    pedal_time_constant: float = 2.0

    def __post_init__(self) -> None:
        if self.target_speed is not None and not (0.0 <= self.target_speed <= 150.0):
            raise ValueError(
                "SpeedProfile.target_speed must be in [0, 150] m/s or None, "
                f"got {self.target_speed}"
            )
        for name in ("ramp_rate", "gain", "max_lateral_acceleration", "comfortable_deceleration",
                     "max_acceleration", "pedal_time_constant"):  # fmt: skip
            value = getattr(self, name)
            if not value > 0:
                raise ValueError(f"SpeedProfile.{name} must be > 0, got {value}")
        if not math.isfinite(self.start_time) or self.start_time < 0:
            raise ValueError(f"SpeedProfile.start_time must be >= 0 s, got {self.start_time}")
        if not (math.isfinite(self.pedal_noise) and 0.0 <= self.pedal_noise <= 4.0):
            raise ValueError(
                f"SpeedProfile.pedal_noise must be in [0, 4] m/s^2, got {self.pedal_noise}"
            )
        if not math.isfinite(self.pedal_time_constant):
            raise ValueError(
                "SpeedProfile.pedal_time_constant must be a finite number of seconds > 0, "
                f"got {self.pedal_time_constant}"
            )

    @classmethod
    def hold(cls, max_lateral_acceleration: float = math.inf) -> SpeedProfile:
        """Keep the speed the run starts with."""
        return cls(max_lateral_acceleration=max_lateral_acceleration)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def speed_profile_arrays(profiles: Sequence[SpeedProfile]) -> dict[str, np.ndarray]:
    """The fields of one :class:`SpeedProfile` per car as arrays of shape (n,), keyed as
    :func:`speed_command` reads them (``target`` NaN: no target speed)."""
    return {
        "target": np.array(
            [np.nan if p.target_speed is None else p.target_speed for p in profiles]
        ),
        "start": np.array([p.start_time for p in profiles]),
        "rate": np.array([p.ramp_rate for p in profiles]),
        "gain": np.array([p.gain for p in profiles]),
        "lateral": np.array([p.max_lateral_acceleration for p in profiles]),
        "braking": np.array([p.comfortable_deceleration for p in profiles]),
        "limit": np.array([p.max_acceleration for p in profiles]),
        "pedal_noise": np.array([p.pedal_noise for p in profiles]),
        "pedal_time_constant": np.array([p.pedal_time_constant for p in profiles]),
    }


_PREVIEW = np.linspace(0.0, 1.0, 33)


def speed_command(
    profile: Mapping[str, np.ndarray],
    initial_speed: np.ndarray,
    info: Mapping[str, np.ndarray],
    road: Road,
    remnant: np.ndarray | None = None,
) -> np.ndarray:
    """Acceleration (m/s^2) of N cars following their speed profiles (see :class:`SpeedProfile`),
    with ``remnant`` (the pedal remnant, m/s^2, (N,)) added before the limit."""
    t = info["time"]
    v = info["speed"]
    target = profile["target"]
    ramping = np.isfinite(target)
    goal = np.where(ramping, target, initial_speed)
    elapsed = np.maximum(t - profile["start"], 0.0)
    direction = np.sign(goal - initial_speed)
    reference = initial_speed + direction * np.minimum(
        profile["rate"] * elapsed, np.abs(goal - initial_speed)
    )
    still_ramping = (
        ramping
        & (profile["rate"] * elapsed < np.abs(goal - initial_speed))
        & (t >= profile["start"])
    )
    feed_forward = np.where(still_ramping, direction * profile["rate"], 0.0)
    lateral = profile["lateral"]
    if not road.is_straight and np.any(np.isfinite(lateral)):
        braking = profile["braking"]
        reach = v * v / (2.0 * braking) + 2.0 * v + 20.0
        ahead = reach[:, None] * _PREVIEW[None, :]
        stations = info["station"][:, None] + ahead
        kappa = np.abs(road.curvature_lookup(stations))
        with np.errstate(divide="ignore"):
            bend_speed2 = np.where(kappa > 0, lateral[:, None] / kappa, np.inf)
        envelope = bend_speed2 + 2.0 * braking[:, None] * ahead
        binding = np.argmin(envelope, axis=1)
        allowed = np.sqrt(envelope[np.arange(v.size), binding])
        slowing = allowed < reference
        reference = np.minimum(reference, allowed)
        # approaching a bend the allowed speed falls at the braking rate: feed it forward
        approaching = slowing & (ahead[np.arange(v.size), binding] > 1.0)
        feed_forward = np.where(slowing, np.where(approaching, -braking, 0.0), feed_forward)
    accel = profile["gain"] * (reference - v) + feed_forward
    if remnant is not None:
        accel = accel + remnant
    return np.clip(accel, -profile["limit"], profile["limit"])


# ---------------------------------------------------------------- batches
def info_arrays(
    info: Mapping[str, Any], keys: Sequence[str] | None = None
) -> dict[str, np.ndarray]:
    """One car's ``info`` (scalars) as 1-element float64 arrays (for a batch of one)."""
    names = keys if keys is not None else [k for k in info if not k.startswith("_")]
    return {k: np.array([info[k]], dtype=np.float64) for k in names}


class LoopBatch:
    """Any drivers, acting one car at a time (the fallback of :func:`make_batch`).

    Each car gets its own deep copy of its driver, so one driver object can
    drive many cars independently.
    """

    def __init__(self, drivers: Sequence[Driver]) -> None:
        self.drivers = [copy.deepcopy(d) for d in drivers]
        self.num_cars = len(self.drivers)

    def reset(
        self, seeds: Sequence[int | None], dt: float, cars: Sequence[int] | np.ndarray | None = None
    ) -> None:
        """Reset every car's driver, or only those of ``cars`` (indices, one seed each)."""
        drivers = self.drivers if cars is None else [self.drivers[int(i)] for i in cars]
        for driver, seed in zip(drivers, seeds, strict=True):
            driver.reset(seed, dt=dt)

    def act(self, info: Mapping[str, np.ndarray], road: Road) -> tuple[np.ndarray, np.ndarray]:
        keys = [k for k in info if not k.startswith("_")]
        steering = np.zeros(self.num_cars)
        acceleration = np.zeros(self.num_cars)
        for i, driver in enumerate(self.drivers):
            one = {k: info[k][i].item() for k in keys}
            steering[i], acceleration[i] = driver.act(one, road)
        return steering, acceleration


class CompositeBatch:
    """Several batches, each driving its own subset of the cars.

    A part whose batch names the ``info`` keys it reads (a tuple ``info_needed``, as
    :class:`~hasa_env.drivers.human.HumanBatch` does) gets only those of its cars' info
    (those ``info`` has); any other part gets every key but the ``"_key"`` masks.
    """

    def __init__(self, parts: Sequence[tuple[np.ndarray, BatchDriver]], num_cars: int) -> None:
        self.parts = [(np.asarray(idx, dtype=np.int64), batch) for idx, batch in parts]
        self.num_cars = num_cars
        self._needed: list[tuple[str, ...] | None] = [
            getattr(batch, "info_needed", None) for _, batch in self.parts
        ]

    def _part_infos(
        self, info: Mapping[str, np.ndarray]
    ) -> list[tuple[np.ndarray, Any, dict[str, np.ndarray]]]:
        """(car indices, batch, its cars' info) of every part."""
        every: list[str] | None = None
        out = []
        for (idx, batch), needed in zip(self.parts, self._needed, strict=True):
            if needed is None:
                if every is None:
                    every = [k for k in info if not k.startswith("_")]
                keys: Sequence[str] = every
            else:
                keys = [k for k in needed if k in info]
            out.append((idx, batch, {k: np.asarray(info[k])[idx] for k in keys}))
        return out

    def reset(
        self, seeds: Sequence[int | None], dt: float, cars: Sequence[int] | np.ndarray | None = None
    ) -> None:
        """Reset every car's driver, or only those of ``cars`` (indices, one seed each;
        the parts must support partial resets, as :class:`~hasa_env.drivers.human.HumanBatch`)."""
        if cars is None:
            for idx, batch in self.parts:
                batch.reset([seeds[i] for i in idx.tolist()], dt)
            return
        rows = np.asarray(cars, dtype=np.int64).reshape(-1)
        if len(seeds) != rows.size:
            raise ValueError(f"got {len(seeds)} seeds for {rows.size} cars")
        seed_of = dict(zip(rows.tolist(), seeds, strict=True))
        for idx, batch in self.parts:
            local = np.flatnonzero(np.isin(idx, rows))
            if local.size:
                partial(batch).reset([seed_of[int(idx[j])] for j in local.tolist()], dt, local)

    def act(self, info: Mapping[str, np.ndarray], road: Road) -> tuple[np.ndarray, np.ndarray]:
        steering = np.zeros(self.num_cars)
        acceleration = np.zeros(self.num_cars)
        for idx, batch, sub in self._part_infos(info):
            s, a = batch.act(sub, road)
            steering[idx] = s
            acceleration[idx] = a
        return steering, acceleration

    def steer(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        """The steering of :meth:`act` alone (parts with a ``steer`` method)."""
        steering = np.zeros(self.num_cars)
        for idx, batch, sub in self._part_infos(info):
            steering[idx] = partial(batch).steer(sub, road)
        return steering


def partial(batch: BatchDriver) -> PartialBatchDriver:
    """``batch`` as a :class:`PartialBatchDriver`, or a TypeError naming what it lacks."""
    if not isinstance(batch, PartialBatchDriver):
        raise TypeError(
            f"{type(batch).__name__} cannot restart single cars or steer alone "
            "(needs reset(seeds, dt, cars=...) and steer(info, road))"
        )
    return batch


def make_batch(drivers: Sequence[Driver]) -> BatchDriver:
    """One :class:`BatchDriver` for N cars, car i driven by ``drivers[i]``.

    Drivers whose class has a ``make_batch(drivers)`` classmethod are
    vectorized together (one batch per class); the rest run car by car in a
    :class:`LoopBatch`.
    """
    drivers = list(drivers)
    if not drivers:
        raise ValueError("make_batch needs at least one driver")
    groups: dict[Any, list[int]] = {}
    for i, driver in enumerate(drivers):
        key = type(driver) if hasattr(type(driver), "make_batch") else None
        groups.setdefault(key, []).append(i)
    parts: list[tuple[np.ndarray, BatchDriver]] = []
    for key, idx in groups.items():
        members = [drivers[i] for i in idx]
        batch = LoopBatch(members) if key is None else key.make_batch(members)
        parts.append((np.array(idx), batch))
    if len(parts) == 1:
        return parts[0][1]
    return CompositeBatch(parts, len(drivers))
