"""Synthetic humans for N cars of a vector env, each car's human chosen per episode.

A :class:`HumanPool` keeps the humans of N cars as vectorized batches of the population
code (:func:`hasa_env.drivers.human.human_batch`), one or more per driver of the
population, so that a car can change its human whenever its episode restarts (the
advisor task draws one per episode) without touching the other cars:

- every batch holds drivers of one kind only (one population member), so restarting a
  car means restarting one slot of a batch of its new driver
  (``HumanBatch.reset(seeds, dt, cars=...)``), never changing a batch's parameters;
- a car's old slot is freed when its new episode starts; free slots are reused, and a
  driver whose batches are full gets a new batch (with spare slots);
- each batch computes all its slots (free ones get a live car's ``info`` and their
  output is dropped); a batch without live cars is skipped.

A restarted car's human drives exactly as the same driver reset alone with the same
seed (``tests/test_rl_humans.py``): batches compute row by row.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from hasa_env.drivers.archetypes import HumanParams, archetype_of
from hasa_env.drivers.base import PartialBatchDriver
from hasa_env.drivers.human import human_batch, info_keys
from hasa_env.sim.road import Road

__all__ = ["HumanPool"]


@dataclass(eq=False)
class _Batch:
    """One vectorized batch of one driver and the car in each of its slots (-1: free)."""

    driver: int
    humans: PartialBatchDriver
    car_at: np.ndarray
    rows: np.ndarray = field(init=False)  # the car whose info each slot gets
    live: np.ndarray = field(init=False)  # slots holding a car

    def __post_init__(self) -> None:
        self.refresh()

    def refresh(self) -> None:
        self.live = self.car_at >= 0
        filler = self.car_at[self.live][0] if self.live.any() else 0
        self.rows = np.where(self.live, self.car_at, filler)


class HumanPool:
    """The synthetic humans of N cars, each car driven (or advised) by one driver at a time.

    Args:
        drivers: the drivers a car's human is chosen from (e.g. a population), any archetype.
        num_cars: N.
        dt: the humans' step (s), e.g. the simulation sample time.
        spare: free slots a new batch gets, as a fraction of the cars it starts with.

    ``assign(cars, drivers, seeds)`` starts new runs; ``steer(info, road)`` (or ``act``
    for the speed command too) returns every car's road-wheel angle (rad) for the
    cars' true ``info`` arrays (the keys of :data:`hasa_env.drivers.human.INFO_NEEDED`, and
    ``bias``: :func:`hasa_env.drivers.human.info_keys`).
    A car without a human yet gets NaN.
    """

    def __init__(
        self, drivers: Sequence[HumanParams], num_cars: int, dt: float, spare: float = 0.25
    ) -> None:
        self.drivers = list(drivers)
        if not self.drivers:
            raise ValueError("HumanPool needs at least one driver")
        for params in self.drivers:
            archetype_of(params)  # TypeError for anything but synthetic drivers' parameters
        if isinstance(num_cars, bool) or not isinstance(num_cars, int) or num_cars < 1:
            raise ValueError(f"num_cars must be a positive integer, got {num_cars!r}")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        if not (math.isfinite(spare) and spare >= 0):
            raise ValueError(f"spare must be a finite number >= 0, got {spare!r}")
        self.num_cars = num_cars
        self.dt = float(dt)
        self.spare = float(spare)
        self._batches: list[_Batch] = []
        self._batch_of = np.full(num_cars, -1, dtype=np.int64)
        self._slot_of = np.full(num_cars, -1, dtype=np.int64)
        self.driver_of = np.full(num_cars, -1, dtype=np.int64)
        """Index (into ``drivers``) of each car's current human; -1 before its first."""

    @property
    def num_batches(self) -> int:
        """Batches in the pool (one or more per driver that has driven)."""
        return len(self._batches)

    def assign(
        self,
        cars: Sequence[int] | np.ndarray,
        drivers: Sequence[int] | np.ndarray,
        seeds: Sequence[int],
    ) -> None:
        """Car ``cars[j]`` starts a new run with driver ``drivers[j]`` seeded ``seeds[j]``."""
        car_rows = np.asarray(cars, dtype=np.int64).reshape(-1)
        driver_rows = np.asarray(drivers, dtype=np.int64).reshape(-1)
        if not (car_rows.size == driver_rows.size == len(seeds)):
            raise ValueError(
                f"assign needs one driver and one seed per car, got {car_rows.size} cars, "
                f"{driver_rows.size} drivers and {len(seeds)} seeds"
            )
        if car_rows.size and (car_rows.min() < 0 or car_rows.max() >= self.num_cars):
            raise IndexError(f"cars must index the {self.num_cars} cars")
        if driver_rows.size and (driver_rows.min() < 0 or driver_rows.max() >= len(self.drivers)):
            raise IndexError(f"drivers must index the {len(self.drivers)} drivers")
        if np.unique(car_rows).size != car_rows.size:
            raise ValueError("assign got a car twice")
        touched: dict[int, list[tuple[int, int]]] = {}  # batch -> [(slot, seed)]
        for car in car_rows.tolist():  # free the old slots first, so they can be reused
            b = int(self._batch_of[car])
            if b >= 0:
                self._batches[b].car_at[self._slot_of[car]] = -1
                touched.setdefault(b, [])
        for driver in np.unique(driver_rows).tolist():
            mine = np.flatnonzero(driver_rows == driver)
            slots = self._free_slots(driver, mine.size)
            for j, (b, slot) in zip(mine.tolist(), slots, strict=True):
                car = int(car_rows[j])
                self._batches[b].car_at[slot] = car
                self._batch_of[car], self._slot_of[car] = b, slot
                self.driver_of[car] = driver
                touched.setdefault(b, []).append((slot, int(seeds[j])))
        for b, restarts in touched.items():
            batch = self._batches[b]
            if restarts:
                restart_slots = [s for s, _ in restarts]
                batch.humans.reset([seed for _, seed in restarts], self.dt, cars=restart_slots)
            batch.refresh()

    def _free_slots(self, driver: int, count: int) -> list[tuple[int, int]]:
        """``count`` free (batch, slot) pairs of ``driver``, making a new batch if needed."""
        found: list[tuple[int, int]] = []
        for b, batch in enumerate(self._batches):
            if batch.driver != driver:
                continue
            for slot in np.flatnonzero(batch.car_at < 0).tolist():
                if len(found) == count:
                    return found
                found.append((b, slot))
        missing = count - len(found)
        if missing > 0:
            size = missing + max(
                1, math.ceil(self.spare * max(missing, self.num_cars / len(self.drivers)))
            )
            humans = human_batch([self.drivers[driver]] * size)
            humans.reset([0] * size, self.dt)  # every slot starts; assign restarts its own
            self._batches.append(_Batch(driver, humans, np.full(size, -1, dtype=np.int64)))
            b = len(self._batches) - 1
            found += [(b, slot) for slot in range(missing)]
        return found

    def steer(self, info: Mapping[str, np.ndarray], road: Road) -> np.ndarray:
        """Every car's steering (rad, road wheel) for its true ``info`` now."""
        return self._run(info, road, with_speed=False)[0]

    def act(self, info: Mapping[str, np.ndarray], road: Road) -> tuple[np.ndarray, np.ndarray]:
        """Every car's (steering rad, acceleration m/s^2) for its true ``info`` now."""
        return self._run(info, road, with_speed=True)

    def _run(
        self, info: Mapping[str, np.ndarray], road: Road, with_speed: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        steering = np.full(self.num_cars, np.nan)
        acceleration = np.full(self.num_cars, np.nan)
        arrays = {key: np.asarray(info[key], dtype=np.float64) for key in info_keys(info)}
        for batch in self._batches:
            if not batch.live.any():
                continue
            sub = {key: value[batch.rows] for key, value in arrays.items()}
            cars = batch.car_at[batch.live]
            if with_speed:
                s, a = batch.humans.act(sub, road)
                acceleration[cars] = a[batch.live]
            else:
                s = batch.humans.steer(sub, road)
            steering[cars] = s[batch.live]
        return steering, acceleration
