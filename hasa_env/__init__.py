"""hasa-env: human-as-advisor lane keeping (Mai et al.), a Gymnasium environment.

Importing ``hasa_env`` registers the environment ids:

- ``hasa_env/LaneKeeping-v0``: straight road;
- ``hasa_env/LaneKeepingCurved-v0``: the shipped curved track.

Both have a native vector entry point
(``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``).
The package's layers (docs/design.md §2): :mod:`hasa_env.sim` (config, road,
dynamics, the pure transition) at the bottom, then :mod:`hasa_env.steering`,
:mod:`hasa_env.render` and :mod:`hasa_env.devices`, :mod:`hasa_env.envs`,
:mod:`hasa_env.recording`, :mod:`hasa_env.drivers`, and :mod:`hasa_env.rl`
and :mod:`hasa_env.session` at the top.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from hasa_env._lazy import lazy_attributes
from hasa_env.envs.base import register_track_ids
from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.envs.vector import LaneKeepingVectorEnv
from hasa_env.sim.config import ConfigError, default_config, describe_config, make_config

try:
    __version__ = version("hasa-env")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

ENV_IDS = ("hasa_env/LaneKeeping-v0", "hasa_env/LaneKeepingCurved-v0")
"""The registered lane-keeping environment ids."""

_RECORDING_NAMES = (
    "Recording",
    "RecordingError",
    "RecordingWrapper",
    "compare_recordings",
    "load_recording",
    "load_recordings",
    "replay",
    "replay_actions",
    "save_recording",
)

__all__ = [
    "ConfigError",
    "LaneKeepingEnv",
    "LaneKeepingVectorEnv",
    "default_config",
    "describe_config",
    "make_config",
    "register_envs",
    "ENV_IDS",
    "__version__",
    *_RECORDING_NAMES,
]

# the recording API imports pandas (~0.3 s), which env users need not pay for
__getattr__, __dir__ = lazy_attributes(
    __name__,
    dict.fromkeys(_RECORDING_NAMES, "hasa_env.recording"),
    eager=[n for n in __all__ if n not in _RECORDING_NAMES],
)


def register_envs() -> None:
    """Register the hasa_env ids with gymnasium (idempotent; done on import)."""
    register_track_ids(
        ENV_IDS,
        "hasa_env.envs.lane_keeping:LaneKeepingEnv",
        "hasa_env.envs.vector:LaneKeepingVectorEnv",
    )


register_envs()
