"""Tasks that put a human and an estimator in the loop: the human-as-advisor task.

A policy drives the car of :mod:`hasa_env`; a synthetic human of a population sits at
the wheel and turns it as it would to keep the true lane; the human's measured steering
feeds an estimator of :mod:`estimators` (the Gaussian-mixture EKF by default), which
tells the lanes apart. This package is the layer between :mod:`estimators` (the filter
and its adapters) and :mod:`benchmarks` (docs/design.md §2).

Importing ``advisor_tasks`` registers its ids (``hasa_env`` registers only the plain
lane-keeping ids, and names nothing above it):

- ``hasa_env/LaneKeepingAdvisor-v0``: the straight road;
- ``hasa_env/LaneKeepingAdvisorCurved-v0``: the shipped curved track.

Both have a native vector entry point
(``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``), and
``gym.make("advisor_tasks:hasa_env/LaneKeepingAdvisor-v0")`` imports this package
itself. Modules: :mod:`~advisor_tasks.config` (the task's config and estimator
choice), :mod:`~advisor_tasks.setup` (frozen set-up, spaces, readout),
:mod:`~advisor_tasks.env` (one car), :mod:`~advisor_tasks.vector` (N cars).
"""

from __future__ import annotations

import hasa_env  # noqa: F401 - registers the plain ids first
from hasa_env._lazy import lazy_attributes
from hasa_env.envs.base import register_track_ids

ADVISOR_ENV_IDS = ("hasa_env/LaneKeepingAdvisor-v0", "hasa_env/LaneKeepingAdvisorCurved-v0")
"""The registered ids of the human-as-advisor task."""

__all__ = [
    "ADVISOR_ENV_IDS",
    "LaneKeepingAdvisorEnv",  # noqa: F822 - a lazy attribute (see below)
    "LaneKeepingAdvisorVectorEnv",  # noqa: F822 - a lazy attribute (see below)
    "default_config",  # noqa: F822 - a lazy attribute (see below)
    "describe_config",  # noqa: F822 - a lazy attribute (see below)
    "register_envs",
]

# loaded on first access: the task imports the estimators, the drivers and the RL layer
_LAZY = {
    "LaneKeepingAdvisorEnv": "advisor_tasks.env",
    "LaneKeepingAdvisorVectorEnv": "advisor_tasks.vector",
    "default_config": "advisor_tasks.setup",
    "describe_config": "advisor_tasks.setup",
}
__getattr__, __dir__ = lazy_attributes(
    __name__, _LAZY, eager=[n for n in __all__ if n not in _LAZY]
)


def register_envs() -> None:
    """Register the advisor task's ids with gymnasium (idempotent; done on import).

    Entry-point strings: gymnasium imports the env modules only when one is made.
    """
    register_track_ids(
        ADVISOR_ENV_IDS,
        "advisor_tasks.env:LaneKeepingAdvisorEnv",
        "advisor_tasks.vector:LaneKeepingAdvisorVectorEnv",
    )


register_envs()
