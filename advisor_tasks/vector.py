"""The human-as-advisor task for N cars at once: the vector twin of
:class:`advisor_tasks.env.LaneKeepingAdvisorEnv`.

``gym.make_vec("hasa_env/LaneKeepingAdvisor-v0", num_envs=N,
vectorization_mode="vector_entry_point", config={...})``. The cars are numpy arrays
stepped by the same pure transition as every hasa env
(:func:`hasa_env.sim.transition.env_step`, one simulation sample at a time), the N
humans are vectorized batches of the population code (:class:`hasa_env.rl.HumanPool`:
a car gets a new human whenever its episode restarts) and the N estimators are one
batch of the Gaussian-mixture EKF (``GaussianMixtureEKF.step`` over N runs at every
sample). Every car draws its randomness from its own generator in the single env's
order, so car ``i`` reset with ``seed`` reproduces the single env reset with
``seed + i`` bit for bit, autoresets included (``tests/test_advisor_env.py``).

Autoreset mode ``NEXT_STEP``, as the lane-keeping vector env: a car whose episode ended
is reset on the next ``step`` (its action is ignored, reward 0, flags False).
``reset(options={"reset_mask": m})`` resets only the cars of ``m`` (what
:class:`hasa_env.rl.SB3VecEnv` uses). Spaces are the single env's, batched; ``infos``
is a dict of arrays (one entry per car, with gymnasium's ``"_key"`` masks) holding the
single env's info keys.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from advisor_tasks.env import ADVISOR_RESET_OPTIONS
from advisor_tasks.setup import (
    ADVISOR_INFO_KEYS,
    AdvisorSetup,
    WheelNoise,
    build_advisor_setup,
    estimate_readout,
    observation_rows,
)
from hasa_env.envs.base import check_vector_args, started_state
from hasa_env.envs.vector import vector_reset_request
from hasa_env.render import make_renderer
from hasa_env.rl.humans import HumanPool
from hasa_env.sim.dynamics import (
    ARRAY_OPS,
    VehicleState,
    lane_keeping_reward,
    road_frame_acceleration,
    road_frame_velocity,
    sensor_readings,
)
from hasa_env.sim.setup import (
    INFO_KEYS,
    RESET_OPTIONS,
    draw_episode,
    draw_noise_block,
    info_values,
)
from hasa_env.sim.transition import env_step

__all__ = ["LaneKeepingAdvisorVectorEnv"]


class LaneKeepingAdvisorVectorEnv(VectorEnv):
    """N cars of the advisor task stepped together (see the module docstring and
    :class:`advisor_tasks.env.LaneKeepingAdvisorEnv` for spaces, reward and info)."""

    metadata = {
        "render_modes": ["rgb_array"],
        "autoreset_mode": AutoresetMode.NEXT_STEP,
        "render_fps": 30,
    }
    partial_reset = True
    """``reset(options={"reset_mask": m})`` resets exactly the cars of ``m`` (for SB3VecEnv)."""

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
        self.setup: AdvisorSetup = build_advisor_setup(config, track)
        self.config = self.setup.config
        n = self.num_envs = int(num_envs)
        self.render_mode = render_mode
        env = self.setup.env
        self.single_action_space = self.setup.action_space()
        self.single_observation_space = self.setup.observation_space()
        self.action_space = batch_space(self.single_action_space, n)
        self.observation_space = batch_space(self.single_observation_space, n)
        self._curvature = env.curvature_array()
        self._bounds = self.setup.observation_bounds()
        self._rngs: list[np.random.Generator] = [np.random.default_rng() for _ in range(n)]
        self._noise = np.zeros((n, env.noise_block, len(env.noise_std)))
        self._noise_pos = np.zeros(n, dtype=np.int64)
        self._row_base = np.arange(n) * env.noise_block  # car i's block in the flat noise
        self._sim_step = np.zeros(n, dtype=np.int64)
        self._acceleration = np.zeros(n)
        self._bias = np.zeros(n)
        self._bias_index = np.zeros(n, dtype=np.int64)
        self._autoreset = np.zeros(n, dtype=bool)
        self._kappa = np.zeros(n)
        n_phases = env.disturbance.n_phases if env.disturbance is not None else 0
        self._phases = np.zeros((n, n_phases))
        self._velocity = (np.zeros(n), np.zeros(n))
        self._sensors = np.zeros((len(env.noise_std), n))  # one row per channel
        self._state: VehicleState | None = None
        self._arange = np.arange(n)
        self._humans = HumanPool(self.setup.drivers, n, self.setup.dt)
        self._wheel_noise = WheelNoise(n)
        self._estimator = self.setup.make_estimator()
        self._advisor = np.zeros(n, dtype=np.int64)
        self._command = np.zeros(n)
        self._policy_steering = np.zeros(n)
        self._wheel = np.zeros(n)
        self._substeps = np.zeros((n, env.action_repeat))
        self._readout: dict[str, np.ndarray] = {}
        self._renderers: list[Any] | None = None

    # ------------------------------------------------------------------ API
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        n = self.num_envs
        mask, seeds, options = vector_reset_request(
            seed, options, n, started=self._state is not None
        )
        allowed = (*RESET_OPTIONS, *ADVISOR_RESET_OPTIONS)
        for key in options:
            if key not in allowed:
                raise ValueError(
                    f"unknown reset option {key!r}; allowed: {', '.join(allowed)}, reset_mask"
                )
        idx = self._arange if mask is None else np.flatnonzero(mask)
        for i in idx.tolist():
            if seeds[i] is not None:
                self._rngs[i] = np.random.default_rng(seeds[i])
        if self._state is None:
            self._state = VehicleState(*(np.zeros(n) for _ in range(5)))
        self._reset_cars(idx, options, whole=mask is None)
        self._autoreset[idx] = False
        info = self._info()
        if mask is not None:  # as gymnasium's vector envs: info entries of the reset cars only
            for key in ADVISOR_INFO_KEYS:
                info["_" + key] = mask.copy()
        return self._observation(), info

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        setup = self.setup
        env = setup.env
        policy_steering, policy_acceleration = setup.action_to_physical(actions, self.num_envs)
        self._policy_steering = np.array(policy_steering, dtype=np.float64)
        resetting = self._autoreset.copy()
        any_resetting = bool(resetting.any())
        road = env.road
        limit = env.steering_limit
        low, high = env.acceleration_limits
        start_steering = self._state.steering
        off_road = np.zeros(self.num_envs, dtype=bool)
        for j in range(env.action_repeat):
            state = self._state
            info = {
                "time": self._sim_step * setup.dt,
                "station": state.station,
                "lateral_offset": state.lateral_offset,
                "heading": state.heading,
                "speed": state.speed,
                "steering": state.steering,
            }
            if setup.human_drives:
                command, human_acceleration = self._humans.act(info, road)
                steering = np.minimum(np.maximum(command, -limit), limit)
                acceleration = np.minimum(np.maximum(human_acceleration, low), high)
            else:
                command = self._humans.steer(info, road)
                steering, acceleration = policy_steering, policy_acceleration
            outcome = env_step(
                state,
                self._velocity,
                steering,
                acceleration,
                setup.sample,
                self._curvature,
                ARRAY_OPS,
                self._sim_step,
                self._phases,
            )
            self._state = VehicleState(*(np.asarray(f, dtype=np.float64) for f in outcome.state))
            self._velocity = outcome.velocity
            self._sim_step += 1
            self._acceleration = np.asarray(acceleration, dtype=np.float64)
            off_road |= np.asarray(outcome.off_road, dtype=bool)
            self._sample_all(outcome.imu, skip=resetting)
            self._command = command
            self._wheel = self._wheel_reading(command, None)
            measurement = np.column_stack([self._sensors[0], self._sensors[1], self._wheel])
            imu = self._sensors[3:5].T
            if any_resetting:  # placeholders: missing, so they neither update nor gate
                measurement[resetting] = np.nan
                imu = np.where(resetting[:, None], 0.0, imu)
            self._estimator.step(measurement, imu, **setup.road_points(self._state.station))
            self._substeps[:, j] = self._state.lateral_offset
        lateral_weight, rate_weight, penalty = env.reward_weights
        rewards = np.asarray(
            lane_keeping_reward(
                self._state.lateral_offset,
                self._state.steering - start_steering,
                off_road,
                0.5 * env.road.lane_width,
                limit,
                lateral_weight,
                rate_weight,
                penalty,
            ),
            dtype=np.float64,
        )
        terminated = off_road
        truncated = self._sim_step >= env.max_sim_steps
        if resetting.any():
            idx = np.flatnonzero(resetting)
            self._reset_cars(idx, None, whole=False)
            rewards[idx] = 0.0
            terminated[idx] = False
            truncated[idx] = False
        else:
            self._readout = estimate_readout(self._estimator.estimate(), setup.hypotheses)
        self._autoreset = terminated | truncated
        return self._observation(), rewards, terminated, truncated, self._info()

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode='rgb_array'")
            return None
        if self._renderers is None:
            self._renderers = [
                make_renderer(self.setup.env, "rgb_array") for _ in range(self.num_envs)
            ]
        info = self._info()
        return tuple(
            renderer.render({k: v[i] for k, v in info.items() if not k.startswith("_")})
            for i, renderer in enumerate(self._renderers)
        )

    def close_extras(self, **kwargs: Any) -> None:
        self._renderers = None

    @property
    def estimator(self) -> Any:
        """The batched estimator (one run per car, stepping at the simulation rate)."""
        return self._estimator

    # ------------------------------------------------------------- helpers
    def _reset_cars(self, idx: np.ndarray, options: dict[str, Any] | None, whole: bool) -> None:
        """Start new episodes of the cars ``idx``: car, sensors, human, estimator."""
        setup = self.setup
        env = setup.env
        options = dict(options or {})
        chosen = None
        if "advisor_index" in options:
            value = options.pop("advisor_index")
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ValueError(f"reset option 'advisor_index' must be an integer, got {value!r}")
            if not 0 <= value < len(setup.drivers):
                raise ValueError(
                    f"reset option 'advisor_index' = {value!r} is out of range: allowed "
                    f"integers 0..{len(setup.drivers) - 1} (one per driver of the population)"
                )
            chosen = int(value)
        fields = [f.copy() for f in started_state(self._state)]
        human_seeds, wheel_seeds = [], []
        for i in idx.tolist():
            rng = self._rngs[i]
            start, index, bias, block, phases = draw_episode(rng, env, options)
            drawn = int(rng.integers(len(setup.drivers)))
            human_seed, wheel_seed = (int(s) for s in rng.integers(0, 2**63 - 1, size=2))
            if chosen is not None:
                self._advisor[i] = chosen
            else:
                self._advisor[i] = drawn if setup.fixed_driver is None else setup.fixed_driver
            human_seeds.append(human_seed)
            wheel_seeds.append(wheel_seed)
            if phases:
                self._phases[i] = phases
            for f, value in zip(fields, start, strict=True):
                f[i] = value
            self._bias[i], self._bias_index[i] = bias, index
            self._noise[i] = block
            self._noise_pos[i] = 0
            self._sim_step[i] = 0
            self._acceleration[i] = 0.0
        self._state = VehicleState(*fields)
        start_state = VehicleState(*(f[idx] for f in fields))
        velocity = road_frame_velocity(start_state, ARRAY_OPS)
        self._velocity[0][idx], self._velocity[1][idx] = velocity
        # the reset cars' first sample: instantaneous IMU at zero acceleration
        kappa = np.broadcast_to(
            np.asarray(self._curvature(start_state.station), dtype=np.float64), idx.shape
        )
        imu = road_frame_acceleration(start_state, 0.0, kappa, env.params, ARRAY_OPS)
        noise = self._noise[idx, 0]
        self._noise_pos[idx] = 1
        readings = sensor_readings(start_state, imu, self._bias[idx], noise.T, env.noise_std)
        self._kappa[idx] = kappa
        for channel, reading in zip(self._sensors, readings, strict=True):
            channel[idx] = reading
        self._humans.assign(idx, self._advisor[idx], human_seeds)
        self._wheel_noise.restart(idx, wheel_seeds)
        steering = start_state.steering
        self._command[idx] = steering
        self._policy_steering[idx] = steering
        self._wheel[idx] = self._wheel_reading(steering, idx)
        self._substeps[idx] = start_state.lateral_offset[:, None]
        measurement = np.column_stack(
            [self._sensors[0][idx], self._sensors[1][idx], self._wheel[idx]]
        )
        points = setup.road_points(start_state.station)
        if whole:
            estimate = self._estimator.reset(
                measurement, setup.hypotheses, prior=setup.prior, true_bias=self._bias, **points
            )
        else:
            estimate = self._estimator.reset(
                measurement,
                setup.hypotheses,
                prior=setup.prior,
                true_bias=self._bias[idx],
                runs=idx,
                **points,
            )
        self._readout = estimate_readout(estimate, setup.hypotheses)

    def _wheel_reading(self, command: np.ndarray, idx: np.ndarray | None) -> np.ndarray:
        """The steering sensor's reading of the humans' wheels (rad), of cars ``idx`` (None: all)."""
        if self.setup.human_drives:  # the car's own steering sensor reads the human's wheel
            return self._sensors[5].copy() if idx is None else self._sensors[5][idx]
        return command + self.setup.env.noise_std[5] * self._wheel_noise.draw(idx)

    def _sample_all(self, imu: tuple, skip: np.ndarray) -> None:
        """Every car's sensors at this sample (one noise row each).

        Cars in ``skip`` (about to be reset, which draws them a new block) draw nothing
        from their generators; their readings here are placeholders.
        """
        env = self.setup.env
        block = env.noise_block
        pos = self._noise_pos
        if pos.max() >= block:
            for i in np.flatnonzero((pos >= block) & ~skip).tolist():
                self._noise[i] = draw_noise_block(self._rngs[i], env)
                self._noise_pos[i] = 0
            pos = np.minimum(self._noise_pos, block - 1)
        noise = self._noise.reshape(-1, self._noise.shape[2])[self._row_base + pos]
        self._noise_pos += 1
        state = started_state(self._state)
        readings = sensor_readings(state, imu, self._bias, noise.T, env.noise_std)
        kappa = self._curvature(state.station)
        self._kappa = np.array(
            np.broadcast_to(np.asarray(kappa, dtype=np.float64), state.station.shape)
        )
        for channel, reading in zip(self._sensors, readings, strict=True):
            channel[:] = reading

    def _observation(self) -> np.ndarray:
        return observation_rows(self._readout, self._sensors.T, self._wheel, self._bounds)

    def _info(self) -> dict[str, Any]:
        values = info_values(
            self._sim_step,
            started_state(self._state),
            self._velocity,
            self._acceleration,
            self._kappa,
            self._bias,
            self._bias_index,
            self._sensors,
            self.setup.env,
        )
        info: dict[str, Any] = {}
        for key, value in zip(INFO_KEYS, values, strict=True):
            info[key] = np.array(value, copy=True)
        for key, value in self._readout.items():
            info[key] = np.array(value, copy=True)
        info["advisor_index"] = self._advisor.copy()
        info["advisor_steering"] = np.array(self._command, dtype=np.float64)
        info["sensor_advisor_steering"] = self._wheel.copy()
        info["policy_steering"] = self._policy_steering.copy()
        info["substep_lateral_offset"] = self._substeps.copy()
        mask = np.ones(self.num_envs, dtype=bool)
        for key in ADVISOR_INFO_KEYS:
            info["_" + key] = mask
        return info
