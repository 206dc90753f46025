"""A Stable-Baselines3 adapter for gymnasium vector envs: :class:`SB3VecEnv`.

SB3 expects *same-step* autoreset: the step that ends an episode returns the
*next* episode's first observation, with the last one in
``infos[i]["terminal_observation"]``. gymnasium's ``NEXT_STEP`` autoreset
(the native env's) instead returns the last observation and resets on the
following ``step``, ignoring that step's action. Feeding that to SB3
directly would add one fake transition per episode (an action that does
nothing, reward 0, across the episode boundary); the adapter avoids it by
resetting the finished cars at once, within the same SB3 step.

This module imports Stable-Baselines3 (and with it torch): it is the RL
extra's (``pip install 'hasa-env[rl]'``); ``hasa_env.rl.SB3VecEnv`` loads it
on first use.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from typing import Any, cast

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from hasa_env.envs.vector import LaneKeepingVectorEnv
from hasa_env.rl.evaluation import require_sb3

require_sb3()
from stable_baselines3.common.env_util import is_wrapped  # noqa: E402 - after the check
from stable_baselines3.common.vec_env.base_vec_env import VecEnv  # noqa: E402

__all__ = ["SB3VecEnv"]


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

    The base must be the native env, a vector env declaring ``partial_reset = True`` (the
    advisor task's), or gymnasium's sync / async vector env; wrappers in between must be
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
    native = isinstance(env, LaneKeepingVectorEnv) or getattr(env, "partial_reset", False)
    if not native and not isinstance(env, gym.vector.SyncVectorEnv | gym.vector.AsyncVectorEnv):
        raise TypeError(
            f"SB3VecEnv cannot tell whether a {type(env).__name__} supports "
            "reset(options={'reset_mask': ...}) in its autoreset mode; give it a SAME_STEP "
            "vector env instead"
        )


class SB3VecEnv(VecEnv):
    """Stable-Baselines3 ``VecEnv`` view of a gymnasium ``VectorEnv``.

    ``SB3VecEnv(gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point"))``
    (a subclass of SB3's ``VecEnv``). Observations, actions and spaces are the vector env's
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
        # SB3 types metadata as render modes only; gymnasium also keeps the autoreset mode.
        self.metadata = {**self.metadata, "autoreset_mode": AutoresetMode.SAME_STEP}  # type: ignore[dict-item]
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
        # Gymnasium types a vector reset's seed as one int; vector envs take one per env too.
        obs, info = self.venv.reset(seed=cast(Any, seed), options=options[0] or None)
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
            final_obs: Any = info.get("final_obs")
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

    def _per_env(self) -> gym.vector.SyncVectorEnv | gym.vector.AsyncVectorEnv | None:
        """The vector env if it holds separate env objects (gymnasium's sync / async), else None."""
        base = self.venv.unwrapped
        if isinstance(base, gym.vector.SyncVectorEnv | gym.vector.AsyncVectorEnv):
            return base
        return None

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """The attribute of each env; a native vector env shares one value for all cars."""
        idx = list(self._get_indices(indices))
        per_env = self._per_env()
        if per_env is not None:
            values = per_env.get_attr(attr_name)
            return [values[i] for i in idx]
        value = getattr(self.venv, attr_name)
        return [value for _ in idx]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Set an attribute; on a native vector env only for all cars at once."""
        idx = list(self._get_indices(indices))
        per_env = self._per_env()
        if per_env is not None:
            values = list(per_env.get_attr(attr_name))
            for i in idx:
                values[i] = value
            per_env.set_attr(attr_name, values)
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
        per_env = self._per_env()
        if per_env is None:
            raise NotImplementedError(
                f"env_method({method_name!r}): a {type(self.venv.unwrapped).__name__} has no "
                "per-env objects to call methods on"
            )
        results = per_env.call(method_name, *method_args, **method_kwargs)
        return [results[i] for i in idx]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: Any = None) -> list[bool]:
        """Whether each env is wrapped by ``wrapper_class`` (never, for a native vector env)."""
        idx = list(self._get_indices(indices))
        envs = getattr(self.venv.unwrapped, "envs", None)
        if envs is None:
            return [False for _ in idx]
        return [is_wrapped(envs[i], wrapper_class) for i in idx]

    def get_images(self) -> Sequence[np.ndarray | None]:
        if self.venv.render_mode != "rgb_array":
            return [None for _ in range(self.num_envs)]
        frames = self.venv.render()
        if frames is None:
            return [None for _ in range(self.num_envs)]
        return [np.asarray(frame) for frame in frames]
