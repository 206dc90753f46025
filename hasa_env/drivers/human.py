"""What every synthetic human shares: perception, delay, seeding, output stage, speed.

A synthetic driver of any archetype (two-point PI, preview optimal control,
intermittent control) is a frozen parameter dataclass plus a vectorized
batch. The batch (:class:`HumanBatch`) gives each archetype:

- seeding: car i's randomness comes from ``SeedSequence(seed_i)`` alone
  (child 0: the output stage's remnant; child 1: the archetype's own noise),
  drawn in blocks, so a driver's run is identical alone or in any batch;
- perception with a sensorimotor delay (:class:`DelayLine`): the control
  law sees the true state of ``delay`` s ago;
- the output stage (:class:`~hasa_env.drivers.motor.MotorStage`): lag,
  remnant, wheel quantization;
- the speed behaviour (:class:`~hasa_env.drivers.base.SpeedProfile`).

:class:`HumanDriver` is the single-car :class:`~hasa_env.drivers.base.Driver`
around a batch of one.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import fields
from typing import Any, ClassVar, Protocol, cast

import numpy as np

from hasa_env.drivers.base import (
    BatchDriver,
    CompositeBatch,
    PartialBatchDriver,
    SpeedProfile,
    info_arrays,
    speed_command,
    speed_profile_arrays,
)
from hasa_env.drivers.motor import MotorParams, MotorStage, NoiseBlocks, ou_coefficients
from hasa_env.sim.road import Road, lane_centre_bearing

__all__ = [
    "DelayLine",
    "HumanBatch",
    "HumanDriver",
    "car_streams",
    "check_common",
    "check_range",
    "HumanComposite",
    "human_batch",
    "info_keys",
    "lane_bearings",
    "params_from_dict",
    "params_to_dict",
    "sum_from",
]

MIN_SPEED = 1.0
"""m/s; below it speed-scaled gains and look-ahead distances stop scaling."""

INFO_NEEDED = ("time", "station", "lateral_offset", "heading", "speed", "steering")
"""The ``info`` keys a synthetic driver reads; it also reads ``bias`` (the episode's true
camera bias, m) where given: a road whose lane shift moves toward the other hypothesis
needs it (:meth:`hasa_env.sim.road.Road.driven_offset`)."""


def info_keys(info: Mapping[str, Any]) -> tuple[str, ...]:
    """The keys of ``info`` a synthetic driver reads: :data:`INFO_NEEDED`, and ``bias``
    where ``info`` has it."""
    return (*INFO_NEEDED, "bias") if "bias" in info else INFO_NEEDED


MOTOR_STREAM, OWN_STREAM, PEDAL_STREAM = 0, 1, 2
"""Spawn keys of a car's SeedSequence: the output stage's and the archetype's noise."""


def check_range(
    owner: str, name: str, value: Any, low: float, high: float, *, open_low: bool = False
) -> None:
    """Raise ValueError "<owner>.<name> must be in [low, high], got value" unless it is."""
    ok = isinstance(value, int | float | np.floating | np.integer) and not isinstance(value, bool)
    ok = ok and math.isfinite(value) and (value > low if open_low else value >= low)
    if not (ok and value <= high):
        bracket = "(" if open_low else "["
        raise ValueError(f"{owner}.{name} must be in {bracket}{low:g}, {high:g}], got {value!r}")


def lane_bearings(
    info: Mapping[str, np.ndarray],
    road: Road,
    near: np.ndarray,
    far: np.ndarray,
    preferred_offset: np.ndarray | float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Bearings (rad) of the driven lane's centre at ``near`` and ``far`` m ahead of N cars.

    The point d m ahead lies ``l(d) = offset(s + d) + preferred_offset`` left of the road's
    centre line (``road.lane_shifts``, :meth:`~hasa_env.sim.road.Road.driven_offset` for
    each car's episode bias ``info["bias"]``; 0 without them). Straight road: phi = -(theta + atan((y - l(near)) / near)), omega =
    -(theta + atan((y - l(far)) / far)); curved road:
    :func:`hasa_env.sim.road.lane_centre_bearing` (exact).
    """
    y, theta = info["lateral_offset"], info["heading"]
    s = info["station"]
    near_offset: Any = preferred_offset
    far_offset: Any = preferred_offset
    if road.lane_shifts:
        bias = info.get("bias")
        near_offset = near_offset + road.driven_offset(s + near, bias)
        far_offset = far_offset + road.driven_offset(s + far, bias)
    if road.is_straight:
        return (
            -(theta + np.arctan((y - near_offset) / near)),
            -(theta + np.arctan((y - far_offset) / far)),
        )
    return (
        np.asarray(lane_centre_bearing(road, s, y, theta, near, near_offset), dtype=np.float64),
        np.asarray(lane_centre_bearing(road, s, y, theta, far, far_offset), dtype=np.float64),
    )


def sum_from(first: np.ndarray, terms: np.ndarray) -> np.ndarray:
    """``first + terms[:, 0] + terms[:, 1] + ...`` of N cars ((N,) and (N, m) arrays), added
    left to right as a loop over the columns adds them (``np.add.accumulate`` is sequential:
    the same additions in the same order, the same bits), in one call."""
    table = np.empty((terms.shape[0], terms.shape[1] + 1))
    table[:, 0] = first
    table[:, 1:] = terms
    return np.add.accumulate(table, axis=1)[:, -1]


class DelayLine:
    """A pure delay of ``steps[i]`` env steps on car i's vector of ``width`` signals.

    A car's first call fills its line with its input (the driver has seen the
    initial state for ever); each call returns the input of ``steps`` calls ago.
    :meth:`restart` makes some cars' next call a first call again.
    """

    def __init__(self, steps: np.ndarray, width: int) -> None:
        self.steps = np.asarray(steps, dtype=np.int64)
        self.width = int(width)
        self._ring = int(self.steps.max()) + 1
        self._buffer = np.zeros((self._ring, self.steps.size, self.width))
        self._rows = np.arange(self.steps.size)
        self._pos = 0
        self._fresh = np.ones(self.steps.size, dtype=bool)

    def restart(self, cars: np.ndarray) -> None:
        """The next call is the first one for cars ``cars`` (indices)."""
        self._fresh[cars] = True

    def __call__(self, values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=np.float64)
        if self._fresh.any():
            fresh = self._fresh
            self._buffer[:, fresh] = values[None, fresh]
            self._fresh = np.zeros(self.steps.size, dtype=bool)
        self._buffer[self._pos] = values
        seen = self._buffer[(self._pos - self.steps) % self._ring, self._rows]
        self._pos = (self._pos + 1) % self._ring
        return seen


def car_streams(seed: int | None, key: int) -> np.random.Generator:
    """Car's generator number ``key`` (a child of ``SeedSequence(seed)``)."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(key,)))


class _DriverStages:
    """The output stage and the speed stage of N cars, shared by an archetype's batch
    (:class:`HumanBatch`) and by several archetypes' cars driven together
    (:class:`HumanComposite`): the :class:`~hasa_env.drivers.motor.MotorStage` and each car's
    pedal remnant (an OU process of std ``speed.pedal_noise``, its own noise stream) added to
    :func:`speed_command`. The owner sets ``num_cars``, ``profile`` and ``motor``."""

    num_cars: int
    profile: dict[str, np.ndarray]
    motor: MotorStage
    _initial_speed: np.ndarray  # each car's speed at its first step (m/s)
    # the pedal remnant (m/s^2) of each car, its AR(1) coefficient, innovation std and draws
    _pedal: np.ndarray
    _pedal_rho: np.ndarray
    _pedal_innovation: np.ndarray
    _pedal_draws: NoiseBlocks

    def _start_stages(self, seeds: Sequence[int | None], dt: float) -> None:
        """Every car's stages at a full reset (``seeds``: one per car; ``dt`` in s)."""
        self.motor.reset([car_streams(s, MOTOR_STREAM) for s in seeds], dt)
        self._pedal_rho, self._pedal_innovation = ou_coefficients(
            self.profile["pedal_noise"], self.profile["pedal_time_constant"], dt
        )
        self._pedal_draws = NoiseBlocks([car_streams(s, PEDAL_STREAM) for s in seeds], 1)
        self._pedal = np.zeros(self.num_cars)

    def _restart_stages(self, seeds: Sequence[int | None], dt: float, rows: np.ndarray) -> None:
        """The stages of the cars ``rows`` restarted (a partial reset)."""
        self.motor.reset([car_streams(s, MOTOR_STREAM) for s in seeds], dt, rows)
        self._pedal_draws.restart(rows, [car_streams(s, PEDAL_STREAM) for s in seeds])
        self._pedal[rows] = 0.0

    def acceleration(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        """The speed command of ``act`` (m/s^2), its pedal remnant drawn (call it once a
        step, after ``steer``)."""
        remnant = None
        if self._pedal_innovation.any():
            draws = self._pedal_draws.next()[:, 0]
            self._pedal = self._pedal_rho * self._pedal + self._pedal_innovation * draws
            remnant = self._pedal
        return speed_command(self.profile, self._initial_speed, info, road, remnant)


class HumanBatch(_DriverStages, ABC):
    """Base of the archetypes' batches: N drivers of one archetype acting on N cars' arrays.

    Subclasses set ``params_type`` and implement :meth:`_reset` (per-run set-up),
    :meth:`_start` (state at the first step, from the true ``info``) and
    :meth:`_command` (the command u(k), rad, of the control law). The output
    stage turns it into the applied steering; :func:`speed_command` gives the
    acceleration, with each driver's pedal remnant (an OU process of std
    ``speed.pedal_noise``, its own noise stream) added.

    ``reset(seeds, dt, cars=...)`` restarts only some cars (a vector env's
    autoreset): each restarted car then drives exactly as a driver reset
    alone with its seed, while the others go on.
    """

    params_type: ClassVar[type]
    info_needed: ClassVar[tuple[str, ...]] = (*INFO_NEEDED, "bias")
    """The ``info`` keys the batch reads (a :class:`~hasa_env.drivers.base.CompositeBatch`
    hands it only these)."""
    sees_ahead: ClassVar[bool] = False
    """True: the control law looks at the driven lane ahead itself (:func:`lane_bearings`);
    False: it steers on :meth:`perceived` offsets."""
    _fresh: np.ndarray  # cars whose next step is their first, set by reset()
    registry: ClassVar[dict[type, type[HumanBatch]]] = {}
    """params_type -> batch class, filled as the archetypes' batch classes are defined."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        HumanBatch.registry[cls.params_type] = cls

    def __init__(self, params: Sequence[Any]) -> None:
        self.params = list(params)
        name = type(self).__name__
        if not self.params:
            raise ValueError(f"{name} needs at least one {self.params_type.__name__}")
        wrong = [type(p).__name__ for p in self.params if not isinstance(p, self.params_type)]
        if wrong:
            raise TypeError(f"{name} needs {self.params_type.__name__}, got {wrong[0]}")
        self.num_cars = len(self.params)
        self.max_steering = self.arr("max_steering")
        self.preferred_offset = self.arr("preferred_offset")
        self._keeps_offset = bool(self.preferred_offset.any())
        self.profile = speed_profile_arrays([p.speed for p in self.params])
        self.motor = MotorStage(
            self.arr("neuromuscular_frequency"),
            self.arr("neuromuscular_damping"),
            [p.motor for p in self.params],
            self.max_steering,
        )
        self._dt: float | None = None

    def arr(self, key: str) -> np.ndarray:
        """The field ``key`` of every driver, as a float64 array."""
        return np.array([getattr(p, key) for p in self.params], dtype=np.float64)

    def reset(
        self, seeds: Sequence[int | None], dt: float, cars: Sequence[int] | np.ndarray | None = None
    ) -> None:
        """Start every car's run (``seeds``: one per car), or only those of ``cars``.

        Args:
            seeds: one seed per car (per entry of ``cars`` when given).
            dt: the env step (s); a partial reset keeps the batch's.
            cars: indices of the cars to restart (None: all); the others go on.
        """
        if cars is not None:
            rows = np.asarray(cars, dtype=np.int64).reshape(-1)
            if len(seeds) != rows.size:
                raise ValueError(f"got {len(seeds)} seeds for {rows.size} cars")
            if self._dt is None:
                raise RuntimeError("reset the whole batch (cars=None) before restarting cars")
            if rows.size and (rows.min() < 0 or rows.max() >= self.num_cars):
                raise IndexError(f"cars must index the batch of {self.num_cars} drivers")
            if float(dt) != self._dt:
                raise ValueError(f"a partial reset keeps the batch's dt = {self._dt} s, got {dt}")
            self._restart_stages(seeds, self._dt, rows)
            self._reset(seeds, self._dt, rows)
            self._fresh[rows] = True
            return
        if len(seeds) != self.num_cars:
            raise ValueError(f"got {len(seeds)} seeds for {self.num_cars} drivers")
        if not dt > 0:
            raise ValueError(f"dt must be > 0 s, got {dt}")
        self._dt = float(dt)
        self._start_stages(seeds, self._dt)
        self.delay_steps = np.array([round(p.delay / dt) for p in self.params], dtype=np.int64)
        self._reset(seeds, self._dt, None)
        self._all_fresh = True
        self._fresh = np.ones(self.num_cars, dtype=bool)

    def act(self, info: Mapping[str, np.ndarray], road: Road) -> tuple[np.ndarray, np.ndarray]:
        steering = self.steer(info, road)
        return steering, self.acceleration(info, road)

    def steer(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        """The steering of :meth:`act` alone (rad, road wheel), without the speed command.

        For callers that use only the steering (a human advising while the car
        drives): the same steering, and the next calls stay the same.
        """
        return self.motor.step(self.command(info, road), info["speed"])

    def command(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        """The command u(k) (rad) the output stage gets: :meth:`steer` before its
        ``motor.step`` (a car's first step also starts the output stage)."""
        if self._dt is None:
            raise RuntimeError("call reset() before act()")
        if not self.sees_ahead and (self._keeps_offset or road.lane_shifts):
            info = self.perceived(info, road)
        if self._all_fresh:
            start = np.asarray(info["steering"], dtype=np.float64)
            self.motor.start(start)
            self._initial_speed = np.asarray(info["speed"], dtype=np.float64).copy()
            self._start(info, road, start, None)
            self._all_fresh = False
            self._fresh = np.zeros(self.num_cars, dtype=bool)
        elif self._fresh.any():
            rows = np.flatnonzero(self._fresh)
            start = np.asarray(info["steering"], dtype=np.float64)
            self.motor.start(start, rows)
            self._initial_speed[rows] = np.asarray(info["speed"], dtype=np.float64)[rows]
            self._start(info, road, start, rows)
            self._fresh = np.zeros(self.num_cars, dtype=bool)
        return self._command(info, road)

    def perceived(self, info: Mapping[str, np.ndarray], road: Road) -> Mapping[str, np.ndarray]:
        """The true ``info`` as the drivers steer on it: offset and heading from the lane
        they want to drive along (docs/design.md §14).

        The target is the driven lane's centre (:meth:`~hasa_env.sim.road.Road.driven_offset`,
        ``road.lane_shifts``) plus each driver's ``preferred_offset``::

            y_seen     = y - offset(s) - preferred_offset
            theta_seen = theta - slope(s)

        (small angles: the driven lane's heading relative to the road is its slope). Every
        archetype's control law then steers to y_seen = 0; its look-ahead extrapolates the
        driven lane straight from the car's station (the far point sees a shift's slope,
        not its end). Archetypes that look ahead themselves (``sees_ahead``) skip it.
        """
        station = np.asarray(info["station"], dtype=np.float64)
        target = self.preferred_offset
        out = dict(info)
        if road.lane_shifts:
            bias = info.get("bias")  # the episode's; a shift may move toward its other hypothesis
            target = target + road.driven_offset(station, bias)
            out["heading"] = np.asarray(info["heading"], dtype=np.float64) - road.driven_slope(
                station, bias
            )
        out["lateral_offset"] = np.asarray(info["lateral_offset"], dtype=np.float64) - target
        return out

    # ------------------------------------------------------------ archetype hooks
    @abstractmethod
    def _reset(self, seeds: Sequence[int | None], dt: float, cars: np.ndarray | None) -> None:
        """Per-run set-up of every car (``cars`` None; ``self.delay_steps`` is known) or of
        the cars ``cars`` (indices, one seed each); the output stage is reset."""

    @abstractmethod
    def _start(
        self,
        info: Mapping[str, np.ndarray],
        road: Road,
        steering: np.ndarray,
        cars: np.ndarray | None,
    ) -> None:
        """The control law's state at the first step, from the true ``info`` and steering
        (rad) of every car: all cars (``cars`` None) or only ``cars`` (indices)."""

    @abstractmethod
    def _command(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        """The command u(k) (rad, road wheel) of each car at this step."""


class NamedParams(Protocol):
    """What every driver's parameters have: the name of the driver they make."""

    @property
    def name(self) -> str: ...


class HumanDriver:
    """A synthetic human of one archetype as a :class:`~hasa_env.drivers.base.Driver`.

    ``Driver(params).reset(seed, dt=0.01)`` then ``act(info, road)`` each env
    step. Runs are identical whether the driver acts alone or vectorized with
    others (:meth:`make_batch`). Subclasses set ``accepts`` (the parameter
    types they drive).
    """

    accepts: ClassVar[tuple[type[NamedParams], ...]]

    def __init__(self, params: Any) -> None:
        if not isinstance(params, self.accepts):
            allowed = " or ".join(t.__name__ for t in self.accepts)
            raise TypeError(f"{type(self).__name__} needs {allowed}, got {type(params).__name__}")
        self.params = params
        self.name = params.name
        self._batch: BatchDriver | None = None

    @classmethod
    def make_batch(cls, drivers: Sequence[HumanDriver]) -> BatchDriver:
        """A vectorized batch of these drivers (one car each), one part per archetype."""
        return human_batch([d.params for d in drivers])

    def reset(self, seed: int | None = None, *, dt: float = 0.01) -> None:
        self._batch = self.make_batch([self])
        self._batch.reset([seed], dt)

    def act(self, info: Mapping[str, Any], road: Road) -> tuple[float, float]:
        if self._batch is None:
            raise RuntimeError("call reset() before act()")
        steering, acceleration = self._batch.act(info_arrays(info, info_keys(info)), road)
        return float(steering[0]), float(acceleration[0])

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.params!r})"


def human_batch(params: Sequence[Any]) -> PartialBatchDriver:
    """One vectorized batch for N cars, car i driven by ``params[i]`` (archetypes may mix).

    Each archetype's cars form one batch of its class (:attr:`HumanBatch.registry`);
    several archetypes make a :class:`~hasa_env.drivers.base.CompositeBatch`.
    """
    params = list(params)
    if not params:
        raise ValueError("human_batch needs at least one driver's parameters")
    groups: dict[type, list[int]] = {}
    for i, p in enumerate(params):
        if type(p) not in HumanBatch.registry:
            allowed = ", ".join(t.__name__ for t in HumanBatch.registry)
            raise TypeError(
                f"not synthetic driver parameters: {type(p).__name__} (allowed: {allowed})"
            )
        groups.setdefault(type(p), []).append(i)
    parts: list[tuple[np.ndarray, HumanBatch]] = [
        (np.array(idx), HumanBatch.registry[kind]([params[i] for i in idx]))
        for kind, idx in groups.items()
    ]
    if len(parts) == 1:
        return parts[0][1]
    return HumanComposite(parts, len(params))


class HumanComposite(CompositeBatch, _DriverStages):
    """Several archetypes' batches (:func:`human_batch`) with one output stage and one speed
    stage for all their cars.

    Each part computes its cars' commands (:meth:`HumanBatch.command`); one
    :class:`~hasa_env.drivers.motor.MotorStage` turns all of them into steering and one
    :func:`~hasa_env.drivers.base.speed_command` (with every car's pedal remnant) gives the
    accelerations: one call each per step instead of one per archetype. Every car keeps its
    own noise streams and every operation of the stages is per car, so each car gets the
    bits it gets in its archetype's batch. The stages stack only when the parts draw the
    same noise channels (all or none with command noise, all or none with a pedal
    remnant: the channels a car draws depend on its batch's); otherwise (decided at every
    full reset) each part drives alone, as a plain :class:`CompositeBatch`.
    """

    # the shared stages' state, set at each full reset while the stages are stacked
    _dt: float
    _all_fresh: bool
    _fresh: np.ndarray

    def __init__(self, parts: Sequence[tuple[np.ndarray, HumanBatch]], num_cars: int) -> None:
        super().__init__(parts, num_cars)
        self.humans: list[tuple[np.ndarray, HumanBatch]] = [
            (i, cast(HumanBatch, b)) for i, b in self.parts
        ]
        params: list[Any] = [None] * num_cars  # every car's parameters, in car order
        for idx, batch in self.humans:
            for i, p in zip(idx.tolist(), batch.params, strict=True):
                params[i] = p

        def arr(key: str) -> np.ndarray:
            return np.array([getattr(p, key) for p in params], dtype=np.float64)

        self.profile = speed_profile_arrays([p.speed for p in params])
        self.motor = MotorStage(
            arr("neuromuscular_frequency"),
            arr("neuromuscular_damping"),
            [p.motor for p in params],
            arr("max_steering"),
        )
        self.stacked = False

    def reset(
        self, seeds: Sequence[int | None], dt: float, cars: Sequence[int] | np.ndarray | None = None
    ) -> None:
        """As :meth:`CompositeBatch.reset`; the shared stages restart the same cars."""
        super().reset(seeds, dt, cars)
        if cars is not None:
            if self.stacked:
                rows = np.asarray(cars, dtype=np.int64).reshape(-1)
                self._restart_stages(seeds, self._dt, rows)
                self._fresh[rows] = True
            return
        batches = [b for _, b in self.humans]
        self.stacked = (
            len({b.motor.commanded for b in batches}) == 1
            and len({bool(b._pedal_innovation.any()) for b in batches}) == 1
        )
        if not self.stacked:
            return
        self._dt = float(dt)
        self._start_stages(seeds, self._dt)
        self._initial_speed = np.zeros(self.num_cars)
        self._all_fresh = True
        self._fresh = np.ones(self.num_cars, dtype=bool)

    def act(self, info: Mapping[str, np.ndarray], road: Road) -> tuple[np.ndarray, np.ndarray]:
        if not self.stacked:
            return super().act(info, road)
        steering = self.steer(info, road)
        return steering, self.acceleration(info, road)

    def steer(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        if not self.stacked:
            return super().steer(info, road)
        if self._all_fresh or self._fresh.any():
            start = np.asarray(info["steering"], dtype=np.float64)
            rows = None if self._all_fresh else np.flatnonzero(self._fresh)
            self.motor.start(start, rows)
            speed = np.asarray(info["speed"], dtype=np.float64)
            if rows is None:
                self._initial_speed = speed.copy()
            else:
                self._initial_speed[rows] = speed[rows]
            self._all_fresh = False
            self._fresh = np.zeros(self.num_cars, dtype=bool)
        commands = np.empty(self.num_cars)
        for idx, batch, sub in self._part_infos(info):
            commands[idx] = batch.command(sub, road)
        return self.motor.step(commands, info["speed"])


def check_common(owner: str, params: Any) -> None:
    """Checks of the fields every archetype's parameters share (see :class:`HumanBatch`)."""
    check_range(owner, "delay", params.delay, 0.0, 1.0)
    check_range(owner, "neuromuscular_frequency", params.neuromuscular_frequency, 0.0, 200.0, open_low=True)  # fmt: skip
    check_range(owner, "neuromuscular_damping", params.neuromuscular_damping, 0.0, 5.0, open_low=True)  # fmt: skip
    check_range(owner, "max_steering", params.max_steering, 0.0, 1.5, open_low=True)
    check_range(owner, "preferred_offset", params.preferred_offset, -2.0, 2.0)
    for name, kind in (("speed", SpeedProfile), ("motor", MotorParams)):
        value = getattr(params, name)
        if not isinstance(value, kind):
            raise TypeError(f"{owner}.{name} must be a {kind.__name__}, got {type(value).__name__}")


def params_to_dict(params: Any, archetype: str) -> dict[str, Any]:
    """A JSON-able dict of an archetype's parameter dataclass, tagged ``"archetype"``."""
    out: dict[str, Any] = {"archetype": archetype}
    for f in fields(params):
        value = getattr(params, f.name)
        out[f.name] = value.to_dict() if hasattr(value, "to_dict") else value
    return out


def params_from_dict(
    cls: type, data: Mapping[str, Any], archetype: str, **nested: Callable[[Any], Any]
) -> Any:
    """Inverse of :func:`params_to_dict` for ``cls`` (a missing "archetype" or "motor" is allowed).

    ``nested`` maps further fields to the functions that rebuild them from their dicts.
    """
    values = dict(data)
    tag = values.pop("archetype", archetype)
    if tag != archetype:
        raise ValueError(f"{cls.__name__}.from_dict: archetype {tag!r} is not {archetype!r}")
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"{cls.__name__}.from_dict: unknown fields {unknown}")
    if "speed" in values:
        values["speed"] = SpeedProfile(**values["speed"])
    if "motor" in values:
        values["motor"] = MotorParams.from_dict(values["motor"])
    for key, build in nested.items():
        if key in values:
            values[key] = build(values[key])
    return cls(**values)
