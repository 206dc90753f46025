"""The Gymnasium environments: :class:`~hasa_env.envs.lane_keeping.LaneKeepingEnv`
(one car) and :class:`~hasa_env.envs.vector.LaneKeepingVectorEnv` (N cars as
arrays), both stepping through :func:`hasa_env.sim.transition.env_step`.
"""

from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.envs.vector import LaneKeepingVectorEnv

__all__ = ["LaneKeepingEnv", "LaneKeepingVectorEnv"]
