"""The native vectorized lane-keeping env: N cars as numpy arrays.

It calls the same dynamics, sensor and reward functions as
:class:`hasa_env.LaneKeepingEnv` (with the array backend) and draws every
car's randomness from its own generator in the same order, so car ``i`` of
``LaneKeepingVectorEnv(num_envs=N)`` reset with ``seed`` reproduces
``LaneKeepingEnv`` reset with ``seed + i`` step for step, as
``gymnasium.vector.SyncVectorEnv`` would (autoreset mode ``NEXT_STEP``).

``gym.make_vec("hasa_env/LaneKeeping-v0", num_envs=N,
vectorization_mode="vector_entry_point", config={...})``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from hasa_env.envs.base import LaneKeepingBase, RendersCars, check_vector_args, started
from hasa_env.sim.car import Car, advance_cars, empty_cars, start_cars, state_values, truncated
from hasa_env.sim.dynamics import ARRAY_OPS
from hasa_env.sim.setup import INFO_KEYS, build_setup, check_reset_options, physical_action
from hasa_env.sim.transition import env_step, step_reward

__all__ = ["LaneKeepingVectorEnv", "vector_reset_request"]


def vector_reset_request(
    seed: int | list[int | None] | None,
    options: Mapping[str, Any] | None,
    num_envs: int,
    *,
    started: bool,
) -> tuple[np.ndarray | None, list[int | None], dict[str, Any]]:
    """A vector env's ``reset(seed=..., options=...)`` checked: (reset_mask or None, one
    seed per env, the other options).

    ``seed``: None, an int (env i gets ``seed + i``) or one int >= 0 / None per env;
    ``options["reset_mask"]``: a (N,) bool array selecting the envs to reset (a partial
    reset, only once the env has ``started``). Everything is checked before any state
    or generator changes, so a refused reset leaves the env as it was.
    """
    n = num_envs
    if options is not None and not isinstance(options, Mapping):
        raise ValueError(
            f"reset options must be a mapping (dict) or None, got {type(options).__name__} "
            f"{options!r:.60}"
        )
    options = dict(options or {})
    mask = options.pop("reset_mask", None)
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != (n,) or mask.dtype != np.bool_:
            raise ValueError(
                f"reset option 'reset_mask' must be a bool array of shape ({n},), got {mask!r}"
            )
        if not mask.any():
            raise ValueError("reset option 'reset_mask' must select at least one env")
        if not started and not mask.all():
            raise RuntimeError("reset() without reset_mask must come first (it resets every car)")
    if seed is None:
        seeds: list[int | None] = [None] * n
    elif isinstance(seed, bool):
        raise TypeError(f"reset(seed=...) must be an integer, a list or None, got {seed!r}")
    elif isinstance(seed, int | np.integer):
        seeds = [int(seed) + i for i in range(n)]
    else:
        seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(f"reset(seed=...) got {len(seeds)} seeds for {n} envs")
    for i, s in enumerate(seeds):
        if s is not None and (isinstance(s, bool) or not isinstance(s, int | np.integer) or s < 0):
            raise ValueError(
                f"reset(seed=...): seed {i} must be an integer >= 0 or None, got {s!r}"
            )
    return mask, seeds, options


class LaneKeepingVectorEnv(LaneKeepingBase, RendersCars, VectorEnv):
    """N independent lane-keeping cars stepped together (see :class:`hasa_env.LaneKeepingEnv`).

    Spaces are the single env's, batched. ``infos`` is a dict of arrays (one
    entry per car, with the ``"_key"`` masks of gymnasium's vector API) holding
    the single env's info keys. A car whose episode ended is reset on the next
    ``step`` (its action is ignored, reward 0, flags False).
    """

    metadata = {
        "render_modes": ["rgb_array"],
        "autoreset_mode": AutoresetMode.NEXT_STEP,
        "render_fps": 30,
    }

    def __init__(
        self,
        num_envs: int = 1,
        config: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        track: str | None = None,
        max_episode_steps: int | None = None,
    ) -> None:
        num_envs = check_vector_args(
            num_envs, render_mode, self.metadata["render_modes"], max_episode_steps
        )
        self.setup = build_setup(config, track)
        self.config = self.setup.config
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.single_action_space = self.setup.action_space()
        self.single_observation_space = self.setup.observation_space()
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._curvature = self.setup.curvature_array()
        n = self.num_envs
        self._rngs: list[np.random.Generator] = [np.random.default_rng() for _ in range(n)]
        self._cars = empty_cars(n, self.setup)
        self._car: Car[np.ndarray] | None = None  # the cars once reset
        self._autoreset = np.zeros(n, dtype=bool)
        self._arange = np.arange(n)
        self._scene = self.setup
        self._sensor_lo, self._sensor_hi = (
            b.astype(np.float64) for b in self.setup.sensor_bounds()
        )
        self._state_lo, self._state_hi = (b.astype(np.float64) for b in self.setup.state_bounds())

    # ------------------------------------------------------------------ API
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        n = self.num_envs
        mask, seeds, options = vector_reset_request(seed, options, n, started=self._car is not None)
        idx = self._arange if mask is None else np.flatnonzero(mask)
        options = check_reset_options(options, self.setup)
        for i in idx.tolist():
            if seeds[i] is not None:
                self._rngs[i] = np.random.default_rng(seeds[i])
        cars = self._car = self._cars
        start_cars(cars, idx, self._rngs, self.setup, options, self._curvature)
        self._autoreset[idx] = False
        info = self._info(cars)
        if mask is not None:  # as gymnasium's vector envs: info entries of the reset cars only
            for key in INFO_KEYS:
                info["_" + key] = mask.copy()
        return self._observation(cars), info

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        cars = started(self._car)
        setup = self.setup
        steer, acc = physical_action(setup, actions, self.num_envs)
        resetting = self._autoreset.copy()
        start_steering = cars.state.steering
        outcome = env_step(
            cars.state,
            cars.velocity,
            steer,
            acc,
            setup,
            self._curvature,
            ARRAY_OPS,
            cars.sim_step,
            cars.phases,
        )
        # every car's next sample; the cars about to be reset are overwritten below
        advance_cars(
            cars, outcome, acc, setup.action_repeat, self._rngs, setup, self._curvature, resetting
        )
        rewards = np.asarray(
            step_reward(setup, start_steering, outcome.state, outcome.off_road), dtype=np.float64
        )
        terminated = np.asarray(outcome.off_road, dtype=bool)
        time_up = truncated(cars, setup)
        if resetting.any():
            idx = np.flatnonzero(resetting)
            start_cars(cars, idx, self._rngs, setup, None, self._curvature)
            rewards[idx] = 0.0
            terminated[idx] = False
            time_up[idx] = False
        self._autoreset = terminated | time_up
        return self._observation(cars), rewards, terminated, time_up, self._info(cars)

    # ------------------------------------------------------------- helpers
    def _sensor_obs(self, car: Car) -> np.ndarray:
        values = np.stack(car.sensors, axis=1)
        return np.clip(values, self._sensor_lo, self._sensor_hi).astype(np.float32)

    def _state_obs(self, car: Car) -> np.ndarray:
        values = np.stack(state_values(car), axis=1)
        return np.clip(values, self._state_lo, self._state_hi).astype(np.float32)

    def _info(self, car: Car) -> dict[str, Any]:
        """The info as arrays with gymnasium's ``"_key"`` masks (every car)."""
        info: dict[str, Any] = {}
        mask = np.ones(self.num_envs, dtype=bool)
        for key, value in super()._info(car).items():
            info[key] = np.array(value, copy=True)
            info["_" + key] = mask
        return info
