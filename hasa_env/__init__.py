"""hasa-env: human-as-advisor lane keeping (Mai et al.), a Gymnasium environment.

Importing ``hasa_env`` registers the environment ids:

- ``hasa_env/LaneKeeping-v0``: straight road;
- ``hasa_env/LaneKeepingCurved-v0``: the shipped curved track.

Both have a native vector entry point
(``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

import gymnasium as gym

from hasa_env.config import ConfigError, default_config, describe_config, make_config
from hasa_env.lane_keeping import LaneKeepingEnv
from hasa_env.vector import LaneKeepingVectorEnv

try:
    __version__ = version("hasa-env")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

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
"""Loaded from :mod:`hasa_env.recording` on first use (it imports pandas)."""

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

ENV_IDS = ("hasa_env/LaneKeeping-v0", "hasa_env/LaneKeepingCurved-v0")


_LAZY = dict.fromkeys(_RECORDING_NAMES, "hasa_env.recording")


def __getattr__(name: str):  # noqa: ANN202 - PEP 562 lazy attributes
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hasa_env' has no attribute {name!r}")
    from importlib import import_module

    return getattr(import_module(module), name)


def register_envs() -> None:
    """Register the hasa_env ids with gymnasium (idempotent; done on import)."""
    for env_id, track in zip(ENV_IDS, ("straight", "curved"), strict=True):
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point="hasa_env.lane_keeping:LaneKeepingEnv",
            vector_entry_point="hasa_env.vector:LaneKeepingVectorEnv",
            kwargs={"track": track},
        )


register_envs()
