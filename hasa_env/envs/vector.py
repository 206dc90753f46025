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

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from hasa_env.envs.base import LaneKeepingBase, VectorCarShell, started
from hasa_env.sim.car import Car, advance_cars, start_cars, state_values, truncated
from hasa_env.sim.dynamics import ARRAY_OPS
from hasa_env.sim.setup import INFO_KEYS, build_setup, check_reset_options, physical_action
from hasa_env.sim.transition import env_step, step_reward

__all__ = ["LaneKeepingVectorEnv"]


class LaneKeepingVectorEnv(LaneKeepingBase, VectorCarShell, VectorEnv):
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

    make_setup = staticmethod(build_setup)

    def _init_env(self) -> None:
        self._sensor_lo, self._sensor_hi = (
            b.astype(np.float64) for b in self.setup.sensor_bounds()
        )
        self._state_lo, self._state_hi = (b.astype(np.float64) for b in self.setup.state_bounds())

    # ------------------------------------------------------------------ API
    info_keys = INFO_KEYS

    def _checked_options(self, options: dict[str, Any]) -> dict[str, Any]:
        return check_reset_options(options, self.setup)

    def _start(
        self, cars: Car[np.ndarray], idx: np.ndarray, options: dict[str, Any], whole: bool
    ) -> None:
        start_cars(cars, idx, self._rngs, self.setup, options, self._curvature)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        rewards, terminated, time_up, info = self.step_without_observation(actions)
        return self._observation(started(self._car)), rewards, terminated, time_up, info

    def step_without_observation(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """:meth:`step` without building the observation: (rewards, terminated, truncated,
        infos), the same values (for callers that read the info only, as
        :func:`hasa_env.drivers.runner.run_drivers`)."""
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
        return rewards, terminated, time_up, self._info(cars)

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
