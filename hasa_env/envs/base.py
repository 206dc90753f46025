"""What the single-car and the vector env share, and the type of an unwrapped hasa env.

:class:`LaneKeepingBase` builds the observation of the configured type and the
info from an env's per-episode values, floats for one car
(:class:`~hasa_env.envs.lane_keeping.LaneKeepingEnv`) or arrays for N
(:class:`~hasa_env.envs.vector.LaneKeepingVectorEnv`); :func:`hasa_unwrapped`
gives code that takes any wrapped hasa env its ``config`` and ``setup``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, Protocol, cast

import gymnasium as gym
import numpy as np
from gymnasium.vector import VectorEnv

from hasa_env.sim.dynamics import VehicleState
from hasa_env.sim.setup import INFO_KEYS, EnvSetup, info_values

__all__ = [
    "HasaEnv",
    "LaneKeepingBase",
    "check_render_mode",
    "check_vector_args",
    "hasa_unwrapped",
    "started_state",
]


class HasaEnv(Protocol):
    """An unwrapped hasa env, single or vector: its validated config and its set-up."""

    config: dict[str, Any]
    setup: EnvSetup


def check_render_mode(render_mode: str | None, allowed: list[str], kind: str = "env") -> None:
    """A ValueError naming the allowed modes unless ``render_mode`` is None or one of ``allowed``."""
    if render_mode is not None and render_mode not in allowed:
        raise ValueError(
            f"render_mode={render_mode!r} is not supported by the {kind}; allowed: None, "
            + ", ".join(repr(m) for m in allowed)
        )


def check_vector_args(
    num_envs: Any, render_mode: str | None, allowed: list[str], max_episode_steps: Any
) -> int:
    """A native vector env's constructor arguments checked; returns ``num_envs`` as an int."""
    if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
        raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
    check_render_mode(render_mode, allowed, "vector env")
    if max_episode_steps is not None:
        raise ValueError("max_episode_steps is not supported; set config['time_limit'] (s) instead")
    return int(num_envs)


def started_state(state: VehicleState | None) -> VehicleState:
    """An env's true state, or the RuntimeError of a step before the first reset."""
    if state is None:
        raise RuntimeError("call reset() before step()")
    return state


def hasa_unwrapped(env: gym.Env | VectorEnv) -> HasaEnv:
    """``env.unwrapped`` as a hasa env (typed only: a non-hasa env fails where used)."""
    return cast(HasaEnv, env.unwrapped)


class LaneKeepingBase(ABC):
    """The observation and the info of a lane-keeping env from its per-episode values.

    The values are floats for one car and (N,) arrays for N cars; ``_sensors``
    holds the readings in :data:`hasa_env.sim.dynamics.SENSOR_NAMES` order (a
    tuple for one car, a (6, N) array for N).
    """

    setup: EnvSetup
    _sim_step: Any
    _velocity: tuple[Any, Any]
    _acceleration: Any
    _kappa: Any
    _bias: Any
    _bias_index: Any
    _sensors: Any

    @abstractmethod
    def _sensor_obs(self) -> np.ndarray:
        """The ``"sensors"`` observation: the readings saturated at their bounds, float32."""

    @abstractmethod
    def _state_obs(self, state: VehicleState) -> np.ndarray:
        """The ``"state"`` observation (oracle): state and curvature at their bounds, float32."""

    def _observation(self, state: VehicleState) -> Any:
        kind = self.setup.observation_type
        if kind == "sensors":
            return self._sensor_obs()
        if kind == "state":
            return self._state_obs(state)
        return {"sensors": self._sensor_obs(), "state": self._state_obs(state)}

    def _info(self, state: VehicleState) -> dict[str, Any]:
        """The info of :data:`hasa_env.sim.setup.INFO_KEYS` (floats for one car, arrays for N)."""
        values = info_values(
            self._sim_step,
            state,
            self._velocity,
            self._acceleration,
            self._kappa,
            self._bias,
            self._bias_index,
            self._sensors,
            self.setup,
        )
        return dict(zip(INFO_KEYS, values, strict=True))
