"""Running drivers in the env and collecting recordings (one DataFrame per run).

- :func:`run_driver`: N runs of one driver (vectorized over the native vector
  env when the env is given by id and N > 1, else one single env run after
  another);
- :func:`run_drivers`: one run per (driver, seed) pair, all cars at once in
  one vector env;
- :func:`run_population`: runs of every driver of a population (what the
  benchmark uses: 9 drivers x 10 runs x 30 s in a second or two).

Every run gets an env seed and a driver seed derived deterministically from
``seed``, the driver's name and the track (:func:`run_seeds`), so a run is
the same whichever function produced it and however many other cars drove
with it. Frames have the columns :data:`hasa_env.sim.setup.RECORDING_COLUMNS`
(row 0 = reset state) and ``attrs`` with the env id, the full validated
config, the track, the seeds, the reset options and the driver's name;
:func:`save_runs` writes them in the recording format
(:func:`hasa_env.recording.save_recording`), replayable from their sidecars.
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd

from hasa_env.drivers.archetypes import HumanParams, make_driver
from hasa_env.drivers.base import Driver, make_batch
from hasa_env.envs.base import hasa_unwrapped
from hasa_env.recording.writer import save_recording
from hasa_env.sim.config import deep_merge
from hasa_env.sim.setup import INFO_KEYS, RECORDING_COLUMNS, EnvSetup, recording_row

__all__ = [
    "DEFAULT_ENV_ID",
    "recording_meta",
    "run_driver",
    "run_drivers",
    "run_population",
    "run_seeds",
    "save_runs",
]

DEFAULT_ENV_ID = "hasa_env/LaneKeeping-v0"
_INT_COLUMNS = ("step", "bias_index")
_BOOL_COLUMNS = ("terminated", "truncated")


def run_seeds(seed: int, runs: int, key: str = "") -> list[tuple[int, int]]:
    """(env seed, driver seed) of runs 0..runs-1, derived from ``seed`` and a ``key``.

    The key is usually "<driver name>/<track>", so different drivers and
    tracks get independent runs from the same seed.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    tag = zlib.crc32(key.encode("utf-8"))
    out = []
    for r in range(runs):
        state = np.random.SeedSequence([int(seed), tag, r]).generate_state(2, dtype=np.uint32)
        out.append((int(state[0]), int(state[1])))
    return out


def _physical_config(config: Mapping[str, Any] | None) -> dict[str, Any]:
    return deep_merge(dict(config or {}), {"action": {"type": "physical"}})


def _track_of(env_id: str, config: Mapping[str, Any]) -> str:
    if "track" in config:
        return str(config["track"])
    spec = gym.spec(env_id)
    return str(spec.kwargs.get("track", "straight"))


def _key(driver: Any, track: str) -> str:
    return f"{getattr(driver, 'name', '')}/{track}"


def _frame(rows: np.ndarray | list, attrs: Mapping[str, Any]) -> pd.DataFrame:
    frame = pd.DataFrame(rows, columns=list(RECORDING_COLUMNS))
    for column in _INT_COLUMNS:
        frame[column] = frame[column].astype(np.int64)
    for column in _BOOL_COLUMNS:
        frame[column] = frame[column].astype(bool)
    frame.attrs.update(attrs)  # (a new frame's attrs are empty)
    return frame


def _env_dt(setup: EnvSetup) -> float:
    return setup.dt * setup.action_repeat


def run_driver(
    driver: Driver,
    env_id_or_env: str | gym.Env = DEFAULT_ENV_ID,
    runs: int = 1,
    seed: int = 0,
    config: Mapping[str, Any] | None = None,
    options: Mapping[str, Any] | None = None,
    *,
    vectorized: bool | None = None,
) -> list[pd.DataFrame]:
    """Drive ``runs`` episodes with ``driver`` and return their recordings.

    Args:
        driver: any :class:`~hasa_env.drivers.base.Driver`.
        env_id_or_env: an env id (the env is made with ``config`` and
            ``action.type = "physical"``) or an env instance (used as it is;
            physical actions are mapped if it expects normalized ones).
        runs: number of episodes.
        seed: base seed; run r uses the seeds ``run_seeds(seed, runs, key)[r]``
            with key "<driver name>/<track>".
        config: env configuration (deep-merged onto the defaults).
        options: ``reset`` options for every run (e.g. ``{"bias_index": 0}``).
        vectorized: run all episodes at once in the native vector env
            (default: when the env is given by id and runs > 1). Same results
            as one after another, up to floating-point rounding.

    Returns:
        One DataFrame per run (:data:`hasa_env.sim.setup.RECORDING_COLUMNS`).
    """
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ValueError(f"runs must be a positive integer, got {runs!r}")
    if isinstance(env_id_or_env, str):
        cfg = _physical_config(config)
        track = _track_of(env_id_or_env, cfg)
        seeds = run_seeds(seed, runs, _key(driver, track))
        if vectorized is None:
            vectorized = runs > 1
        if vectorized:
            return run_drivers([driver] * runs, seeds, env_id_or_env, config, options)
        env = gym.make(env_id_or_env, config=cfg)
        try:
            return [_run_single(driver, env, s, options, env_id_or_env) for s in seeds]
        finally:
            env.close()
    if config is not None:
        raise ValueError(
            "config applies only when the env is given by id; configure the env instance yourself"
        )
    env = env_id_or_env
    track = str(hasa_unwrapped(env).config["track"])
    seeds = run_seeds(seed, runs, _key(driver, track))
    env_id = env.spec.id if env.spec is not None else ""
    return [_run_single(driver, env, s, options, env_id) for s in seeds]


def _run_single(
    driver: Driver,
    env: gym.Env,
    seeds: tuple[int, int],
    options: Mapping[str, Any] | None,
    env_id: str,
) -> pd.DataFrame:
    base = hasa_unwrapped(env)
    setup = base.setup
    road = setup.road
    env_seed, driver_seed = seeds
    normalized = setup.normalized_actions
    limit = setup.steering_limit
    low, high = setup.acceleration_limits
    _, info = env.reset(seed=env_seed, options=dict(options) if options else None)
    driver.reset(driver_seed, dt=_env_dt(setup))
    rows = [recording_row(0, info, 0.0, False, False)]
    step = 0
    while True:
        steering, acceleration = driver.act(info, road)
        if not (np.isfinite(steering) and np.isfinite(acceleration)):
            raise RuntimeError(
                f"driver {getattr(driver, 'name', driver)!r} returned a non-finite action "
                f"({steering}, {acceleration}) at step {step}"
            )
        if normalized:
            action = np.array([steering / limit, 2.0 * (acceleration - low) / (high - low) - 1.0])
        else:
            action = np.array([steering, acceleration], dtype=np.float64)
        _, reward, terminated, truncated, info = env.step(action)
        step += 1
        rows.append(recording_row(step, info, reward, terminated, truncated))
        if terminated or truncated:
            break
    attrs = {
        "env_id": env_id,
        "config": base.config,
        "track": base.config["track"],
        "seed": env_seed,
        "driver": getattr(driver, "name", type(driver).__name__),
        "driver_seed": driver_seed,
        "reset_options": dict(options or {}),
    }
    return _frame(rows, attrs)


def run_drivers(
    drivers: Sequence[Driver],
    seeds: Sequence[tuple[int, int]],
    env_id: str = DEFAULT_ENV_ID,
    config: Mapping[str, Any] | None = None,
    options: Mapping[str, Any] | None = None,
) -> list[pd.DataFrame]:
    """One run per driver, all at once in the native vector env.

    Args:
        drivers: car i is driven by ``drivers[i]`` (the same object may appear
            several times: each car gets its own state).
        seeds: (env seed, driver seed) of each car (see :func:`run_seeds`).
        env_id: registered env id (made with ``vectorization_mode="vector_entry_point"``).
        config: env configuration; ``action.type`` is set to "physical".
        options: ``reset`` options for every car.

    Returns:
        One recording DataFrame per driver, in order; a car that leaves the road
        ends its recording there.
    """
    drivers = list(drivers)
    n = len(drivers)
    if n == 0:
        return []
    if len(seeds) != n:
        raise ValueError(f"got {len(seeds)} seed pairs for {n} drivers")
    cfg = _physical_config(config)
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", config=cfg)
    try:
        base = hasa_unwrapped(env)
        setup = base.setup
        road = setup.road
        env_seeds = [int(s[0]) for s in seeds]
        batch = make_batch(drivers)
        # gymnasium's VectorEnv.reset says seed: int, its vector envs take a list too
        options_ = dict(options) if options else None
        _, info = env.reset(seed=env_seeds, options=options_)  # type: ignore[arg-type]
        batch.reset([int(s[1]) for s in seeds], _env_dt(setup))
        max_steps = -(-setup.max_sim_steps // setup.action_repeat)
        width = len(RECORDING_COLUMNS)
        data = np.zeros((max_steps + 1, n, width))
        _info_block(data[0], 0, info, np.zeros(n), np.zeros(n, bool), np.zeros(n, bool))
        # the info is all run_drivers reads: the native vector env steps without building
        # the observation (the same state, info and rewards)
        step_env = getattr(env, "step_without_observation", None)
        if step_env is None:
            step_env = _drop_observation(env)
        done = np.zeros(n, dtype=bool)
        length = np.full(n, max_steps, dtype=np.int64)
        step = 0
        while not done.all() and step < max_steps:
            steering, acceleration = batch.act(info, road)
            active = ~done
            bad = active & ~(np.isfinite(steering) & np.isfinite(acceleration))
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise RuntimeError(
                    f"driver {getattr(drivers[i], 'name', drivers[i])!r} (car {i}) returned a "
                    f"non-finite action at step {step}"
                )
            actions = np.column_stack(
                [np.where(active, steering, 0.0), np.where(active, acceleration, 0.0)]
            )
            reward, terminated, truncated, info = step_env(actions)
            step += 1
            _info_block(data[step], step, info, reward, terminated, truncated)
            ended = active & (terminated | truncated)
            length[ended] = step
            done |= ended
    finally:
        env.close()
    frames = []
    config_used = base.config
    for i in range(n):
        attrs = {
            "env_id": env_id,
            "config": config_used,
            "track": config_used["track"],
            "seed": int(seeds[i][0]),
            "driver": getattr(drivers[i], "name", type(drivers[i]).__name__),
            "driver_seed": int(seeds[i][1]),
            "reset_options": dict(options or {}),
        }
        frames.append(_frame(data[: length[i] + 1, i, :], attrs))
    return frames


def _drop_observation(env: Any) -> Any:
    """``env.step`` returning (rewards, terminated, truncated, infos) (the observation dropped)."""

    def step(actions: np.ndarray) -> tuple[Any, Any, Any, Any]:
        _, reward, terminated, truncated, info = env.step(actions)
        return reward, terminated, truncated, info

    return step


def _info_block(
    out: np.ndarray,
    step: int,
    info: Mapping[str, np.ndarray],
    reward: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
) -> None:
    """Write one step's recording rows of every car (:data:`RECORDING_COLUMNS`) into
    ``out`` ((N, columns) float64, a slice of the run's preallocated array)."""
    columns = [np.full(reward.shape, float(step))]
    columns.extend(np.asarray(info[k]) for k in INFO_KEYS)
    columns.extend((np.asarray(reward), terminated, truncated))
    # ints and bools are cast to float64 as astype(np.float64) would: exact
    np.stack(columns, axis=1, out=out, casting="safe")


def run_population(
    drivers: Sequence[HumanParams | Driver],
    runs: int = 10,
    seed: int = 0,
    env_id: str = DEFAULT_ENV_ID,
    config: Mapping[str, Any] | None = None,
    options: Mapping[str, Any] | None = None,
    runs_by_name: Mapping[str, int] | None = None,
) -> dict[str, list[pd.DataFrame]]:
    """Runs of every driver of a population, all at once in one vector env.

    Args:
        drivers: synthetic drivers' parameters of any archetype (driven by
            :func:`~hasa_env.drivers.archetypes.make_driver`) or drivers.
        runs: runs per driver.
        seed: base seed (see :func:`run_seeds`; key "<name>/<track>").
        env_id, config, options: as in :func:`run_drivers`.
        runs_by_name: per-driver run counts overriding ``runs`` (e.g. {"Ill": 14}).

    Returns:
        {driver name: [recording, ...]} in population order. Run r of a driver
        is the same as ``run_driver(driver, env_id, runs=R, seed=seed)[r]``.
    """
    cfg = _physical_config(config)
    track = _track_of(env_id, cfg)
    counts = dict(runs_by_name or {})
    objects: list[Driver] = []
    names: list[str] = []
    for item in drivers:
        driver = make_driver(item) if isinstance(item, HumanParams) else item
        objects.append(driver)
        names.append(str(getattr(driver, "name", type(driver).__name__)))
    if len(set(names)) != len(names):
        raise ValueError(f"driver names must be unique, got {names}")
    unknown = [k for k in counts if k not in names]
    if unknown:
        raise ValueError(f"runs_by_name names unknown drivers {unknown}; drivers: {names}")
    cars: list[Driver] = []
    seeds: list[tuple[int, int]] = []
    owner: list[str] = []
    for name, driver in zip(names, objects, strict=True):
        count = counts.get(name, runs)
        for pair in run_seeds(seed, count, f"{name}/{track}"):
            cars.append(driver)
            seeds.append(pair)
            owner.append(name)
    frames = run_drivers(cars, seeds, env_id, config, options)
    out: dict[str, list[pd.DataFrame]] = {name: [] for name in names}
    for name, frame in zip(owner, frames, strict=True):
        out[name].append(frame)
    return out


def recording_meta(frame: pd.DataFrame) -> dict[str, Any]:
    """The :func:`hasa_env.recording.save_recording` ``meta`` of a run made here.

    Config, env seed, env id and reset options from the frame's ``attrs``;
    the driver's name and seed go into ``metadata``.
    """
    attrs = frame.attrs
    missing = [k for k in ("config", "seed", "env_id") if k not in attrs]
    if missing:
        raise ValueError(f"the frame's attrs lack {missing}: it was not made by hasa_env.drivers")
    return {
        "config": attrs["config"],
        "seed": int(attrs["seed"]),
        "env_id": attrs["env_id"],
        "reset_options": dict(attrs.get("reset_options") or {}),
        "metadata": {
            "driver": attrs.get("driver"),
            "driver_seed": attrs.get("driver_seed"),
            "synthetic": True,
        },
    }


def save_runs(
    frames: Sequence[pd.DataFrame], directory: str | Any, prefix: str = "run"
) -> list[Any]:
    """Save runs as recordings ``<directory>/<prefix>_000.csv`` (+ JSON sidecars).

    Returns the CSV paths. Uses :func:`hasa_env.recording.save_recording`, so the
    files load with :func:`hasa_env.recording.load_recordings` and replay exactly.
    """
    folder = Path(directory)
    return [
        save_recording(frame, folder / f"{prefix}_{i:03d}.csv", recording_meta(frame))
        for i, frame in enumerate(frames)
    ]
