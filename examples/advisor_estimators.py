"""How well each steering model advises the estimator in the advisor task (docs/design.md §12.4-12.5).

For each model, six 30 s episodes of ``hasa_env/LaneKeepingAdvisor-v0`` (the "paper"
population, a random advisor per episode, random start, each lane hypothesis three
times) with a lane keeper on the *true* state driving at 100 Hz, so the estimate is
judged on the same driving for every model. Prints the lateral RMSE of the estimate
against the true offset, the episodes whose estimate ends on the true lane, and the
samples whose steering reading the estimator gated as an outlier.

``--policy aggressive``: instead, twelve episodes of a jerky, high-gain lane keeper at
10 Hz that throws the wheel +-0.15 rad at random for the first 6 s (as a policy still
learning does); ``--gate`` turns the estimator's outlier gate on (the task's default: off,
docs/design.md §12.5). A model that drives off the road when it steers itself is refused
by the task (``estimator.lane_check``, docs/design.md §8.11; the two-point preset is) and
printed as such; ``--no-lane-check`` scores it anyway.

Usage::

    python examples/advisor_estimators.py                        # the four models, car drives
    python examples/advisor_estimators.py --drives human --models generalized,fit:generalized
    python examples/advisor_estimators.py --policy aggressive --models generalized [--gate]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import advisor_tasks  # noqa: F401 - registers the advisor ids (and hasa_env's)
from hasa_env import ConfigError

START = {"initial_state": {"lateral_offset_std": 0.5, "heading_std": 0.02}}


def lane_keeper(info: dict) -> np.ndarray:
    """A proportional lane keeper on the true state (normalized steering action)."""
    steering = -0.15 * info["lateral_offset"] - 0.8 * info["heading"]  # rad
    return np.array([np.clip(steering / 0.5, -1.0, 1.0)], dtype=np.float32)


def aggressive(info: dict, rng: np.random.Generator, step: int) -> np.ndarray:
    """A high-gain lane keeper on the true state, throwing the wheel about for 60 steps."""
    steering = -0.8 * info["lateral_offset"] - 3.0 * info["heading"]  # rad
    steering += 0.3 * rng.choice([-1.0, 1.0]) if step < 60 else 0.02 * rng.standard_normal()
    return np.array([np.clip(steering / 0.5, -1.0, 1.0)], dtype=np.float32)


def score(
    model: str, drives: str, episodes: int, policy: str, gate: bool, lane_check: bool = True
) -> tuple[float, int, int]:
    """(mean lateral RMSE of the estimate (m), episodes ending on the true lane, gated
    steering samples)."""
    config = {
        **START,
        "estimator": {"steering_model": model, "outlier_gate": gate, "lane_check": lane_check},
        "advisor": {"drives": drives},
        "action_repeat": 10 if policy == "aggressive" else 1,
    }
    env = gym.make("hasa_env/LaneKeepingAdvisor-v0", config=config)
    rmse, true_lane, gated = [], 0, 0
    for episode in range(episodes):
        seed = episode if policy == "lane-keeper" else 100 + episode
        _, info = env.reset(seed=seed, options={"bias_index": episode % 2})
        rng = np.random.default_rng(episode)
        errors = []
        done = False
        step = 0
        while not done:
            if policy == "lane-keeper":
                action = lane_keeper(info)
            else:
                action = aggressive(info, rng, step)
            _, _, terminated, truncated, info = env.step(action)
            errors.append(info["estimate_lateral_offset"] - info["lateral_offset"])
            done = terminated or truncated
            step += 1
        rmse.append(float(np.sqrt(np.mean(np.square(errors)))))
        true_lane += int(info["estimate_lane_index"] == info["bias_index"])
        gated += int(env.unwrapped.estimator.gated_counts[0, 2])
    return float(np.mean(rmse)), true_lane, gated


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", default="generalized,fit:generalized,two-point,fit:two-point")
    parser.add_argument("--drives", choices=("car", "human"), default="car")
    parser.add_argument("--policy", choices=("lane-keeper", "aggressive"), default="lane-keeper")
    parser.add_argument("--gate", action="store_true", help="the outlier gate on")
    parser.add_argument("--episodes", type=int, default=None, help="default 6 (aggressive: 12)")
    parser.add_argument(
        "--no-lane-check", action="store_true", help="score models that cannot drive too"
    )
    args = parser.parse_args(argv)
    episodes = args.episodes or (6 if args.policy == "lane-keeper" else 12)
    print(f"{'model':<18} {'lateral RMSE (m)':>17} {'true lane':>10} {'gated steering':>15}")
    for model in args.models.split(","):
        try:
            rmse, true_lane, gated = score(
                model, args.drives, episodes, args.policy, args.gate, not args.no_lane_check
            )
        except ConfigError as exc:
            print(f"{model:<18} refused: {exc}")
            continue
        print(f"{model:<18} {rmse:>17.3f} {true_lane:>6}/{episodes:<3} {gated:>15}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
