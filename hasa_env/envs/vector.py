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

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from hasa_env.envs.base import LaneKeepingBase, check_vector_args
from hasa_env.render import SceneRenderer, make_renderer
from hasa_env.sim.dynamics import (
    ARRAY_OPS,
    VehicleState,
    road_frame_acceleration,
    road_frame_velocity,
    sensor_readings,
)
from hasa_env.sim.setup import (
    INFO_KEYS,
    build_setup,
    check_reset_options,
    draw_episode,
    draw_noise_block,
    physical_action,
)
from hasa_env.sim.transition import env_step

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


class LaneKeepingVectorEnv(LaneKeepingBase, VectorEnv):
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
        self._noise = np.zeros((n, self.setup.noise_block, len(self.setup.noise_std)))
        self._noise_pos = np.zeros(n, dtype=np.int64)
        self._sim_step = np.zeros(n, dtype=np.int64)
        self._acceleration = np.zeros(n)
        self._bias = np.zeros(n)
        self._bias_index = np.zeros(n, dtype=np.int64)
        self._autoreset = np.zeros(n, dtype=bool)
        self._kappa = np.zeros(n)
        n_phases = self.setup.disturbance.n_phases if self.setup.disturbance is not None else 0
        self._phases = np.zeros((n, n_phases))  # disturbance phases of each car's episode
        self._velocity = (np.zeros(n), np.zeros(n))
        self._sensors = np.zeros((len(self.setup.noise_std), n))  # one row per channel
        self._state: VehicleState[np.ndarray] | None = None
        self._arange = np.arange(n)
        self._row_base = self._arange * self.setup.noise_block  # car i's block in the flat noise
        self._renderers: list[SceneRenderer] | None = None
        self._sensor_lo, self._sensor_hi = (
            b.astype(np.float64) for b in self.setup.sensor_bounds()
        )
        self._state_lo, self._state_hi = (b.astype(np.float64) for b in self.setup.state_bounds())

    # ------------------------------------------------------------------ API
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        n = self.num_envs
        mask, seeds, options = vector_reset_request(
            seed, options, n, started=self._state is not None
        )
        idx = self._arange if mask is None else np.flatnonzero(mask)
        options = check_reset_options(options, self.setup)
        for i in idx.tolist():
            if seeds[i] is not None:
                self._rngs[i] = np.random.default_rng(seeds[i])
        state = self._state
        if state is None:
            state = VehicleState(*(np.zeros(n) for _ in range(5)))
        state = self._reset_envs(state, idx, options)
        self._autoreset[idx] = False
        info = self._info(state)
        if mask is not None:  # as gymnasium's vector envs: info entries of the reset cars only
            for key in INFO_KEYS:
                info["_" + key] = mask.copy()
        return self._observation(state), info

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        setup = self.setup
        steer, acc = physical_action(setup, actions, self.num_envs)
        resetting = self._autoreset.copy()
        outcome = env_step(
            self._state,
            self._velocity,
            steer,
            acc,
            setup,
            self._curvature,
            ARRAY_OPS,
            self._sim_step,
            self._phases,
        )
        state = VehicleState(*(np.asarray(f, dtype=np.float64) for f in outcome.state))
        self._state = state
        self._velocity = outcome.velocity
        self._sim_step += setup.action_repeat
        self._acceleration = acc
        # every car's next sample; the cars about to be reset are overwritten below
        self._sample_all(state, outcome.imu, self._curvature_of(state.station), skip=resetting)
        terminated = np.asarray(outcome.off_road, dtype=bool)
        truncated = self._sim_step >= setup.max_sim_steps
        rewards = np.asarray(outcome.reward, dtype=np.float64)
        if resetting.any():
            idx = np.flatnonzero(resetting)
            state = self._reset_envs(state, idx, None)
            rewards[idx] = 0.0
            terminated[idx] = False
            truncated[idx] = False
        self._autoreset = terminated | truncated
        return self._observation(state), rewards, terminated, truncated, self._info(state)

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode='rgb_array'")
            return None
        if self._state is None:
            raise RuntimeError("call reset() before render()")
        if self._renderers is None:
            self._renderers = [make_renderer(self.setup, "rgb_array") for _ in range(self.num_envs)]
        info = self._info(self._state)
        frames = []
        for i, renderer in enumerate(self._renderers):
            frame = renderer.render({k: v[i] for k, v in info.items() if not k.startswith("_")})
            assert frame is not None  # (rgb_array)
            frames.append(frame)
        return tuple(frames)

    def close_extras(self, **kwargs: Any) -> None:
        self._renderers = None

    # ------------------------------------------------------------- helpers
    def _reset_envs(
        self, state: VehicleState[np.ndarray], idx: np.ndarray, options: dict[str, Any] | None
    ) -> VehicleState[np.ndarray]:
        """Start new episodes for the cars ``idx`` of ``state``; returns (and keeps) the new
        state of all cars."""
        fields = [f.copy() for f in state]
        for i in idx.tolist():
            start, index, bias, block, phases = draw_episode(self._rngs[i], self.setup, options)
            if phases:
                self._phases[i] = phases
            for f, value in zip(fields, start, strict=True):
                f[i] = value
            self._bias[i], self._bias_index[i] = bias, index
            self._noise[i] = block
            self._noise_pos[i] = 0
            self._sim_step[i] = 0
            self._acceleration[i] = 0.0
        new_state = self._state = VehicleState(*fields)
        start_state = VehicleState(*(f[idx] for f in fields))
        velocity = road_frame_velocity(start_state, ARRAY_OPS)
        self._velocity[0][idx], self._velocity[1][idx] = velocity
        # the reset cars' first sample: instantaneous IMU at zero acceleration
        kappa = self._curvature_of(start_state.station)
        imu = road_frame_acceleration(start_state, 0.0, kappa, self.setup.params, ARRAY_OPS)
        self._refill_exhausted(idx)
        noise = self._noise[idx, self._noise_pos[idx]]
        self._noise_pos[idx] += 1
        readings = sensor_readings(start_state, imu, self._bias[idx], noise.T, self.setup.noise_std)
        self._kappa[idx] = kappa
        for channel, reading in zip(self._sensors, readings, strict=True):
            channel[idx] = reading
        return new_state

    def _curvature_of(self, station: np.ndarray) -> np.ndarray:
        """Road curvature (1/m) at the given stations, same shape."""
        kappa = self._curvature(station)
        return np.broadcast_to(np.asarray(kappa, dtype=np.float64), station.shape)

    def _refill_exhausted(self, rows: np.ndarray) -> None:
        """Draw a new noise block for each car of ``rows`` whose block is used up."""
        exhausted = rows[self._noise_pos[rows] >= self.setup.noise_block]
        for i in exhausted.tolist():
            self._noise[i] = draw_noise_block(self._rngs[i], self.setup)
            self._noise_pos[i] = 0

    def _sample_all(
        self, state: VehicleState[np.ndarray], imu: tuple, kappa: np.ndarray, skip: np.ndarray
    ) -> None:
        """Every car's next noise row, sensors and curvature.

        Cars in ``skip`` (about to be reset, which draws them a new block) draw
        nothing from their generators; their values here are placeholders.
        """
        block = self.setup.noise_block
        pos = self._noise_pos
        if pos.max() >= block:
            self._refill_exhausted(self._arange[~skip])
            pos = np.minimum(pos, block - 1)  # skipped cars: any row, overwritten at reset
        noise = self._noise.reshape(-1, self._noise.shape[2])[self._row_base + pos]
        self._noise_pos += 1
        readings = sensor_readings(state, imu, self._bias, noise.T, self.setup.noise_std)
        self._kappa = np.array(kappa, dtype=np.float64)
        for channel, reading in zip(self._sensors, readings, strict=True):
            channel[:] = reading

    def _sensor_obs(self) -> np.ndarray:
        return np.clip(self._sensors.T, self._sensor_lo, self._sensor_hi).astype(np.float32)

    def _state_obs(self, state: VehicleState) -> np.ndarray:
        s = state
        values = np.stack([s.lateral_offset, s.heading, s.speed, s.steering, self._kappa], axis=1)
        return np.clip(values, self._state_lo, self._state_hi).astype(np.float32)

    def _info(self, state: VehicleState) -> dict[str, Any]:
        """The info as arrays with gymnasium's ``"_key"`` masks (every car)."""
        info: dict[str, Any] = {}
        mask = np.ones(self.num_envs, dtype=bool)
        for key, value in super()._info(state).items():
            info[key] = np.array(value, copy=True)
            info["_" + key] = mask
        return info
