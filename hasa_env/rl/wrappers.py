"""Wrappers for RL: steering-only actions, action repeat, a human advisor steering alongside.

- :func:`make_vector_env`: a native vector env by id (optionally steering only).
- :class:`SteeringOnly` / :class:`VectorSteeringOnly`: the policy steers,
  the acceleration is held at 0 m/s^2 (the reward has no speed term, so a
  policy that may brake learns to stop the car, which trivially keeps the lane).
- :class:`ActionRepeat`, :class:`HumanAdvisor`, :func:`env_action`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import VectorEnv

from hasa_env.envs.base import hasa_unwrapped
from hasa_env.envs.vector import LaneKeepingVectorEnv

__all__ = [
    "make_vector_env",
    "SteeringOnly",
    "VectorSteeringOnly",
    "ActionRepeat",
    "HumanAdvisor",
    "env_action",
]


def make_vector_env(
    env_id: str = "hasa_env/LaneKeeping-v0",
    num_envs: int = 8,
    config: Mapping[str, Any] | None = None,
    steering_only: bool = False,
) -> VectorEnv:
    """A native vector env of ``env_id`` (it resets single cars with ``reset_mask``).

    ``steering_only`` wraps it in :class:`VectorSteeringOnly`. The registered
    id only chooses the default track (``config["track"]`` wins), as with
    ``gym.make_vec(env_id, vectorization_mode="vector_entry_point")``.
    """
    spec = gym.spec(env_id)
    if spec.vector_entry_point != "hasa_env.envs.vector:LaneKeepingVectorEnv":
        raise ValueError(
            f"{env_id!r} is not one of the lane-keeping env's ids (its vector entry point is "
            f"{spec.vector_entry_point!r}); make any id's native vector env with "
            f"gym.make_vec({env_id!r}, num_envs=N, vectorization_mode='vector_entry_point')"
        )
    env: VectorEnv = LaneKeepingVectorEnv(
        num_envs=num_envs, config=config, track=spec.kwargs.get("track")
    )
    env.spec = spec
    return VectorSteeringOnly(env) if steering_only else env


# ----------------------------------------------------------------- actions
def _neutral_acceleration(base: Any) -> float:
    """The action value meaning 0 m/s^2 in the env's action space."""
    setup = base.setup
    lo, hi = setup.acceleration_limits
    if setup.normalized_actions:
        return 2.0 * (0.0 - lo) / (hi - lo) - 1.0
    return 0.0


def _steering_space(space: spaces.Space) -> spaces.Box:
    if not isinstance(space, spaces.Box):
        raise TypeError(f"a steering-only action needs a Box action space, got {space}")
    return spaces.Box(space.low[:1], space.high[:1], dtype=space.dtype)


class SteeringOnly(gym.ActionWrapper):
    """The agent chooses the steering only; the acceleration is 0 m/s^2.

    Action space: ``Box(1,)``, the first element of the env's (normalized
    -1..1, or road-wheel angle in rad with ``action.type = "physical"``).
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        if not hasattr(env.unwrapped, "setup"):
            name = type(env.unwrapped).__name__
            raise TypeError(f"SteeringOnly needs a hasa_env env, got {name}")
        self.action_space = _steering_space(env.action_space)
        self._acceleration = _neutral_acceleration(env.unwrapped)

    def action(self, action: Any) -> np.ndarray:
        steer = np.asarray(action, dtype=np.float64).reshape(-1)
        if steer.shape != (1,):
            raise ValueError(f"SteeringOnly action must have shape (1,), got {np.shape(action)}")
        return np.array([steer[0], self._acceleration])


class VectorSteeringOnly(gym.vector.VectorActionWrapper):
    """:class:`SteeringOnly` for a (native) vector env: actions (N, 1) -> (N, 2)."""

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        if not hasattr(env.unwrapped, "setup"):
            name = type(env.unwrapped).__name__
            raise TypeError(f"VectorSteeringOnly needs a hasa_env vector env, got {name}")
        self.single_action_space = _steering_space(env.single_action_space)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, env.num_envs)
        self._acceleration = _neutral_acceleration(env.unwrapped)

    def actions(self, actions: Any) -> np.ndarray:
        steer = np.asarray(actions, dtype=np.float64)
        if steer.shape not in ((self.num_envs, 1), (self.num_envs,)):
            raise ValueError(
                f"VectorSteeringOnly actions must have shape ({self.num_envs}, 1), "
                f"got {steer.shape}"
            )
        steer = steer.reshape(self.num_envs)
        return np.column_stack([steer, np.full(self.num_envs, self._acceleration)])


class ActionRepeat(gym.Wrapper):
    """Hold each action for ``repeat`` steps of the wrapped env (frame skip).

    Use it when the policy must act slower than the env steps but the env
    itself cannot use ``config["action_repeat"]``: e.g. under an estimator
    wrapper, which needs every 1 / sim_frequency sample. The reward is the
    sum of the sub-steps' rewards; the observation and info are the last
    sub-step's, and ``info["substep_lateral_offset"]`` holds the true lateral
    offset y (m) after each sub-step. The repeat stops early when the episode
    ends.
    """

    def __init__(self, env: gym.Env, repeat: int) -> None:
        super().__init__(env)
        if isinstance(repeat, bool) or not isinstance(repeat, int | np.integer) or repeat < 1:
            raise ValueError(f"repeat must be a positive integer, got {repeat!r}")
        self.repeat = int(repeat)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        total = 0.0
        offsets = []
        for _ in range(self.repeat):
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            offsets.append(float(info["lateral_offset"]))
            if terminated or truncated:
                break
        info = dict(info)
        info["substep_lateral_offset"] = np.array(offsets)
        return obs, total, terminated, truncated, info


class HumanAdvisor(gym.Wrapper):
    """A (synthetic) human advises by steering: ``info["sensor_steering"]`` becomes theirs.

    The human-as-advisor estimator reads the human's steering to tell which
    lane is real. When a policy drives, the env's steering sensor measures the
    *policy's* steering, which carries no information about the true lane. This
    wrapper runs ``driver`` (a :class:`hasa_env.drivers.Driver`, acting on the
    true ``info`` like a human who sees the real markings) alongside the policy
    and reports its steering as the steering measurement, with the timing of a
    human driving: row k's ``sensor_steering`` is the driver's command decided
    at row k-1 (row 0: the env's own reading), plus the env's steering-sensor
    noise (``config["noise"]["steering"]``, rad). The env's reading of the
    applied road-wheel angle stays in ``info["sensor_steering_applied"]`` (rad).
    The driver does not act on the car.

    The driver is reset every episode with a seed drawn from this wrapper's
    generator, itself seeded by ``reset(seed=...)``.
    """

    def __init__(self, env: gym.Env, driver: Any) -> None:
        super().__init__(env)
        base = env.unwrapped
        if not hasattr(base, "setup"):
            raise TypeError(f"HumanAdvisor needs a hasa_env env, got {type(base).__name__}")
        if not callable(getattr(driver, "act", None)) or not callable(
            getattr(driver, "reset", None)
        ):
            raise TypeError("driver must have reset(seed, dt=...) and act(info, road) methods")
        self.driver = driver
        self._rng = np.random.default_rng()
        self._command = 0.0
        self._noise_std = float(hasa_unwrapped(base).config["noise"]["steering"])

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        setup = hasa_unwrapped(self.env).setup
        self.driver.reset(int(self._rng.integers(0, 2**31 - 1)), dt=setup.dt * setup.action_repeat)
        info = dict(info)
        info["sensor_steering_applied"] = info["sensor_steering"]
        self._command = self._decide(info)
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        info = dict(info)
        info["sensor_steering_applied"] = info["sensor_steering"]
        noise = self._noise_std * float(self._rng.standard_normal())
        info["sensor_steering"] = self._command + noise
        self._command = self._decide(info)
        return obs, float(reward), terminated, truncated, info

    @property
    def command(self) -> float:
        """The human's steering (rad) decided at the last row, reported at the next step."""
        return self._command

    def _decide(self, info: Mapping[str, Any]) -> float:
        steering, _ = self.driver.act(info, hasa_unwrapped(self.env).setup.road)
        if not math.isfinite(steering):
            raise RuntimeError(f"the advising driver returned a non-finite steering {steering!r}")
        return float(steering)


def env_action(env: gym.Env, steering: float, acceleration: float) -> np.ndarray:
    """A physical command (road-wheel angle rad, acceleration m/s^2) in ``env``'s action space.

    Handles normalized and physical action types and :class:`SteeringOnly`
    (whose action is the steering alone; the acceleration is then dropped).
    """
    setup = hasa_unwrapped(env).setup
    limit = setup.steering_limit
    lo, hi = setup.acceleration_limits
    if setup.normalized_actions:
        action = np.array([steering / limit, 2.0 * (acceleration - lo) / (hi - lo) - 1.0])
    else:
        action = np.array([steering, acceleration], dtype=np.float64)
    shape = env.action_space.shape
    if shape == (1,):
        return action[:1].astype(env.action_space.dtype)
    if shape != (2,):
        raise ValueError(f"env_action: unexpected action space {env.action_space}")
    return action.astype(env.action_space.dtype)
