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

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from advisor_tasks.env import ADVISOR_RESET_OPTIONS
from advisor_tasks.setup import (
    ADVISOR_INFO_KEYS,
    AdvisorSetup,
    WheelNoise,
    build_advisor_setup,
    estimate_readout,
    observation_rows,
    pop_advisor_option,
)
from hasa_env.envs.base import VectorCarShell, started
from hasa_env.rl.humans import HumanPool
from hasa_env.sim.car import (
    Car,
    advance_cars,
    car_info_values,
    start_cars,
    truncated,
)
from hasa_env.sim.dynamics import ARRAY_OPS
from hasa_env.sim.setup import INFO_KEYS, RESET_OPTIONS
from hasa_env.sim.transition import env_step, step_reward

__all__ = ["LaneKeepingAdvisorVectorEnv"]


class LaneKeepingAdvisorVectorEnv(VectorCarShell, VectorEnv):
    """N cars of the advisor task stepped together (see the module docstring and
    :class:`advisor_tasks.env.LaneKeepingAdvisorEnv` for spaces, reward and info)."""

    metadata = {
        "render_modes": ["rgb_array"],
        "autoreset_mode": AutoresetMode.NEXT_STEP,
        "render_fps": 30,
    }
    partial_reset = True
    """``reset(options={"reset_mask": m})`` resets exactly the cars of ``m`` (for SB3VecEnv)."""

    setup: AdvisorSetup
    make_setup = staticmethod(build_advisor_setup)
    scene_of = staticmethod(lambda setup: setup.env)

    def _init_env(self) -> None:
        n = self.num_envs
        env = self.setup.env
        self._bounds = self.setup.observation_bounds()
        self._humans = HumanPool(self.setup.drivers, n, self.setup.dt)
        self._wheel_noise = WheelNoise(n)
        self._estimator = self.setup.make_estimator()
        self._advisor = np.zeros(n, dtype=np.int64)
        self._command = np.zeros(n)
        self._policy_steering = np.zeros(n)
        self._wheel = np.zeros(n)
        self._substeps = np.zeros((n, env.action_repeat))
        self._readout: dict[str, np.ndarray] = {}

    # ------------------------------------------------------------------ API
    info_keys = ADVISOR_INFO_KEYS

    def _checked_options(self, options: dict[str, Any]) -> dict[str, Any]:
        allowed = (*RESET_OPTIONS, *ADVISOR_RESET_OPTIONS)
        for key in options:
            if key not in allowed:
                raise ValueError(
                    f"unknown reset option {key!r}; allowed: {', '.join(allowed)}, reset_mask"
                )
        return options

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        cars = started(self._car)
        setup = self.setup
        env = setup.env
        policy_steering, policy_acceleration = setup.action_to_physical(actions, self.num_envs)
        self._policy_steering = np.array(policy_steering, dtype=np.float64)
        resetting = self._autoreset.copy()
        any_resetting = bool(resetting.any())
        start_steering = cars.state.steering
        off_road = np.zeros(self.num_envs, dtype=bool)
        for j in range(env.action_repeat):
            command, steering, acceleration = self._human_sample(
                cars, policy_steering, policy_acceleration
            )
            outcome = env_step(
                cars.state,
                cars.velocity,
                steering,
                acceleration,
                setup.sample,
                self._curvature,
                ARRAY_OPS,
                cars.sim_step,
                cars.phases,
            )
            off_road |= np.asarray(outcome.off_road, dtype=bool)
            advance_cars(
                cars, outcome, acceleration, 1, self._rngs, env, self._curvature, resetting
            )
            self._command = command
            self._wheel = self._wheel_reading(cars, command, None)
            sensors = cars.sensors
            measurement = np.column_stack([sensors.speed, sensors.camera_lateral, self._wheel])
            imu = np.column_stack([sensors.imu_longitudinal, sensors.imu_lateral])
            if any_resetting:  # placeholders: missing, so they neither update nor gate
                measurement[resetting] = np.nan
                imu = np.where(resetting[:, None], 0.0, imu)
            self._estimator.step(measurement, imu, **setup.road_points(cars.state.station))
            self._substeps[:, j] = cars.state.lateral_offset
        rewards = np.asarray(
            step_reward(env, start_steering, cars.state, off_road), dtype=np.float64
        )
        terminated = off_road
        time_up = truncated(cars, env)
        if resetting.any():
            idx = np.flatnonzero(resetting)
            self._start(cars, idx, None, whole=False)
            rewards[idx] = 0.0
            terminated[idx] = False
            time_up[idx] = False
        else:
            self._readout = estimate_readout(self._estimator.estimate(), setup.hypotheses)
        self._autoreset = terminated | time_up
        return self._observation(cars), rewards, terminated, time_up, self._info(cars)

    @property
    def estimator(self) -> Any:
        """The batched estimator (one run per car, stepping at the simulation rate)."""
        return self._estimator

    # ------------------------------------------------------------- helpers
    def _human_sample(
        self, cars: Car[np.ndarray], policy_steering: Any, policy_acceleration: Any
    ) -> tuple[np.ndarray, Any, Any]:
        """The humans' commands at this sample, decided on the true states, and the
        (steering, acceleration) that drive the cars: the humans', clipped, when they
        drive; the policy's otherwise."""
        setup = self.setup
        env = setup.env
        state = cars.state
        info = {
            "time": cars.sim_step * setup.dt,
            "station": state.station,
            "lateral_offset": state.lateral_offset,
            "heading": state.heading,
            "speed": state.speed,
            "steering": state.steering,
        }
        if setup.human_drives:
            command, human_acceleration = self._humans.act(info, env.road)
            limit = env.steering_limit
            low, high = env.acceleration_limits
            steering = np.minimum(np.maximum(command, -limit), limit)
            acceleration = np.minimum(np.maximum(human_acceleration, low), high)
            return command, steering, acceleration
        return self._humans.steer(info, env.road), policy_steering, policy_acceleration

    def _start(
        self, cars: Car[np.ndarray], idx: np.ndarray, options: dict[str, Any] | None, whole: bool
    ) -> None:
        """Start new episodes of the cars ``idx``: car, sensors, human, estimator.

        Each car's generator draws its episode (:func:`hasa_env.sim.car.start_cars`),
        then its advisor's index and the seeds of its human and of its wheel sensor,
        the single env's order.
        """
        setup = self.setup
        options = dict(options or {})
        chosen = pop_advisor_option(options, len(setup.drivers))
        start_cars(cars, idx, self._rngs, setup.env, options, self._curvature)
        human_seeds, wheel_seeds = [], []
        for i in idx.tolist():
            rng = self._rngs[i]
            drawn = int(rng.integers(len(setup.drivers)))
            human_seed, wheel_seed = (int(s) for s in rng.integers(0, 2**63 - 1, size=2))
            if chosen is not None:
                self._advisor[i] = chosen
            else:
                self._advisor[i] = drawn if setup.fixed_driver is None else setup.fixed_driver
            human_seeds.append(human_seed)
            wheel_seeds.append(wheel_seed)
        self._humans.assign(idx, self._advisor[idx], human_seeds)
        self._wheel_noise.restart(idx, wheel_seeds)
        steering = cars.state.steering[idx]
        self._command[idx] = steering
        self._policy_steering[idx] = steering
        self._wheel[idx] = self._wheel_reading(cars, steering, idx)
        self._substeps[idx] = cars.state.lateral_offset[idx][:, None]
        sensors = cars.sensors
        measurement = np.column_stack(
            [sensors.speed[idx], sensors.camera_lateral[idx], self._wheel[idx]]
        )
        points = setup.road_points(cars.state.station[idx])
        if whole:
            estimate = self._estimator.reset(
                measurement, setup.hypotheses, prior=setup.prior, true_bias=cars.bias, **points
            )
        else:
            estimate = self._estimator.reset(
                measurement,
                setup.hypotheses,
                prior=setup.prior,
                true_bias=cars.bias[idx],
                runs=idx,
                **points,
            )
        self._readout = estimate_readout(estimate, setup.hypotheses)

    def _wheel_reading(
        self, cars: Car[np.ndarray], command: np.ndarray, idx: np.ndarray | None
    ) -> np.ndarray:
        """The steering sensor's reading of the humans' wheels (rad), of cars ``idx`` (None: all)."""
        if self.setup.human_drives:  # the car's own steering sensor reads the human's wheel
            wheel = cars.sensors.steering
            return wheel.copy() if idx is None else wheel[idx]
        return command + self.setup.env.noise_std.steering * self._wheel_noise.draw(idx)

    def _observation(self, cars: Car[np.ndarray]) -> np.ndarray:
        sensors = np.stack(cars.sensors, axis=1)
        return observation_rows(self._readout, sensors, self._wheel, self._bounds)

    def _info(self, cars: Car[np.ndarray]) -> dict[str, Any]:
        info: dict[str, Any] = {}
        for key, value in zip(INFO_KEYS, car_info_values(cars, self.setup.env), strict=True):
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
