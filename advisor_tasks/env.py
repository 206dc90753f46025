"""The human-as-advisor task: a policy drives, a synthetic human advises, one car.

``gym.make("hasa_env/LaneKeepingAdvisor-v0")`` (straight road) or
``"hasa_env/LaneKeepingAdvisorCurved-v0"``; the vector twin is
:class:`advisor_tasks.vector.LaneKeepingAdvisorVectorEnv`
(``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from advisor_tasks.setup import (
    AdvisorSetup,
    WheelNoise,
    build_advisor_setup,
    estimate_readout,
    observation_rows,
    pop_advisor_option,
)
from hasa_env.drivers.human import human_batch
from hasa_env.envs.base import SingleCarShell, started
from hasa_env.sim.car import Car, advance_car, car_info_values, start_car, truncated
from hasa_env.sim.dynamics import SCALAR_OPS, VehicleState
from hasa_env.sim.setup import INFO_KEYS
from hasa_env.sim.transition import env_step, step_reward

__all__ = ["LaneKeepingAdvisorEnv", "ADVISOR_RESET_OPTIONS"]

ADVISOR_RESET_OPTIONS = ("advisor_index",)
"""Reset options of the advisor task besides the lane-keeping env's (``bias_index``, ...)."""


class LaneKeepingAdvisorEnv(SingleCarShell, gym.Env):
    """Lane keeping with ambiguous markings, where the estimate comes from a human's advice.

    ## Description
    The car, road, markings, sensors and dynamics are those of
    :class:`hasa_env.LaneKeepingEnv` (docs/design.md §3-4): the camera sees ``y + b``
    with the true bias ``b`` unknown among ``markings.hypotheses``. A synthetic human
    of a named population (``advisor.population``; one drawn per episode, or the
    configured ``advisor.driver``) sits at the wheel, sees the true lane and turns
    the wheel as it would to keep it (the lane it drives in and the offset from its
    centre it keeps are the ``scenario``'s: ``road.lane_shifts``, and the drivers'
    preferred offsets of :func:`hasa_env.scenarios.scenario_drivers`). Its measured steering feeds the human-as-advisor
    estimator (``estimator.*``: the Gaussian-mixture EKF by default, docs/design.md
    §8), which tells the lanes apart. With ``advisor.drives = "car"`` (default) the
    policy's action drives the car and the human only advises (the paper's "future
    work": does the advice still tell the true lane when the car drives itself?);
    with ``"human"`` the human's steering and speed drive and the action is ignored.

    Rates: the simulation, the human and the estimator all run at ``sim_frequency``
    (100 Hz); the policy acts every ``action_repeat`` samples, its action held. Within
    one env step each simulation sample is one :func:`hasa_env.sim.transition.env_step`
    of one sample: the human decides on the true state, the car moves, the sensors
    read (one noise row per sample), and the estimator takes that sample's
    measurements. So a 10 Hz policy (``action_repeat`` 10) gets an estimate made from
    every 100 Hz sample. Timing of the advice as in recordings (docs/design.md §5.6):
    the wheel reading of sample k is the human's command decided from sample k-1
    (at reset: the car's initial steering), plus the steering-sensor noise
    (``noise.steering``; 0 under the "paper" population's study conditions).

    ## Action space
    ``action.steering_only`` (default true): ``Box(-1, 1, (1,), float32)``, the
    road-wheel angle (normalized onto ``-max_steering .. max_steering``, or rad with
    ``action.type = "physical"``); the acceleration is 0 m/s^2, so the car keeps its
    speed. False: the lane-keeping env's ``[steering, acceleration]``. Out-of-range
    values are clipped; NaN or inf raises ``ValueError``. Ignored (but checked) when
    the human drives.

    ## Observation space
    ``Box(15 + H,)`` float32, H = number of lane hypotheses (default 2: 17 entries),
    :func:`advisor_tasks.setup.observation_names`; values saturate at the bounds:

    | index        | entry                        | unit  | what                                          | bounds          |
    |--------------|------------------------------|-------|-----------------------------------------------|-----------------|
    | 0            | estimate_lateral_offset      | m     | mixture mean of y                             | [-60, 60]       |
    | 1            | estimate_lateral_offset_std  | m     | mixture std of y                              | [0, 100]        |
    | 2            | estimate_heading             | rad   | atan2(v_y, v_x) of the mixture mean           | [-pi, pi]       |
    | 3            | estimate_speed               | m/s   | sqrt(v_x^2 + v_y^2) of the mixture mean       | [0, 200]        |
    | 4 .. 3+H     | estimate_weight_i            | -     | probability of hypothesis i (lane weights)    | [0, 1]          |
    | 4+H .. 6+H   | estimate_undecided, estimate_decided, estimate_model_mismatch | - | the estimator's decision state, one-hot (:data:`estimators.evidence.DECISIONS`) | {0, 1} |
    | 7+H          | estimate_model_error         | -     | the statistic behind "model_mismatch" (running mean normalized steering innovation squared; 1 until the steering channel has data) | [0, 100] |
    | 8+H .. 13+H  | sensor_<channel>             | SI    | the six raw sensors of LaneKeepingEnv, at the last sample (IMU: mean over that sample) | as LaneKeepingEnv |
    | 14+H         | sensor_advisor_steering      | rad   | the human's wheel (road-wheel angle) as the estimator read it | [-(d_max+1), d_max+1] |

    ## Reward
    The lane-keeping env's, per env step: ``1 - w_y (y / 1.8)^2 - w_d (d_delta /
    d_max)^2``, ``d_delta`` the change of the applied steering over the step, minus
    ``offroad_penalty`` (10) on the step that leaves the road.

    ## Episode end
    | flag       | when                                                                |
    |------------|---------------------------------------------------------------------|
    | terminated | at any simulation sample of the step the car is past a road edge by more than offroad_margin, or faces backwards |
    | truncated  | simulated time reaches ``time_limit`` (30 s) at the end of a step (up to one step past it when the step does not divide it) |

    ## Info
    The same keys at ``reset`` and every ``step``
    (:data:`advisor_tasks.setup.ADVISOR_INFO_KEYS`):

    | key                          | unit  | what                                                   |
    |------------------------------|-------|--------------------------------------------------------|
    | LaneKeepingEnv's keys        | SI    | time, true state, bias, raw sensors (``sensor_*``)     |
    | estimate_* (as estimators.wrappers.estimate_info_keys) | SI | lateral offset and std, lateral and longitudinal velocity, bias, lane_index, weights (H,), mean and std (n,), decision (str) and decision_code, model_error, evidence_scale |
    | estimate_heading, estimate_speed | rad, m/s | as in the observation                          |
    | advisor_index                | -     | the human's index in the population (``env.unwrapped.setup.drivers``) |
    | advisor_steering             | rad   | the human's command over the last sample (at reset: the initial steering) |
    | sensor_advisor_steering      | rad   | the wheel reading the estimator took at the last sample |
    | policy_steering              | rad   | the action's road-wheel angle, clipped (at reset: the initial steering) |
    | substep_lateral_offset       | m     | (action_repeat,) true y after each sample (at reset: the initial y) |

    ## Randomness
    All from the env's generator, seeded by ``reset(seed=...)``: the lane-keeping
    env's draws (:func:`hasa_env.sim.setup.draw_episode`), then the advisor's index
    (always drawn, used when ``advisor.driver`` is "random"), the human's seed and the
    seed of the wheel sensor's noise. Reset options: the lane-keeping env's and
    ``advisor_index`` (an index into the population).

    ## Arguments
    ``gym.make("hasa_env/LaneKeepingAdvisor-v0", config={...}, render_mode=None)``;
    ``config`` is deep-merged onto :func:`advisor_tasks.setup.default_config` and
    validated (:func:`advisor_tasks.setup.describe_config` lists every key).
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 30}

    setup: AdvisorSetup
    make_setup = staticmethod(build_advisor_setup)
    scene_of = staticmethod(lambda setup: setup.env)

    def _init_env(self) -> None:
        env = self.setup.env
        self._bounds = self.setup.observation_bounds()
        self._estimator = self.setup.make_estimator()
        self._humans: dict[int, Any] = {}  # one single-car batch per advisor, reused
        self._wheel_noise = WheelNoise(1)
        self._steering_limit = env.steering_limit
        self._acc_low, self._acc_high = env.acceleration_limits
        self._wheel_std = env.noise_std.steering

    # ------------------------------------------------------------------ API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        setup = self.setup
        options = dict(options or {})
        chosen = pop_advisor_option(options, len(setup.drivers))
        rng = self.np_random
        car = self._car = start_car(rng, setup.env, options, self._curvature)
        drawn = int(rng.integers(len(setup.drivers)))
        human_seed, wheel_seed = (int(s) for s in rng.integers(0, 2**63 - 1, size=2))
        if chosen is None:
            chosen = drawn if setup.fixed_driver is None else setup.fixed_driver
        self._advisor = chosen
        human = self._humans.get(chosen)
        if human is None:
            human = self._humans[chosen] = human_batch([setup.drivers[chosen]])
        human.reset([human_seed], setup.dt)
        self._human = human
        self._wheel_noise.restart(np.array([0]), [wheel_seed])
        state = car.state
        self._command = state.steering
        self._policy_steering = state.steering
        self._wheel = self._wheel_reading(car, state.steering)
        self._substeps = [state.lateral_offset] * setup.env.action_repeat
        estimate = self._estimator.reset(
            self._measurement(car),
            setup.hypotheses,
            prior=setup.prior,
            true_bias=float(car.bias),
            **setup.road_points(np.array([state.station])),
        )
        self._readout = estimate_readout(estimate, setup.hypotheses)
        if self.render_mode == "human":
            self.render()
        return self._observation(car), self._info(car)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        car = started(self._car)
        setup = self.setup
        policy_steering, policy_acceleration = setup.action_to_physical(action, None)
        self._policy_steering = float(policy_steering)
        road = setup.env.road
        start_steering = car.state.steering
        off_road = False
        substeps = []
        estimate = None
        for _ in range(setup.env.action_repeat):
            command, steering, acceleration = self._human_sample(
                car, road, policy_steering, policy_acceleration
            )
            outcome = env_step(
                car.state,
                car.velocity,
                steering,
                acceleration,
                setup.sample,
                self._curvature,
                SCALAR_OPS,
                car.sim_step,
                car.phases,
            )
            off_road = off_road or bool(outcome.off_road)
            advance_car(car, outcome, acceleration, 1, self.np_random, setup.env, self._curvature)
            self._command = command
            self._wheel = self._wheel_reading(car, command)
            sensors = car.sensors
            estimate = self._estimator.step(
                self._measurement(car),
                np.array([[sensors.imu_longitudinal, sensors.imu_lateral]]),
                **setup.road_points(np.array([car.state.station])),
            )
            substeps.append(car.state.lateral_offset)
        self._substeps = substeps
        assert estimate is not None  # action_repeat >= 1: the loop ran
        self._readout = estimate_readout(estimate, setup.hypotheses)
        reward = step_reward(setup.env, start_steering, car.state, off_road)
        time_up = truncated(car, setup.env)
        if self.render_mode == "human":
            self.render()
        return self._observation(car), float(reward), off_road, time_up, self._info(car)

    @property
    def state(self) -> VehicleState | None:
        """The true Frenet state (None before the first reset)."""
        return None if self._car is None else self._car.state

    @property
    def estimator(self) -> Any:
        """The estimator (stepping at the simulation rate)."""
        return self._estimator

    # ------------------------------------------------------------- helpers
    def _human_sample(
        self, car: Car[float], road: Any, policy_steering: float, policy_acceleration: float
    ) -> tuple[float, float, float]:
        """The human's command at this sample, decided on the true state, and the
        (steering, acceleration) that drive the car: the human's, clipped, when the
        human drives; the policy's otherwise."""
        state = car.state
        info = {
            "time": np.array([car.sim_step * self.setup.dt]),
            "station": np.array([state.station]),
            "lateral_offset": np.array([state.lateral_offset]),
            "heading": np.array([state.heading]),
            "speed": np.array([state.speed]),
            "steering": np.array([state.steering]),
        }
        if self.setup.human_drives:
            command, human_acceleration = self._human.act(info, road)
            command = float(command[0])
            steering = min(max(command, -self._steering_limit), self._steering_limit)
            acceleration = min(max(float(human_acceleration[0]), self._acc_low), self._acc_high)
            return command, steering, acceleration
        command = float(self._human.steer(info, road)[0])
        return command, policy_steering, policy_acceleration

    def _wheel_reading(self, car: Car[float], command: float) -> float:
        """The steering sensor's reading of the human's wheel (rad)."""
        if self.setup.human_drives:  # the car's own steering sensor reads the human's wheel
            return car.sensors.steering
        return command + self._wheel_std * float(self._wheel_noise.draw()[0])

    def _measurement(self, car: Car[float]) -> np.ndarray:
        return np.array([[car.sensors.speed, car.sensors.camera_lateral, self._wheel]])

    def _observation(self, car: Car[float]) -> np.ndarray:
        sensors = np.array([car.sensors], dtype=np.float64)
        return observation_rows(self._readout, sensors, np.array([self._wheel]), self._bounds)[0]

    def _info(self, car: Car[float]) -> dict[str, Any]:
        values = car_info_values(car, self.setup.env)
        info: dict[str, Any] = dict(zip(INFO_KEYS, values, strict=True))
        for key, value in self._readout.items():
            row = value[0]
            if row.ndim:
                info[key] = row.copy()
            elif row.dtype.kind == "i":
                info[key] = int(row)
            elif row.dtype.kind == "U":
                info[key] = str(row)
            else:
                info[key] = float(row)
        info["advisor_index"] = self._advisor
        info["advisor_steering"] = float(self._command)
        info["sensor_advisor_steering"] = float(self._wheel)
        info["policy_steering"] = float(self._policy_steering)
        info["substep_lateral_offset"] = np.array(self._substeps, dtype=np.float64)
        return info
