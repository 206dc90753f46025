"""Reinforcement learning on the lane-keeping envs: an SB3 adapter, wrappers, evaluation.

- :class:`SB3VecEnv` (:mod:`~hasa_env.rl.sb3`) turns a gymnasium
  ``VectorEnv`` into Stable-Baselines3's ``VecEnv`` with same-step
  autoreset; it imports Stable-Baselines3 (and torch, the RL extra), so it
  is loaded on first access.
- :mod:`~hasa_env.rl.wrappers`: :func:`make_vector_env`,
  :class:`SteeringOnly` / :class:`VectorSteeringOnly`, :class:`ActionRepeat`,
  :class:`HumanAdvisor`, :func:`env_action`.
- :mod:`~hasa_env.rl.evaluation`: :func:`evaluate` and :func:`compare` of
  policies (:class:`SB3Policy`, :class:`DriverPolicy`, :class:`ConstantSteering`).
- :class:`HumanPool` (:mod:`~hasa_env.rl.humans`): synthetic humans for the N cars of a
  vector env, each car's human chosen per episode (as the human-as-advisor task's vector
  env uses them).
"""

from hasa_env._lazy import lazy_attributes
from hasa_env.rl.evaluation import (
    ConstantSteering,
    DriverPolicy,
    EvalResult,
    Policy,
    SB3Policy,
    compare,
    evaluate,
    require_sb3,
)
from hasa_env.rl.humans import HumanPool
from hasa_env.rl.wrappers import (
    ActionRepeat,
    HumanAdvisor,
    SteeringOnly,
    VectorSteeringOnly,
    env_action,
    make_vector_env,
)

__all__ = [
    "ActionRepeat",
    "ConstantSteering",
    "DriverPolicy",
    "EvalResult",
    "HumanAdvisor",
    "HumanPool",
    "Policy",
    "SB3Policy",
    "SB3VecEnv",  # noqa: F822 - a lazy attribute (see below)
    "SteeringOnly",
    "VectorSteeringOnly",
    "compare",
    "env_action",
    "evaluate",
    "make_vector_env",
    "require_sb3",
]

# SB3VecEnv imports Stable-Baselines3 and torch (optional, ~2 s): loaded on first access
__getattr__, __dir__ = lazy_attributes(
    __name__, {"SB3VecEnv": "hasa_env.rl.sb3"}, eager=[n for n in __all__ if n != "SB3VecEnv"]
)
