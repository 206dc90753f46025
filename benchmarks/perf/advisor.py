"""Advisor-task speed: steps per second of the human-as-advisor task against the plain
lane-keeping env, as ratios measured in the same run.

Measured, all with the method of :mod:`benchmarks.perf.env` (uniform random actions
sampled before timing, resets at episode ends timed as part of running the env, the
median of the repeats reported with its spread):

- ``plain_single`` / ``advisor_single``: ``gym.make("hasa_env/LaneKeeping-v0")`` and
  ``gym.make("hasa_env/LaneKeepingAdvisor-v0")`` (default configs: action_repeat 1,
  the advisor task's estimator and a synthetic human stepping at every sample);
- ``plain_vector_1024`` / ``advisor_vector_1024``: the native vector envs at N = 1024,
  action_repeat 1 (env-steps per second: N x ``step()`` calls per second; vector
  envs are warmed up first so that the timed window sees the steady autoreset rate);
- ``advisor_vector_64_repeat_10``: the vector advisor task at N = 64 with a 10 Hz
  policy (action_repeat 10), the set-up of ``examples/train_ppo.py``; reported, no target.

The repeats of the envs compared with each other alternate (plain, advisor, plain, ...),
so a change of the machine's load hits both alike. Targets: vector advisor task at
N = 1024 >= 1/20 of the plain vector env (the training path); the single advisor task
runs at least 20 times real time at 100 Hz (``advisor_single_real_time_factor``:
simulated seconds per wall-clock second, the wall clock being the reference a person at
the wheel needs; decided instead of a compiled kernel for the single env, docs/design.md
§12.6). The ratio single advisor / plain single env is reported without a target.

Usage::

    python -m benchmarks.perf.advisor            # about 20 s on 2 cores
    python -m benchmarks.perf.advisor --quick    # seconds, rough numbers
    hasa-bench perf --only advisor
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

import advisor_tasks  # noqa: F401 - registers the advisor ids (and hasa_env's)
from benchmarks.perf.env import sample_box_actions

__all__ = ["run", "main", "format_table", "TARGETS", "MEASURES"]

PLAIN_ID = "hasa_env/LaneKeeping-v0"
ADVISOR_ID = "hasa_env/LaneKeepingAdvisor-v0"

MEASURES = (
    "plain_single",
    "advisor_single",
    "plain_vector_1024",
    "advisor_vector_1024",
    "advisor_vector_64_repeat_10",
)
"""Keys of the measured envs."""

TARGETS: dict[str, tuple[str, float]] = {
    "advisor_over_plain_vector_1024": ("vector advisor / plain vector, N=1024", 1.0 / 20.0),
    "advisor_single_real_time_factor": (
        "single advisor, simulated s per wall-clock s (real time = 1)",
        20.0,
    ),
}
"""Key -> (description, minimum) of every target."""

# (env.step calls per repeat, repeats, untimed warm-up steps)
_PLAN_FULL = {
    "plain_single": (20_000, 5, 20),
    "advisor_single": (2_000, 5, 20),
    "plain_vector_1024": (300, 5, 300),
    "advisor_vector_1024": (60, 5, 300),
    "advisor_vector_64_repeat_10": (40, 3, 30),
}
_PLAN_QUICK = {
    "plain_single": (1_000, 1, 5),
    "advisor_single": (100, 1, 5),
    "plain_vector_1024": (20, 1, 20),
    "advisor_vector_1024": (5, 1, 20),
    "advisor_vector_64_repeat_10": (3, 1, 3),
}


def _single_timer(env: gym.Env, steps: int, warmup: int, seed: int) -> Callable[[], float]:
    """A function timing ``steps`` env.step calls (resets included): env-steps per second."""
    actions = sample_box_actions(env.action_space, (steps,), seed)
    env.reset(seed=seed)
    for a in actions[:warmup]:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()

    def once() -> float:
        env.reset()
        step, reset = env.step, env.reset
        start = time.perf_counter()
        for a in actions:
            _, _, terminated, truncated, _ = step(a)
            if terminated or truncated:
                reset()
        return steps / (time.perf_counter() - start)

    return once


def _vector_timer(
    env: gym.vector.VectorEnv, steps: int, warmup: int, seed: int
) -> Callable[[], float]:
    """A function timing ``steps`` vector step calls (the env autoresets): env-steps/s."""
    n = env.num_envs
    actions = sample_box_actions(env.single_action_space, (steps, n), seed)
    env.reset(seed=seed)
    for k in range(warmup):
        env.step(actions[k % steps])

    def once() -> float:
        step = env.step
        start = time.perf_counter()
        for a in actions:
            step(a)
        return steps * n / (time.perf_counter() - start)

    return once


def _makers() -> dict[str, tuple[Callable[[], Any], Callable[..., Callable[[], float]]]]:
    def vec(env_id: str, n: int, config: dict[str, Any] | None = None) -> Callable[[], Any]:
        return lambda: gym.make_vec(
            env_id, num_envs=n, vectorization_mode="vector_entry_point", config=config or {}
        )

    return {
        "plain_single": (lambda: gym.make(PLAIN_ID), _single_timer),
        "advisor_single": (lambda: gym.make(ADVISOR_ID), _single_timer),
        "plain_vector_1024": (vec(PLAIN_ID, 1024), _vector_timer),
        "advisor_vector_1024": (vec(ADVISOR_ID, 1024), _vector_timer),
        "advisor_vector_64_repeat_10": (vec(ADVISOR_ID, 64, {"action_repeat": 10}), _vector_timer),
    }


_PAIRS = (
    ("plain_single", "advisor_single"),
    ("plain_vector_1024", "advisor_vector_1024"),
    ("advisor_vector_64_repeat_10",),
)
"""Measurements whose repeats alternate."""


def run(quick: bool = False, seed: int = 0, progress: Callable[[str], None] | None = None) -> dict:
    """Measure every env; return rates (env-steps/s), ratios and targets.

    Returns:
        ``{"envs": {key: {"steps_per_second" (median), "min_steps_per_second",
        "max_steps_per_second", "steps", "repeats", "num_envs", "env_step_seconds"}}, "ratios": {...},
        "targets": {key: {"description", "value", "minimum", "passed"}}, "quick",
        "machine"}``.
    """
    plan = _PLAN_QUICK if quick else _PLAN_FULL
    say = progress or (lambda message: None)
    makers = _makers()
    envs: dict[str, dict[str, Any]] = {}
    for group in _PAIRS:
        made = {}
        timers = {}
        for key in group:
            say(key)
            make, timer = makers[key]
            made[key] = make()
            steps, _, warmup = plan[key]
            timers[key] = timer(made[key], steps, warmup, seed)
        rates: dict[str, list[float]] = {key: [] for key in group}
        for _ in range(max(plan[key][1] for key in group)):
            for key in group:
                if len(rates[key]) < plan[key][1]:
                    rates[key].append(timers[key]())
        for key in group:
            setup = made[key].unwrapped.setup
            step_seconds = getattr(setup, "env", setup).env_step_duration
            made[key].close()
            steps, repeats, _ = plan[key]
            envs[key] = {
                "steps_per_second": float(statistics.median(rates[key])),
                "min_steps_per_second": float(min(rates[key])),
                "max_steps_per_second": float(max(rates[key])),
                "steps": steps,
                "repeats": repeats,
                "num_envs": getattr(made[key], "num_envs", 1),
                "env_step_seconds": float(step_seconds),
            }
    rate = {key: value["steps_per_second"] for key, value in envs.items()}
    ratios = {
        "advisor_over_plain_vector_1024": rate["advisor_vector_1024"] / rate["plain_vector_1024"],
        "advisor_over_plain_single": rate["advisor_single"] / rate["plain_single"],
        "advisor_single_real_time_factor": (
            rate["advisor_single"] * envs["advisor_single"]["env_step_seconds"]
        ),
    }
    targets = {
        key: {
            "description": description,
            "value": ratios[key],
            "minimum": minimum,
            "passed": bool(ratios[key] >= minimum),
        }
        for key, (description, minimum) in TARGETS.items()
    }
    return {
        "envs": envs,
        "ratios": ratios,
        "targets": targets,
        "quick": bool(quick),
        "seed": seed,
        "machine": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "platform": platform.platform(),
            "cpu_count": os.cpu_count(),
        },
    }


def format_table(results: dict) -> str:
    """The results of :func:`run` as a plain-text table."""
    head = f"{'env':<30} {'env-steps/s':>13} {'min .. max':>23} {'steps x rep':>12}"
    lines = [head, "-" * len(head)]
    for key in MEASURES:
        r = results["envs"][key]
        spread = f"{r['min_steps_per_second']:,.0f} .. {r['max_steps_per_second']:,.0f}"
        lines.append(
            f"{key:<30} {r['steps_per_second']:>13,.0f} {spread:>23} "
            f"{r['steps']:>6} x {r['repeats']:<3}"
        )
    lines.append("")
    for t in results["targets"].values():
        verdict = "PASS" if t["passed"] else "FAIL"
        if t["minimum"] < 1:  # a share of the plain env's rate
            value = f"1/{1 / t['value']:.1f} (target >= 1/{1 / t['minimum']:.0f})"
        else:  # a factor (times real time)
            value = f"{t['value']:.1f}x (target >= {t['minimum']:.0f}x)"
        lines.append(f"{t['description']:<42} {value} {verdict}")
    if results.get("quick"):
        lines.append("(quick mode: few steps, rough numbers)")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``python -m benchmarks.perf.advisor [--quick] [--json FILE] [--strict]``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--quick", action="store_true", help="seconds, rough numbers")
    parser.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    parser.add_argument("--seed", type=int, default=0, help="seed of the actions and resets")
    parser.add_argument("--strict", action="store_true", help="exit 1 if a target fails")
    args = parser.parse_args(argv)

    def progress(message: str) -> None:
        print(f"timing {message} ...", file=sys.stderr, flush=True)

    results = run(quick=args.quick, seed=args.seed, progress=progress)
    print(format_table(results))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(results, fh, indent=2, allow_nan=False)
            fh.write("\n")
    failed = [k for k, t in results["targets"].items() if not t["passed"]]
    return 1 if (args.strict and failed) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
