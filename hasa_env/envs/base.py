"""What the single-car and the vector env share, and the type of an unwrapped hasa env.

:class:`LaneKeepingBase` builds the observation of the configured type and the
info from an env's car record (:class:`hasa_env.sim.car.Car`), floats for one car
(:class:`~hasa_env.envs.lane_keeping.LaneKeepingEnv`) or arrays for N
(:class:`~hasa_env.envs.vector.LaneKeepingVectorEnv`); :func:`hasa_unwrapped`
gives code that takes any wrapped hasa env its ``config`` and ``setup``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any, Protocol, cast

import gymnasium as gym
import numpy as np
from gymnasium.vector import VectorEnv

from hasa_env.render import SceneRenderer, make_renderer
from hasa_env.sim.car import Car, car_info_values
from hasa_env.sim.setup import INFO_KEYS, EnvSetup

__all__ = [
    "HasaEnv",
    "LaneKeepingBase",
    "RendersCars",
    "RendersOneCar",
    "check_render_mode",
    "check_vector_args",
    "hasa_unwrapped",
    "register_track_ids",
    "started",
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


def register_track_ids(ids: Sequence[str], entry_point: str, vector_entry_point: str) -> None:
    """Register ``ids`` with gymnasium, one per track: ``ids[0]`` the straight road,
    ``ids[1]`` the shipped curved track (idempotent: a registered id is left alone).

    The entry points are ``"module:Class"`` strings, imported only when an env is made.
    """
    for env_id, track in zip(ids, ("straight", "curved"), strict=True):
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point=entry_point,
            vector_entry_point=vector_entry_point,
            kwargs={"track": track},
        )


def started(car: Car | None) -> Car:
    """An env's car, or the RuntimeError of a step before the first reset."""
    if car is None:
        raise RuntimeError("call reset() before step()")
    return car


def hasa_unwrapped(env: gym.Env | VectorEnv) -> HasaEnv:
    """``env.unwrapped`` as a hasa env (typed only: a non-hasa env fails where used)."""
    return cast(HasaEnv, env.unwrapped)


class LaneKeepingBase(ABC):
    """The observation and the info of a lane-keeping env from its car record.

    ``_car`` is the :class:`~hasa_env.sim.car.Car` of the episode (floats for one car,
    (N,) arrays for N cars); the subclasses saturate the values at the bounds in
    their backend's way.
    """

    setup: EnvSetup
    _car: Car | None

    @abstractmethod
    def _sensor_obs(self, car: Car) -> np.ndarray:
        """The ``"sensors"`` observation: the readings saturated at their bounds, float32."""

    @abstractmethod
    def _state_obs(self, car: Car) -> np.ndarray:
        """The ``"state"`` observation (oracle): state and curvature at their bounds, float32."""

    def _observation(self, car: Car) -> Any:
        kind = self.setup.observation_type
        if kind == "sensors":
            return self._sensor_obs(car)
        if kind == "state":
            return self._state_obs(car)
        return {"sensors": self._sensor_obs(car), "state": self._state_obs(car)}

    def _info(self, car: Car) -> dict[str, Any]:
        """The info of :data:`hasa_env.sim.setup.INFO_KEYS` (floats for one car, arrays for N)."""
        return dict(zip(INFO_KEYS, car_info_values(car, self.setup), strict=True))


class RendersOneCar:
    """``render`` and ``close`` of a single-car env (the plain one and the advisor task).

    The env sets ``render_mode``, ``_car`` (None before the first reset), ``_scene``
    (the set-up whose road and markings are drawn) and defines ``_info(car)``.
    """

    render_mode: str | None
    _car: Any
    _scene: EnvSetup
    _renderer: SceneRenderer | None = None

    @abstractmethod
    def _info(self, car: Any) -> dict[str, Any]:
        """The env's info for ``car`` (what the renderer draws)."""

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human' "
                "to gym.make"
            )
            return None
        if self._car is None:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            self._renderer = make_renderer(self._scene, self.render_mode)
        return self._renderer.render(self._info(self._car))

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class RendersCars:
    """``render`` and ``close_extras`` of a native vector env: one ``rgb_array`` frame per car.

    The env sets ``render_mode``, ``num_envs``, ``_car`` (None before the first reset),
    ``_scene`` and defines ``_info(cars)`` (arrays, with gymnasium's ``"_key"`` masks).
    """

    render_mode: str | None
    num_envs: int
    _car: Any
    _scene: EnvSetup
    _renderers: list[SceneRenderer] | None = None

    @abstractmethod
    def _info(self, car: Any) -> dict[str, Any]:
        """The env's info for the cars (one entry per car)."""

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode='rgb_array'")
            return None
        if self._car is None:
            raise RuntimeError("call reset() before render()")
        if self._renderers is None:
            self._renderers = [
                make_renderer(self._scene, "rgb_array") for _ in range(self.num_envs)
            ]
        info = self._info(self._car)
        frames = []
        for i, renderer in enumerate(self._renderers):
            frame = renderer.render({k: v[i] for k, v in info.items() if not k.startswith("_")})
            assert frame is not None  # (rgb_array)
            frames.append(frame)
        return tuple(frames)

    def close_extras(self, **kwargs: Any) -> None:
        self._renderers = None
