"""Lane keeping with ambiguous lane markings: the single-car Gymnasium env."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from hasa_env.envs.base import LaneKeepingBase, SingleCarShell, started
from hasa_env.sim.car import Car, advance_car, start_car, state_values, truncated
from hasa_env.sim.dynamics import SCALAR_OPS, VehicleState
from hasa_env.sim.setup import build_setup, check_reset_options, physical_action
from hasa_env.sim.transition import env_step, step_reward

__all__ = ["LaneKeepingEnv"]


class LaneKeepingEnv(LaneKeepingBase, SingleCarShell, gym.Env):
    """A kinematic bicycle keeping its lane while the camera sees a biased lane.

    ## Description
    The car (paper eq. (1), docs/design.md §4.1; markings §3.5) starts off-centre in its lane
    (y = -0.5 m, v = 15 m/s by default) on a straight or curved road. Lane
    markings are ambiguous: the camera reports the lateral offset relative to
    one of several lane-centre hypotheses, ``y + b``, where the true bias ``b``
    is drawn per episode from ``config["markings"]["hypotheses"]``
    (default {0, -1.8} m) or fixed with ``reset(options={"bias_index": i})``.
    Simulation runs at ``sim_frequency`` (100 Hz); the policy acts every
    ``action_repeat`` samples. The observation is taken *after* the step.

    ## Action space
    ``Box(-1, 1, (2,), float32)`` by default (``action.type = "normalized"``),
    mapped linearly onto the physical limits; with ``"physical"`` the Box is in
    physical units. Out-of-range actions are clipped; NaN or inf raises
    ``ValueError``.

    | index | action                   | unit   | normalized -1 .. 1 maps to            |
    |-------|--------------------------|--------|---------------------------------------|
    | 0     | road-wheel angle delta   | rad    | -max_steering .. max_steering (0.5)   |
    | 1     | acceleration a           | m/s^2  | min_acceleration .. max_acceleration  |

    ## Observation space
    ``observation.type = "sensors"`` (default, what an autonomous car sees),
    ``Box(6,)`` float32; readings saturate at the bounds:

    | index | sensor            | unit   | measures                       | bounds             |
    |-------|-------------------|--------|--------------------------------|--------------------|
    | 0     | speed             | m/s    | v + noise                      | [-10, v_max + 10]  |
    | 1     | camera_lateral    | m      | y + b + noise (biased!)        | [-50, 50]          |
    | 2     | camera_heading    | rad    | theta + noise                  | [-pi, pi]          |
    | 3     | imu_longitudinal  | m/s^2  | mean d(v cos theta)/dt + noise | [-200, 200]        |
    | 4     | imu_lateral       | m/s^2  | mean d(v sin theta)/dt + noise | [-200, 200]        |
    | 5     | steering          | rad    | delta + noise                  | [-(d_max+1), ...]  |

    The IMU reports the road-frame acceleration averaged over the time since
    the previous observation (``action_repeat`` samples; the input of the
    paper's discrete model, eq. (4); docs/design.md §3.6). ``"state"`` (oracle), ``Box(5,)``:

    | index | state            | unit | bounds             |
    |-------|------------------|------|--------------------|
    | 0     | lateral_offset y | m    | [-50, 50]          |
    | 1     | heading theta    | rad  | [-pi, pi]          |
    | 2     | speed v          | m/s  | [0, v_max]         |
    | 3     | steering delta   | rad  | [-d_max, d_max]    |
    | 4     | road_curvature   | 1/m  | [-1, 1]            |

    ``"both"``: ``Dict(sensors=..., state=...)``.

    ## Reward
    Per env step: ``1 - w_y (y / 1.8)^2 - w_d (d_delta / d_max)^2``, minus
    ``offroad_penalty`` (10) on the step that leaves the road.

    ## Episode end
    | flag       | when                                                               |
    |------------|--------------------------------------------------------------------|
    | terminated | at any simulation sample of the step, the car is past a road edge by more than offroad_margin, or faces backwards |
    | truncated  | simulated time reaches ``time_limit`` (30 s, the paper's run length) at the end of a step: with an ``action_repeat`` whose step does not divide it, up to one step past it |

    ## Info
    The same keys at ``reset`` and every ``step`` (:data:`hasa_env.sim.setup.INFO_KEYS`):
    time (s), station (m), the true state, the applied acceleration,
    road_curvature, road-frame velocities, the true ``bias`` and ``bias_index``,
    and every raw (unclipped) sensor reading as ``sensor_<name>``.

    ## Arguments
    ``gym.make("hasa_env/LaneKeeping-v0", config={...}, render_mode=None)``;
    ``config`` is deep-merged onto :func:`hasa_env.default_config` and validated.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 30}

    make_setup = staticmethod(build_setup)

    def _init_env(self) -> None:
        self._bounds = {
            "sensors": [b.astype(np.float64).tolist() for b in self.setup.sensor_bounds()],
            "state": [b.astype(np.float64).tolist() for b in self.setup.state_bounds()],
        }
        self._ended = False  # the episode ended (terminated or truncated) without a reset since
        self._warned_ended = False

    # ------------------------------------------------------------------ API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        options = check_reset_options(options, self.setup)  # refused: nothing reseeded or drawn
        super().reset(seed=seed)
        self._ended = self._warned_ended = False
        car = self._car = start_car(self.np_random, self.setup, options, self._curvature)
        if self.render_mode == "human":
            self.render()
        return self._observation(car), self._info(car)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        car = started(self._car)
        setup = self.setup
        steer, acc = physical_action(setup, action)
        if self._ended and not self._warned_ended:
            gym.logger.warn(
                "step() called after the episode ended (terminated or truncated) without "
                "reset(): the car drives on past its end; call reset() to start a new episode"
            )
            self._warned_ended = True
        start_steering = car.state.steering
        outcome = env_step(
            car.state,
            car.velocity,
            steer,
            acc,
            setup,
            self._curvature,
            SCALAR_OPS,
            car.sim_step,
            car.phases,
        )
        advance_car(car, outcome, acc, setup.action_repeat, self.np_random, setup, self._curvature)
        reward = step_reward(setup, start_steering, outcome.state, outcome.off_road)
        terminated = bool(outcome.off_road)
        time_up = truncated(car, setup)
        self._ended = self._ended or terminated or time_up
        if self.render_mode == "human":
            self.render()
        return self._observation(car), float(reward), terminated, time_up, self._info(car)

    # ------------------------------------------------------------- helpers
    def _sensor_obs(self, car: Car) -> np.ndarray:
        return _clipped(car.sensors, *self._bounds["sensors"])

    def _state_obs(self, car: Car) -> np.ndarray:
        return _clipped(state_values(car), *self._bounds["state"])

    @property
    def state(self) -> VehicleState | None:
        """The true Frenet state (None before the first reset)."""
        return None if self._car is None else self._car.state


def _clipped(values: tuple, low: list[float], high: list[float]) -> np.ndarray:
    """float32 observation of ``values`` saturated at the bounds."""
    return np.array(
        [
            lo if v < lo else (hi if v > hi else v)
            for v, lo, hi in zip(values, low, high, strict=True)
        ],
        dtype=np.float32,
    )
