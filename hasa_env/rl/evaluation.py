"""Evaluating policies: :func:`evaluate` runs a :class:`Policy` (an SB3 model
through :class:`SB3Policy`, a synthetic driver through :class:`DriverPolicy`,
or a :class:`ConstantSteering`) on seeded episodes and reports the lateral
error of the true state and the return; :func:`compare` tabulates several.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import asdict, dataclass
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np

from hasa_env.envs.base import hasa_unwrapped
from hasa_env.extras import install_hint
from hasa_env.rl.wrappers import env_action

__all__ = [
    "Policy",
    "SB3Policy",
    "DriverPolicy",
    "ConstantSteering",
    "EvalResult",
    "evaluate",
    "compare",
    "require_sb3",
]

_SB3_HINT = (
    f"Stable-Baselines3 is not installed; install the rl extra: {install_hint('rl')}; "
    "it needs torch, and a CPU wheel is enough"
)


def require_sb3() -> Any:
    """Import and return ``stable_baselines3``, or raise ImportError saying how to install it."""
    try:
        import stable_baselines3  # optional extra 'rl' (torch)
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise ImportError(_SB3_HINT) from exc
    return stable_baselines3


# ---------------------------------------------------------------- policies
@runtime_checkable
class Policy(Protocol):
    """What :func:`evaluate` runs: ``reset`` before each episode, then ``act`` every step."""

    name: str

    def reset(self, seed: int, env: gym.Env) -> None: ...

    def act(self, observation: Any, info: Mapping[str, Any]) -> np.ndarray: ...


class SB3Policy:
    """A trained Stable-Baselines3 model (``model.predict``, deterministic by default).

    ``normalize``: applied to each observation first, e.g. the ``normalize_obs`` of the
    ``VecNormalize`` the model was trained under (with its ``training`` set to False).
    """

    def __init__(
        self,
        model: Any,
        name: str = "ppo",
        deterministic: bool = True,
        normalize: Callable[[Any], Any] | None = None,
    ) -> None:
        self.model = model
        self.name = name
        self.deterministic = deterministic
        self.normalize = normalize

    def reset(self, seed: int, env: gym.Env) -> None:
        return None

    def act(self, observation: Any, info: Mapping[str, Any]) -> np.ndarray:
        if self.normalize is not None:
            observation = self.normalize(observation)
        action, _ = self.model.predict(observation, deterministic=self.deterministic)
        return action


class ConstantSteering:
    """Hold a road-wheel angle (rad, default 0: "zero steering") at 0 m/s^2."""

    def __init__(self, steering: float = 0.0, name: str = "zero steering") -> None:
        if not math.isfinite(steering):
            raise ValueError(f"steering must be finite, got {steering!r}")
        self.steering = float(steering)
        self.name = name
        self._env: gym.Env | None = None

    def reset(self, seed: int, env: gym.Env) -> None:
        self._env = env

    def act(self, observation: Any, info: Mapping[str, Any]) -> np.ndarray:
        if self._env is None:
            raise RuntimeError("call reset(seed, env) before act()")
        return env_action(self._env, self.steering, 0.0)


class DriverPolicy:
    """A :class:`hasa_env.drivers.Driver` (e.g. a synthetic human) acting on the true ``info``.

    The driver is reset with the episode's seed and the env step
    (``action_repeat / sim_frequency`` s); its physical command is mapped into
    the env's action space by :func:`env_action`.
    """

    def __init__(self, driver: Any, name: str | None = None) -> None:
        self.driver = driver
        self.name = name or f"driver {getattr(driver, 'name', type(driver).__name__)}"
        self._env: gym.Env | None = None

    def reset(self, seed: int, env: gym.Env) -> None:
        setup = hasa_unwrapped(env).setup
        self.driver.reset(seed, dt=setup.dt * setup.action_repeat)
        self._env = env

    def act(self, observation: Any, info: Mapping[str, Any]) -> np.ndarray:
        if self._env is None:
            raise RuntimeError("call reset(seed, env) before act()")
        steering, acceleration = self.driver.act(info, hasa_unwrapped(self._env).setup.road)
        return env_action(self._env, steering, acceleration)


# -------------------------------------------------------------- evaluation
@dataclass(frozen=True)
class EvalResult:
    """Evaluation of one policy over seeded episodes.

    Attributes:
        name: the policy's name.
        episodes: number of episodes.
        mean_abs_lateral_error: mean |y| (m) of the true lateral offset over
            every step of every episode (the reset state excluded).
        rms_lateral_error: root mean square of y (m) over the same steps.
        mean_return: mean undiscounted episode return.
        std_return: standard deviation of the episode returns.
        offroad_rate: fraction of episodes that ended by leaving the road.
        mean_duration: mean simulated episode length (s).
    """

    name: str
    episodes: int
    mean_abs_lateral_error: float
    rms_lateral_error: float
    mean_return: float
    std_return: float
    offroad_rate: float
    mean_duration: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def line(self) -> str:
        """One formatted line for a results table."""
        return (
            f"{self.name:28s} mean |y| {self.mean_abs_lateral_error:6.3f} m  "
            f"RMS y {self.rms_lateral_error:6.3f} m  return {self.mean_return:8.2f} "
            f"+- {self.std_return:6.2f}  off-road {100 * self.offroad_rate:5.1f} %  "
            f"length {self.mean_duration:5.1f} s"
        )


def evaluate(
    policy: Policy,
    make_env: Callable[[], gym.Env],
    episodes: int = 10,
    seed: int = 0,
    balance_hypotheses: bool = True,
) -> EvalResult:
    """Run ``policy`` for ``episodes`` episodes in one env from ``make_env()``.

    Episode k is reset with ``seed + k`` (the same episodes for every policy
    given the same seed) and, with ``balance_hypotheses``, with the true lane
    hypothesis ``k mod C`` (``options={"bias_index": ...}``), so each
    hypothesis is driven equally often. The lateral error is the *true*
    offset ``info["lateral_offset"]`` (m), whatever the policy observes, at
    every simulation sample (every sub-step under :class:`ActionRepeat`).
    """
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    env = make_env()
    try:
        setup = hasa_unwrapped(env).setup
        n_hyp = len(setup.hypotheses)
        returns: list[float] = []
        offsets: list[float] = []
        offroad = 0
        durations: list[float] = []
        for k in range(episodes):
            options = {"bias_index": k % n_hyp} if balance_hypotheses else None
            obs, info = env.reset(seed=seed + k, options=options)
            policy.reset(seed + k, env)
            total = 0.0
            done = False
            while not done:
                obs, reward, terminated, truncated, info = env.step(policy.act(obs, info))
                total += float(reward)
                if "substep_lateral_offset" in info:
                    offsets.extend(np.asarray(info["substep_lateral_offset"]).tolist())
                else:
                    offsets.append(float(info["lateral_offset"]))
                done = terminated or truncated
            returns.append(total)
            offroad += int(terminated)
            durations.append(float(info["time"]))
    finally:
        env.close()
    y = np.asarray(offsets)
    return EvalResult(
        name=policy.name,
        episodes=episodes,
        mean_abs_lateral_error=float(np.mean(np.abs(y))),
        rms_lateral_error=float(np.sqrt(np.mean(y * y))),
        mean_return=float(np.mean(returns)),
        std_return=float(np.std(returns)),
        offroad_rate=offroad / episodes,
        mean_duration=float(np.mean(durations)),
    )


def compare(
    policies: Iterable[Policy], make_env: Callable[[], gym.Env], episodes: int = 10, seed: int = 0
) -> list[EvalResult]:
    """:func:`evaluate` every policy on the same seeded episodes."""
    return [evaluate(p, make_env, episodes, seed) for p in policies]
