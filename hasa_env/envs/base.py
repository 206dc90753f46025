"""What the single-car and the vector env share, and the type of an unwrapped hasa env.

:class:`LaneKeepingBase` builds the observation of the configured type and the
info from an env's car record (:class:`hasa_env.sim.car.Car`), floats for one car
(:class:`~hasa_env.envs.lane_keeping.LaneKeepingEnv`) or arrays for N
(:class:`~hasa_env.envs.vector.LaneKeepingVectorEnv`); :func:`hasa_unwrapped`
gives code that takes any wrapped hasa env its ``config`` and ``setup``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol, cast

import gymnasium as gym
import numpy as np
from gymnasium.vector import VectorEnv
from gymnasium.vector.utils import batch_space

from hasa_env.render import SceneRenderer, make_renderer
from hasa_env.sim.car import Car, car_info_values, empty_cars
from hasa_env.sim.setup import INFO_KEYS, EnvSetup

__all__ = [
    "HasaEnv",
    "LaneKeepingBase",
    "SingleCarShell",
    "VectorCarShell",
    "check_render_mode",
    "check_vector_args",
    "hasa_unwrapped",
    "register_track_ids",
    "started",
    "vector_reset_request",
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


class SingleCarShell:
    """What every single-car env (the plain one and the advisor task) shares: the
    constructor's common part, ``render`` and ``close``.

    ``__init__(config, render_mode, track)`` checks the render mode, builds the set-up
    with the class's ``make_setup`` (validated config, deep-merged onto the defaults),
    the spaces, the scene drawn (``scene_of(setup)``: the car's :class:`EnvSetup`) and its
    curvature function, and leaves ``_car`` None until the first reset; then it calls the
    env's ``_init_env`` hook. The env defines ``_info(car)``, ``reset`` and ``step``.
    """

    metadata: dict[str, Any]
    render_mode: str | None
    _car: Any
    _scene: EnvSetup
    _renderer: SceneRenderer | None = None
    make_setup: Callable[[Mapping[str, Any] | None, str | None], Any]
    scene_of: Callable[[Any], EnvSetup] = staticmethod(lambda setup: setup)

    def __init__(
        self,
        config: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        track: str | None = None,
    ) -> None:
        check_render_mode(render_mode, self.metadata["render_modes"])
        self.setup = self.make_setup(config, track)
        self.config = self.setup.config
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": self.config["render"]["fps"]}
        self.action_space = self.setup.action_space()
        self.observation_space = self.setup.observation_space()
        self._scene = self.scene_of(self.setup)
        self._curvature = self._scene.curvature_scalar()
        self._car = None
        self._init_env()

    def _init_env(self) -> None:
        """The env's own fields, after the shared ones (a hook; nothing by default)."""

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


class VectorCarShell:
    """What every native vector env (the plain one and the advisor task) shares: the
    constructor's common part, ``render`` (one ``rgb_array`` frame per car) and
    ``close_extras``.

    ``__init__(num_envs, config, render_mode, track, max_episode_steps)`` checks its
    arguments, builds the set-up with the class's ``make_setup``, the single and batched
    spaces, the scene (``scene_of(setup)``) and its curvature function, one generator per
    car and the N cars (:func:`hasa_env.sim.car.empty_cars`; ``_car`` is None until the
    first reset); then it calls the env's ``_init_env`` hook. The env defines ``_info(cars)``
    (arrays, with gymnasium's ``"_key"`` masks), ``reset`` and ``step``.
    """

    metadata: dict[str, Any]
    render_mode: str | None
    num_envs: int
    _car: Any
    _scene: EnvSetup
    _renderers: list[SceneRenderer] | None = None
    make_setup: Callable[[Mapping[str, Any] | None, str | None], Any]
    scene_of: Callable[[Any], EnvSetup] = staticmethod(lambda setup: setup)

    def __init__(
        self,
        num_envs: int = 1,
        config: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        track: str | None = None,
        max_episode_steps: int | None = None,
    ) -> None:
        n = check_vector_args(
            num_envs, render_mode, self.metadata["render_modes"], max_episode_steps
        )
        self.setup = self.make_setup(config, track)
        self.config = self.setup.config
        self.num_envs = n
        self.render_mode = render_mode
        self.single_action_space = self.setup.action_space()
        self.single_observation_space = self.setup.observation_space()
        self.action_space = batch_space(self.single_action_space, n)
        self.observation_space = batch_space(self.single_observation_space, n)
        self._scene = self.scene_of(self.setup)
        self._curvature = self._scene.curvature_array()
        self._rngs: list[np.random.Generator] = [np.random.default_rng() for _ in range(n)]
        self._cars = empty_cars(n, self._scene)
        self._car = None
        self._autoreset = np.zeros(n, dtype=bool)
        self._arange = np.arange(n)
        self._init_env()

    def _init_env(self) -> None:
        """The env's own fields, after the shared ones (a hook; nothing by default)."""

    info_keys: Sequence[str]
    """The keys of the env's info (masked per car after a partial reset)."""

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every car, or the cars of ``options["reset_mask"]`` (a partial reset).

        ``seed``: None, an int (car i gets ``seed + i``) or one seed per car; a car given
        a seed gets a new generator. Everything is checked before anything changes.
        """
        mask, seeds, options = vector_reset_request(
            seed, options, self.num_envs, started=self._car is not None
        )
        options = self._checked_options(options)
        idx = self._arange if mask is None else np.flatnonzero(mask)
        for i in idx.tolist():
            if seeds[i] is not None:
                self._rngs[i] = np.random.default_rng(seeds[i])
        cars = self._car = self._cars
        self._start(cars, idx, options, whole=mask is None)
        self._autoreset[idx] = False
        info = self._info(cars)
        if mask is not None:  # as gymnasium's vector envs: info entries of the reset cars only
            for key in self.info_keys:
                info["_" + key] = mask.copy()
        return self._observation(cars), info

    @abstractmethod
    def _checked_options(self, options: dict[str, Any]) -> dict[str, Any]:
        """The reset options (``reset_mask`` removed) checked, before anything changes."""

    @abstractmethod
    def _start(self, cars: Any, idx: np.ndarray, options: dict[str, Any], whole: bool) -> None:
        """New episodes for the cars ``idx`` (``whole``: every car, a full reset)."""

    @abstractmethod
    def _observation(self, car: Any) -> Any:
        """The env's observation of the cars."""

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
