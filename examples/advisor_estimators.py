"""How well each steering model advises the estimator in the advisor task (docs/design.md §12.4-12.5).

For each model, six 30 s episodes of ``hasa_env/LaneKeepingAdvisor-v0`` (the "paper"
population, a random advisor per episode, random start, each lane hypothesis three
times) with a lane keeper on the *true* state driving at 100 Hz, so the estimate is
judged on the same driving for every model. Prints the lateral RMSE of the estimate
against the true offset, how each episode ended (:func:`episode_outcome`) and the
samples whose steering reading the estimator gated as an outlier.

How an episode ended is read from the estimator's decision state at its last step
(:data:`estimators.evidence.DECISIONS`): ``true lane`` / ``wrong lane`` when it is
``decided`` (one lane's weight at the estimator's ``decision_threshold``, 0.95 by
default, or above), ``undecided`` below it, ``refused`` in ``model_mismatch``, with the
reason (:func:`estimators.evidence.refusal_reasons`: the reversal rule, the path rule or
the mismatch test). An episode that ends with more than the threshold on a wrong lane
counts as ``wrong lane`` in any state, as hasa-bench's "confident wrong lane" does. Before,
the count was of episodes whose *most likely* lane at the end was the true one: a refused
episode, back at the prior's 0.5 / 0.5, counted as the true lane whenever that was index 0
(the tie's argmax), and an undecided one whenever it leaned the right way.

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
from collections import Counter
from collections.abc import Sequence
from typing import cast

import gymnasium as gym
import numpy as np

import advisor_tasks  # registers the advisor ids (and hasa_env's)
from estimators.evidence import DECISIONS, refusal_reasons
from hasa_env import ConfigError

START = {"initial_state": {"lateral_offset_std": 0.5, "heading_std": 0.02}}
OUTCOMES = ("true lane", "wrong lane", "undecided", "refused")


def lane_keeper(info: dict) -> np.ndarray:
    """A proportional lane keeper on the true state (normalized steering action)."""
    steering = -0.15 * info["lateral_offset"] - 0.8 * info["heading"]  # rad
    return np.array([np.clip(steering / 0.5, -1.0, 1.0)], dtype=np.float32)


def aggressive(info: dict, rng: np.random.Generator, step: int) -> np.ndarray:
    """A high-gain lane keeper on the true state, throwing the wheel about for 60 steps."""
    steering = -0.8 * info["lateral_offset"] - 3.0 * info["heading"]  # rad
    steering += 0.3 * rng.choice([-1.0, 1.0]) if step < 60 else 0.02 * rng.standard_normal()
    return np.array([np.clip(steering / 0.5, -1.0, 1.0)], dtype=np.float32)


def episode_outcome(
    decision: str,
    weights: Sequence[float] | np.ndarray,
    true_index: int,
    threshold: float,
    refusal_code: int = 0,
) -> tuple[str, str]:
    """How an episode ended, from the estimate at its last step: (one of :data:`OUTCOMES`,
    the reason of a refusal or ``""``).

    ``decision``: the decision state (:data:`estimators.evidence.DECISIONS`); ``weights``:
    the lane weights; ``true_index``: the true lane's index; ``threshold``: the estimator's
    ``decision_threshold``; ``refusal_code``: the filter's ``refusal_codes`` entry. The lane
    counts only when the estimator decided it (the most likely lane of an episode sent back
    to its prior is the tie's argmax, index 0); more than ``threshold`` on a wrong lane is
    ``wrong lane`` in any state (hasa-bench's ``wrong_lane_confident``: weights the mismatch
    test froze there)."""
    if decision not in DECISIONS:
        raise ValueError(f"unknown decision state {decision!r} (one of {DECISIONS})")
    w = np.asarray(weights, dtype=np.float64)
    wrong = np.delete(w, true_index)
    if decision == "decided":
        return ("true lane" if int(np.argmax(w)) == true_index else "wrong lane"), ""
    if wrong.size and float(wrong.max()) > threshold:
        return "wrong lane", ""
    if decision == "undecided":
        return "undecided", ""
    return "refused", str(refusal_reasons(np.array([decision]), np.array([refusal_code]))[0])


def tally(outcomes: Sequence[tuple[str, str]]) -> tuple[dict[str, int], str]:
    """Episodes per outcome (every one of :data:`OUTCOMES`) and the refusals' reasons as
    ``"reversal rule 3, mismatch test 1"`` (``""`` without refusals)."""
    counts = Counter(outcome for outcome, _ in outcomes)
    unknown = set(counts) - set(OUTCOMES)
    if unknown:
        raise ValueError(f"unknown outcomes {sorted(unknown)} (one of {OUTCOMES})")
    reasons = Counter(reason for outcome, reason in outcomes if outcome == "refused")
    why = ", ".join(f"{reason} {n}" for reason, n in sorted(reasons.items()))
    return {outcome: counts[outcome] for outcome in OUTCOMES}, why


def score(
    model: str, drives: str, episodes: int, policy: str, gate: bool, lane_check: bool = True
) -> tuple[float, list[tuple[str, str]], int]:
    """(mean lateral RMSE of the estimate (m), each episode's :func:`episode_outcome`,
    gated steering samples)."""
    config = {
        **START,
        "estimator": {"steering_model": model, "outlier_gate": gate, "lane_check": lane_check},
        "advisor": {"drives": drives},
        "action_repeat": 10 if policy == "aggressive" else 1,
    }
    env = gym.make("hasa_env/LaneKeepingAdvisor-v0", config=config)
    estimator = cast(advisor_tasks.LaneKeepingAdvisorEnv, env.unwrapped).estimator
    rmse: list[float] = []
    outcomes: list[tuple[str, str]] = []
    gated = 0
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
        outcomes.append(
            episode_outcome(
                info["estimate_decision"],
                info["estimate_weights"],
                info["bias_index"],
                estimator.settings.decision_threshold,
                int(estimator.refusal_codes[0]),
            )
        )
        gated += int(estimator.gated_counts[0, 2])
    return float(np.mean(rmse)), outcomes, gated


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
    columns = "".join(f"{name:>12}" for name in OUTCOMES)
    print(f"{'model':<18} {'lateral RMSE (m)':>17}{columns} {'gated steering':>15}  refused by")
    for model in args.models.split(","):
        try:
            rmse, outcomes, gated = score(
                model, args.drives, episodes, args.policy, args.gate, not args.no_lane_check
            )
        except ConfigError as exc:
            print(f"{model:<18} refused: {exc}")
            continue
        counts, why = tally(outcomes)
        cells = "".join(f"{f'{counts[name]}/{episodes}':>12}" for name in OUTCOMES)
        print(f"{model:<18} {rmse:>17.3f}{cells} {gated:>15}  {why}".rstrip())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
