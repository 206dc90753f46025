"""Environment speed: steps per second of hasa_env against reference envs, in one run.

Measured on the machine at hand, all with the same method:

- ``hasa_env/LaneKeeping-v0`` via ``gym.make`` (the single env with
  gymnasium's default wrappers);
- gymnasium's ``Pendulum-v1`` via ``gym.make`` (a minimal classic-control env);
- highway-env's ``lane-keeping-v0`` via ``gym.make`` (optional extra
  ``compare``; reported as "not installed" when absent);
- the native vector env, ``gym.make_vec(id, num_envs=N,
  vectorization_mode="vector_entry_point")`` at N = 1, 64 and 1024
  (reported in env-steps per second, i.e. N x ``step()`` calls per second).

Method: the actions (uniform over each env's action space, seeded) are
sampled before timing, so only ``step`` (and the resets after episode ends,
which are part of running an env) is timed. With random actions the car
leaves the road after a few hundred steps, so resets are part of the
workload (the vector env autoresets; it is warmed up first so the timed
window sees the steady-state reset rate). Each measurement is repeated and
the median rate is reported, with the spread. Targets (issue 2): single env
>= 0.5 x Pendulum-v1 (aim 1 x), >= 5 x highway-env, vector env at 1024 envs
>= 1,000,000 env-steps/s.

Usage::

    python -m benchmarks.perf.env            # about 30 s on 2 cores
    python -m benchmarks.perf.env --quick    # a few seconds, rough numbers
    python -m benchmarks.perf.env --json perf.json
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import statistics
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np

import hasa_env  # noqa: F401 - registers the ids

__all__ = ["run", "main", "format_table", "TARGETS", "ENV_ID"]

ENV_ID = "hasa_env/LaneKeeping-v0"
PENDULUM_ID = "Pendulum-v1"
HIGHWAY_ID = "lane-keeping-v0"
VECTOR_SIZES = (1, 64, 1024)

TARGETS: dict[str, tuple[str, float]] = {
    "hasa_over_pendulum": ("single env / Pendulum-v1 (aim 1)", 0.5),
    "hasa_over_highway": ("single env / highway-env lane-keeping-v0", 5.0),
    "vector_1024_env_steps_per_second": ("vector env N=1024, env-steps/s", 1_000_000.0),
}
"""Key -> (description, minimum) of every target."""

# steps per repeat (env.step calls), repeats; highway-env is slow, so fewer steps.
_PLAN_FULL = {
    "hasa_env": (50_000, 5),
    "pendulum": (50_000, 5),
    "highway_env": (3_000, 5),
    "vector_1": (5_000, 5),
    "vector_64": (2_000, 5),
    "vector_1024": (500, 5),
}
_PLAN_QUICK = {
    "hasa_env": (2_000, 1),
    "pendulum": (2_000, 1),
    "highway_env": (100, 1),
    "vector_1": (200, 1),
    "vector_64": (50, 1),
    "vector_1024": (10, 1),
}
_WARMUP = 20  # untimed steps before a single-env measurement
# Untimed vector steps first: all N cars start together, so their episodes only
# end (and autoreset, which costs time) after ~100-300 steps of random actions;
# timing from the start would miss the steady-state reset rate.
_WARMUP_VECTOR = 400


def sample_box_actions(space: gym.Space, shape: tuple[int, ...], seed: int) -> np.ndarray:
    """Uniform actions over a bounded Box, shape ``shape + space.shape``, in the space's dtype."""
    if not isinstance(space, gym.spaces.Box):
        raise TypeError(f"the benchmark samples Box action spaces, got {space}")
    rng = np.random.default_rng(seed)
    low = np.broadcast_to(space.low, space.shape)
    high = np.broadcast_to(space.high, space.shape)
    return rng.uniform(low, high, size=shape + space.shape).astype(space.dtype)


def _time_single(env: gym.Env, steps: int, repeats: int, seed: int) -> dict[str, Any]:
    """Time ``steps`` env.step calls (resetting at episode ends), ``repeats`` times."""
    actions = sample_box_actions(env.action_space, (steps,), seed)
    env.reset(seed=seed)
    for a in actions[:_WARMUP]:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    rates, episodes = [], 0
    for _ in range(repeats):
        env.reset()
        step = env.step
        reset = env.reset
        t0 = time.perf_counter()
        for a in actions:
            _, _, terminated, truncated, _ = step(a)
            if terminated or truncated:
                reset()
                episodes += 1
        rates.append(steps / (time.perf_counter() - t0))
    return _summary(rates, steps, repeats, episodes)


def _time_vector(env: gym.vector.VectorEnv, steps: int, repeats: int, seed: int) -> dict[str, Any]:
    """Time ``steps`` vector step calls (the env autoresets), ``repeats`` times.

    Rates are in env-steps per second (``num_envs`` per call).
    """
    n = env.num_envs
    actions = sample_box_actions(env.single_action_space, (steps, n), seed)
    env.reset(seed=seed)
    for k in range(_WARMUP_VECTOR):
        env.step(actions[k % steps])
    rates, episodes = [], 0
    for _ in range(repeats):
        step = env.step
        t0 = time.perf_counter()
        for a in actions:
            _, _, terminated, truncated, _ = step(a)
            episodes += int(np.count_nonzero(terminated | truncated))
        rates.append(steps * n / (time.perf_counter() - t0))
    out = _summary(rates, steps, repeats, episodes)
    out["num_envs"] = n
    out["calls_per_second"] = out["steps_per_second"] / n
    return out


def _summary(rates: Sequence[float], steps: int, repeats: int, episodes: int) -> dict[str, Any]:
    return {
        "status": "ok",
        "steps_per_second": float(statistics.median(rates)),
        "min_steps_per_second": float(min(rates)),
        "max_steps_per_second": float(max(rates)),
        "steps": steps,
        "repeats": repeats,
        "episodes_ended": episodes,
    }


def _make_highway() -> gym.Env | None:
    """highway-env's lane-keeping-v0, or None if highway-env is not installed.

    Imported lazily with pygame's banner and import-time warnings silenced.
    """
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
    sink = io.StringIO()
    with warnings.catch_warnings(), contextlib.redirect_stdout(sink):
        warnings.simplefilter("ignore")
        try:
            import highway_env  # noqa: F401 - optional (the 'compare' extra)
        except ImportError:
            return None
        return gym.make(HIGHWAY_ID)


def _measure(
    make: Callable[[], Any], timer: Callable[..., dict[str, Any]], plan: tuple[int, int], seed: int
) -> dict[str, Any]:
    env = make()
    if env is None:
        return {"status": "not installed", "steps_per_second": None}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # keep the output clean (e.g. highway-env)
            return timer(env, plan[0], plan[1], seed)
    finally:
        env.close()


def run(quick: bool = False, seed: int = 0, progress: Callable[[str], None] | None = None) -> dict:
    """Measure every env; return the numbers (all rates in env-steps per second).

    Args:
        quick: a seconds-long run with few steps (rough numbers, for smoke tests).
        seed: seed of the pre-sampled actions and of the envs' resets.
        progress: called with a short message before each measurement.

    Returns:
        ``{"envs": {name: {...}}, "ratios": {...}, "targets": {...},
        "quick": bool, "machine": {...}}``. ``envs`` has the keys
        ``hasa_env``, ``pendulum``, ``highway_env``, ``vector_1``,
        ``vector_64``, ``vector_1024``, each with ``status`` ("ok" or "not
        installed"), ``steps_per_second`` (median, env-steps/s), min/max, the
        ``steps`` per repeat, ``repeats`` and ``episodes_ended``; vector
        entries add ``num_envs`` and ``calls_per_second``. ``ratios`` has
        ``hasa_over_pendulum`` and ``hasa_over_highway`` (None without
        highway-env); ``targets`` maps each key of :data:`TARGETS` to its
        ``value``, ``minimum`` and ``passed`` (None if not measured).
    """
    plan = _PLAN_QUICK if quick else _PLAN_FULL
    say = progress or (lambda msg: None)
    envs: dict[str, dict[str, Any]] = {}
    say(f"{ENV_ID} (gym.make)")
    envs["hasa_env"] = _measure(lambda: gym.make(ENV_ID), _time_single, plan["hasa_env"], seed)
    say(f"{PENDULUM_ID} (gym.make)")
    envs["pendulum"] = _measure(lambda: gym.make(PENDULUM_ID), _time_single, plan["pendulum"], seed)
    say(f"highway-env {HIGHWAY_ID} (gym.make)")
    envs["highway_env"] = _measure(_make_highway, _time_single, plan["highway_env"], seed)
    for n in VECTOR_SIZES:
        say(f"{ENV_ID} native vector env, N={n}")
        key = f"vector_{n}"
        envs[key] = _measure(
            partial(gym.make_vec, ENV_ID, num_envs=n, vectorization_mode="vector_entry_point"),
            _time_vector,
            plan[key],
            seed,
        )

    ours = envs["hasa_env"]["steps_per_second"]
    highway = envs["highway_env"]["steps_per_second"]
    ratios = {
        "hasa_over_pendulum": ours / envs["pendulum"]["steps_per_second"],
        "hasa_over_highway": None if highway is None else ours / highway,
    }
    values = {**ratios, "vector_1024_env_steps_per_second": envs["vector_1024"]["steps_per_second"]}
    targets = {
        key: {
            "description": desc,
            "value": values[key],
            "minimum": minimum,
            "passed": None if values[key] is None else bool(values[key] >= minimum),
        }
        for key, (desc, minimum) in TARGETS.items()
    }
    return {
        "quick": bool(quick),
        "seed": seed,
        "machine": {
            "python": platform.python_version(),
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(),
            "gymnasium": gym.__version__,
            "numpy": np.__version__,
        },
        "envs": envs,
        "ratios": ratios,
        "targets": targets,
    }


_LABELS = {
    "hasa_env": f"{ENV_ID} (gym.make)",
    "pendulum": f"{PENDULUM_ID} (gym.make)",
    "highway_env": f"highway-env {HIGHWAY_ID} (gym.make)",
    "vector_1": "hasa_env native vector, N=1",
    "vector_64": "hasa_env native vector, N=64",
    "vector_1024": "hasa_env native vector, N=1024",
}


def _fmt_rate(x: float | None) -> str:
    return "-" if x is None else f"{x:,.0f}"


def format_table(results: dict) -> str:
    """The results of :func:`run` as a plain-text table."""
    lines = []
    head = f"{'env':<42} {'env-steps/s':>13} {'min .. max':>23} {'steps x rep':>12}"
    lines += [head, "-" * len(head)]
    for key, label in _LABELS.items():
        r = results["envs"][key]
        if r["status"] != "ok":
            lines.append(f"{label:<42} {r['status']:>13}")
            continue
        spread = f"{_fmt_rate(r['min_steps_per_second'])} .. {_fmt_rate(r['max_steps_per_second'])}"
        size = f"{r['steps']} x {r['repeats']}"
        extra = ""
        if "num_envs" in r:
            extra = f"  ({r['calls_per_second']:,.0f} step() calls/s)"
        lines.append(
            f"{label:<42} {_fmt_rate(r['steps_per_second']):>13} {spread:>23} {size:>12}{extra}"
        )
    lines.append("")
    head = f"{'target':<42} {'measured':>13} {'required':>13}  result"
    lines += [head, "-" * len(head)]
    for t in results["targets"].values():
        value, minimum = t["value"], t["minimum"]
        if minimum >= 1000:
            shown, need = _fmt_rate(value), f">= {minimum:,.0f}"
        else:
            shown = "-" if value is None else f"{value:.2f}x"
            need = f">= {minimum:g}x"
        verdict = {True: "PASS", False: "FAIL", None: "n/a (not installed)"}[t["passed"]]
        lines.append(f"{t['description']:<42} {shown:>13} {need:>13}  {verdict}")
    m = results["machine"]
    lines.append("")
    lines.append(
        f"{'quick run, ' if results['quick'] else ''}Python {m['python']}, gymnasium "
        f"{m['gymnasium']}, numpy {m['numpy']}, {m['cpu_count']} CPUs, {m['platform']}"
    )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI: run the benchmark, print the table, optionally write JSON.

    Returns 0, or 1 with ``--strict`` when a measured target fails.
    """
    parser = argparse.ArgumentParser(
        allow_abbrev=False,
        prog="python -m benchmarks.perf.env",
        description="Steps per second of hasa_env vs Pendulum-v1 and highway-env lane-keeping-v0, "
        "and of the native vector env at N = 1, 64, 1024.",
    )
    parser.add_argument("--quick", action="store_true", help="a few seconds, rough numbers")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON to PATH")
    parser.add_argument("--seed", type=int, default=0, help="seed of the actions and resets")
    parser.add_argument(
        "--strict", action="store_true", help="exit with status 1 if a target fails"
    )
    args = parser.parse_args(argv)

    def progress(msg: str) -> None:
        print(f"timing {msg} ...", file=sys.stderr, flush=True)

    results = run(quick=args.quick, seed=args.seed, progress=progress)
    print(format_table(results))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(results, f, indent=2, allow_nan=False)
            f.write("\n")
    failed = [k for k, t in results["targets"].items() if t["passed"] is False]
    return 1 if (args.strict and failed) else 0


if __name__ == "__main__":
    sys.exit(main())
