"""Reinforcement-learning helpers: a Stable-Baselines3 adapter, action wrappers, evaluation.

- :class:`SB3VecEnv` turns a gymnasium ``VectorEnv`` (the native
  :class:`hasa_env.LaneKeepingVectorEnv`, or gymnasium's sync / async vector
  envs) into Stable-Baselines3's ``VecEnv`` API. SB3 expects *same-step*
  autoreset: the step that ends an episode returns the *next* episode's first
  observation, with the last one in ``infos[i]["terminal_observation"]``.
  gymnasium's ``NEXT_STEP`` autoreset (the native env's) instead returns the
  last observation and resets on the following ``step``, ignoring that
  step's action. Feeding that to SB3 directly would add one fake transition
  per episode (an action that does nothing, reward 0, across the episode
  boundary); the adapter avoids it by resetting the finished cars at once,
  within the same SB3 step.
- :class:`SteeringOnly` / :class:`VectorSteeringOnly`: the policy steers,
  the acceleration is held at 0 m/s^2 (the reward has no speed term, so a
  policy that may brake learns to stop the car, which trivially keeps the lane).
- :func:`evaluate` runs a :class:`Policy` (an SB3 model through
  :class:`SB3Policy`, a synthetic driver through :class:`DriverPolicy`, or a
  :class:`ConstantSteering`) on seeded episodes and reports the lateral
  error of the true state and the return.

Stable-Baselines3 (and torch) are optional: :class:`SB3VecEnv` and
:class:`SB3Policy` import them when used; the rest needs only gymnasium.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv

from hasa_env.vector import LaneKeepingVectorEnv

__all__ = [
    "SB3VecEnv",  # noqa: F822 - built on first access by the module __getattr__
    "make_vector_env",
    "SteeringOnly",
    "VectorSteeringOnly",
    "ActionRepeat",
    "HumanAdvisor",
    "Policy",
    "SB3Policy",
    "DriverPolicy",
    "ConstantSteering",
    "EvalResult",
    "evaluate",
    "env_action",
    "require_sb3",
]

_SB3_HINT = (
    "Stable-Baselines3 is not installed; install the RL extra: pip install 'hasa-env[rl]' "
    "(it needs torch; a CPU wheel is enough)"
)


def require_sb3() -> Any:
    """Import and return ``stable_baselines3``, or raise ImportError saying how to install it."""
    try:
        import stable_baselines3
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise ImportError(_SB3_HINT) from exc
    return stable_baselines3


def _vec_env_base() -> type:
    require_sb3()
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv

    return VecEnv


# ------------------------------------------------------------ observations
def _obs_row(obs: Any, i: int) -> Any:
    """Row ``i`` of a batched observation (array or dict of arrays), copied."""
    if isinstance(obs, Mapping):
        return {k: _obs_row(v, i) for k, v in obs.items()}
    return np.array(obs[i], copy=True)


def _obs_put(dst: Any, src: Any, mask: np.ndarray) -> Any:
    """``dst`` with the rows ``mask`` taken from ``src`` (arrays or dicts of arrays)."""
    if isinstance(dst, Mapping):
        return {k: _obs_put(dst[k], src[k], mask) for k in dst}
    out = np.array(dst, copy=True)
    out[mask] = np.asarray(src)[mask]
    return out


def _info_rows(info: Mapping[str, Any], n: int) -> list[dict[str, Any]]:
    """gymnasium's vector info (dict of arrays + ``_key`` masks) as one dict per env."""
    rows: list[dict[str, Any]] = [{} for _ in range(n)]
    for key, value in info.items():
        if key.startswith("_"):
            continue
        mask = info.get("_" + key)
        mask = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        if isinstance(value, Mapping):  # nested vector info, e.g. "final_info"
            sub = _info_rows(value, n)
            for i in np.flatnonzero(mask).tolist():
                rows[i][key] = sub[i]
            continue
        for i in np.flatnonzero(mask).tolist():
            item = value[i]
            rows[i][key] = item.item() if isinstance(item, np.generic) else item
    return rows


def _autoreset_mode(venv: VectorEnv) -> AutoresetMode:
    mode = venv.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
    if isinstance(mode, str):
        mode = AutoresetMode(mode)
    return mode


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
    if spec.vector_entry_point != "hasa_env.vector:LaneKeepingVectorEnv":
        raise ValueError(
            f"{env_id!r} is not a hasa_env id (vector entry point {spec.vector_entry_point!r})"
        )
    env: VectorEnv = LaneKeepingVectorEnv(
        num_envs=num_envs, config=config, track=spec.kwargs.get("track")
    )
    env.spec = spec
    return VectorSteeringOnly(env) if steering_only else env


def _partial_reset(venv: VectorEnv, mask: np.ndarray) -> tuple[Any, dict[str, Any]]:
    """Reset only the envs in ``mask`` now (gymnasium's ``reset(options={"reset_mask": mask})``)."""
    return venv.reset(options={"reset_mask": np.asarray(mask, dtype=np.bool_)})


_STATELESS_WRAPPERS = (
    gym.vector.VectorActionWrapper,
    gym.vector.VectorObservationWrapper,
    gym.vector.VectorRewardWrapper,
)
"""Vector wrappers whose ``reset`` only passes a partial reset through (no per-env state)."""


def _check_partial_reset(venv: VectorEnv, trusted: tuple[type, ...]) -> None:
    """Raise unless every layer of ``venv`` resets a subset of envs correctly.

    The base must be the native env or gymnasium's sync / async vector env; wrappers in between must be
    stateless action / observation / reward wrappers, or in ``trusted``.
    """
    env: Any = venv
    while isinstance(env, gym.vector.VectorWrapper):
        if not isinstance(env, _STATELESS_WRAPPERS + trusted):
            raise TypeError(
                f"SB3VecEnv resets finished envs with reset(options={{'reset_mask': ...}}), but "
                f"the vector wrapper {type(env).__name__} may keep per-env state that such a "
                "partial reset would break. Apply it to single envs inside a gymnasium "
                "SyncVectorEnv (or SB3's DummyVecEnv), or, if it handles reset_mask, pass "
                f"SB3VecEnv(venv, trusted_wrappers=({type(env).__name__},))."
            )
        env = env.env
    if not isinstance(
        env, LaneKeepingVectorEnv | gym.vector.SyncVectorEnv | gym.vector.AsyncVectorEnv
    ):
        raise TypeError(
            f"SB3VecEnv cannot tell whether a {type(env).__name__} supports "
            "reset(options={'reset_mask': ...}) in its autoreset mode; give it a SAME_STEP "
            "vector env instead"
        )


class _SB3VecEnvBody:
    """Stable-Baselines3 ``VecEnv`` view of a gymnasium ``VectorEnv``.

    ``SB3VecEnv(gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point"))``
    (a subclass of SB3's ``VecEnv``; ``hasa_env.rl.SB3VecEnv`` imports SB3 on
    first access). Observations, actions and spaces are the vector env's
    single spaces; rewards are float32, ``dones = terminated | truncated``,
    and ``infos`` is a list of dicts (each env's info of that step) with
    ``"TimeLimit.truncated"`` and, when an episode ended,
    ``"terminal_observation"``. The observation returned for an env whose
    episode just ended is the first observation of its next episode, as with
    SB3's ``DummyVecEnv`` (same-step autoreset); that episode's reset info is
    in ``reset_infos[i]``.

    Autoreset modes: ``SAME_STEP`` vector envs are converted directly
    (``final_obs`` / ``final_info``). ``NEXT_STEP`` (the native env) and
    ``DISABLED`` vector envs have their finished envs reset within the same
    SB3 step, with the same random draws the env's own autoreset would make,
    so the episodes are those of SB3's ``DummyVecEnv`` over single envs
    seeded ``seed + i`` (``seed(seed)`` then ``reset()``).

    The partial reset is gymnasium's ``reset(options={"reset_mask": m})``.
    Vector wrappers between the adapter and the base env must pass it on
    correctly: stateless action, observation and reward wrappers do; any
    other wrapper is refused unless listed in ``trusted_wrappers``.

    ``seed()`` and ``set_options()`` apply at the next ``reset()``; a
    gymnasium vector env takes one options dict for all envs.
    """

    def __init__(self, venv: VectorEnv, trusted_wrappers: Sequence[type] = ()) -> None:
        if not isinstance(venv, VectorEnv):
            raise TypeError(f"SB3VecEnv needs a gymnasium VectorEnv, got {type(venv).__name__}")
        self.venv = venv
        self.autoreset_mode = _autoreset_mode(venv)
        if self.autoreset_mode != AutoresetMode.SAME_STEP:
            _check_partial_reset(venv, tuple(trusted_wrappers))
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self.metadata = {**self.metadata, "autoreset_mode": AutoresetMode.SAME_STEP}
        self._actions: np.ndarray | None = None
        self._obs: Any = None

    # ------------------------------------------------------------- VecEnv API
    def reset(self) -> Any:
        """Reset every env; uses and then forgets the seeds of ``seed()`` and ``set_options()``."""
        seeds = list(self._seeds)
        seed: list[int | None] | None = None if all(s is None for s in seeds) else seeds
        options = [dict(o) for o in self._options]
        if any(o != options[0] for o in options[1:]):
            raise ValueError(
                "SB3VecEnv: a gymnasium VectorEnv takes one options dict for all envs; "
                f"set_options() got different ones: {options}"
            )
        obs, info = self.venv.reset(seed=seed, options=options[0] or None)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = _info_rows(info, self.num_envs)
        self._obs = obs
        return copy.deepcopy(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async()")
        actions, self._actions = self._actions, None
        obs, rewards, terminated, truncated, info = self.venv.step(actions)
        terminated = np.asarray(terminated, dtype=bool)
        truncated = np.asarray(truncated, dtype=bool)
        dones = terminated | truncated
        n = self.num_envs
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            infos = _info_rows(info, n)
            final_obs = info.get("final_obs")
            for i in np.flatnonzero(dones).tolist():
                step_info = dict(infos[i].get("final_info", {}))
                self.reset_infos[i] = {
                    k: v for k, v in infos[i].items() if k not in ("final_obs", "final_info")
                }
                step_info["terminal_observation"] = final_obs[i]
                infos[i] = step_info
        else:
            infos = _info_rows(info, n)
            if dones.any():
                for i in np.flatnonzero(dones).tolist():
                    infos[i]["terminal_observation"] = _obs_row(obs, i)
                reset_obs, reset_info = _partial_reset(self.venv, dones)
                obs = _obs_put(obs, reset_obs, dones)
                reset_rows = _info_rows(reset_info, n)
                for i in np.flatnonzero(dones).tolist():
                    self.reset_infos[i] = reset_rows[i]
        for i in range(n):
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        self._obs = obs
        return (
            copy.deepcopy(obs),
            np.asarray(rewards, dtype=np.float32),
            dones,
            infos,
        )

    def close(self) -> None:
        self.venv.close()

    def _per_env(self) -> bool:
        """True if the vector env holds separate env objects (gymnasium's sync / async)."""
        return isinstance(self.venv.unwrapped, gym.vector.SyncVectorEnv | gym.vector.AsyncVectorEnv)

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """The attribute of each env; a native vector env shares one value for all cars."""
        idx = list(self._get_indices(indices))
        if self._per_env():
            values = self.venv.unwrapped.get_attr(attr_name)
            return [values[i] for i in idx]
        value = getattr(self.venv, attr_name)
        return [value for _ in idx]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Set an attribute; on a native vector env only for all cars at once."""
        idx = list(self._get_indices(indices))
        if self._per_env():
            values = list(self.venv.unwrapped.get_attr(attr_name))
            for i in idx:
                values[i] = value
            self.venv.unwrapped.set_attr(attr_name, values)
            return
        if sorted(idx) != list(range(self.num_envs)):
            raise ValueError(
                f"set_attr({attr_name!r}) on a native vector env applies to all cars at once; "
                f"got indices {idx}"
            )
        setattr(self.venv.unwrapped, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call a method of each env (gymnasium's ``VectorEnv.call``)."""
        idx = list(self._get_indices(indices))
        if not self._per_env():
            raise NotImplementedError(
                f"env_method({method_name!r}): a {type(self.venv.unwrapped).__name__} has no "
                "per-env objects to call methods on"
            )
        results = self.venv.unwrapped.call(method_name, *method_args, **method_kwargs)
        return [results[i] for i in idx]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: Any = None) -> list[bool]:
        """Whether each env is wrapped by ``wrapper_class`` (never, for a native vector env)."""
        idx = list(self._get_indices(indices))
        envs = getattr(self.venv.unwrapped, "envs", None)
        if envs is None:
            return [False for _ in idx]
        from stable_baselines3.common.env_util import is_wrapped

        return [is_wrapped(envs[i], wrapper_class) for i in idx]

    def get_images(self) -> Sequence[np.ndarray | None]:
        if self.venv.render_mode != "rgb_array":
            return [None for _ in range(self.num_envs)]
        frames = self.venv.render()
        return list(frames) if frames is not None else [None for _ in range(self.num_envs)]


def __getattr__(name: str) -> Any:
    """PEP 562: build :class:`SB3VecEnv` on first access (imports Stable-Baselines3 and torch)."""
    if name == "SB3VecEnv":
        cls = type(
            "SB3VecEnv",  # noqa: F822 - built on first access by the module __getattr__
            (_SB3VecEnvBody, _vec_env_base()),
            {"__module__": __name__, "__doc__": _SB3VecEnvBody.__doc__},
        )
        globals()["SB3VecEnv"] = cls
        return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ----------------------------------------------------------------- actions
def _neutral_acceleration(base: Any) -> float:
    """The action value meaning 0 m/s^2 in the env's action space."""
    setup = base.setup
    lo, hi = setup.acceleration_limits
    if setup.normalized_actions:
        return 2.0 * (0.0 - lo) / (hi - lo) - 1.0
    return 0.0


def _steering_space(space: spaces.Box) -> spaces.Box:
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
        self._noise_std = float(base.config["noise"]["steering"])

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        setup = self.env.unwrapped.setup
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
        return obs, reward, terminated, truncated, info

    @property
    def command(self) -> float:
        """The human's steering (rad) decided at the last row, reported at the next step."""
        return self._command

    def _decide(self, info: Mapping[str, Any]) -> float:
        steering, _ = self.driver.act(info, self.env.unwrapped.setup.road)
        if not math.isfinite(steering):
            raise RuntimeError(f"the advising driver returned a non-finite steering {steering!r}")
        return float(steering)


def env_action(env: gym.Env, steering: float, acceleration: float) -> np.ndarray:
    """A physical command (road-wheel angle rad, acceleration m/s^2) in ``env``'s action space.

    Handles normalized and physical action types and :class:`SteeringOnly`
    (whose action is the steering alone; the acceleration is then dropped).
    """
    setup = env.unwrapped.setup
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


# ---------------------------------------------------------------- policies
@runtime_checkable
class Policy(Protocol):
    """What :func:`evaluate` runs: ``reset`` before each episode, then ``act`` every step."""

    name: str

    def reset(self, seed: int, env: gym.Env) -> None: ...

    def act(self, observation: Any, info: Mapping[str, Any]) -> np.ndarray: ...


class SB3Policy:
    """A trained Stable-Baselines3 model (``model.predict``, deterministic by default)."""

    def __init__(self, model: Any, name: str = "ppo", deterministic: bool = True) -> None:
        self.model = model
        self.name = name
        self.deterministic = deterministic

    def reset(self, seed: int, env: gym.Env) -> None:
        return None

    def act(self, observation: Any, info: Mapping[str, Any]) -> np.ndarray:
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
        setup = env.unwrapped.setup
        self.driver.reset(seed, dt=setup.dt * setup.action_repeat)
        self._env = env

    def act(self, observation: Any, info: Mapping[str, Any]) -> np.ndarray:
        if self._env is None:
            raise RuntimeError("call reset(seed, env) before act()")
        steering, acceleration = self.driver.act(info, self._env.unwrapped.setup.road)
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
        setup = env.unwrapped.setup
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
