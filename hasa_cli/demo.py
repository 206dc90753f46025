"""``hasa-demo``: a short headless drive that prints a summary.

A proportional lane-keeping controller on the true state drives each
registered env for one episode: the plain lane-keeping ids of :mod:`hasa_env`
and the human-as-advisor ids of :mod:`advisor_tasks` (steering only; their
estimator's weight of the true lane is shown too); the summary shows what the
env reports (lateral error, camera bias, steps per second).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence

import gymnasium as gym
import numpy as np

import advisor_tasks
import hasa_env
from hasa_cli import EXIT_OK, EXIT_USAGE, ArgumentParser, add_version, console_script, error
from hasa_env.sim.config import ConfigError

PROG = "hasa-demo"


def _drive(env_id: str, seed: int, seconds: float) -> dict[str, float]:
    env = gym.make(env_id, config={"time_limit": seconds, "action": {"type": "physical"}})
    _, info = env.reset(seed=seed)
    size = int(np.prod(env.action_space.shape or (2,)))
    errors, camera_errors, steps = [], [], 0
    start = time.perf_counter()
    done = False
    while not done:
        # geometric curve following plus P-D on the true lateral offset and heading
        steer = (
            math.atan(2.8 * info["road_curvature"])
            - 0.04 * info["lateral_offset"]
            - 0.4 * info["heading"]
        )
        action = np.array([steer, 0.0])[:size]  # the advisor ids: steering only
        _, _, term, trunc, info = env.step(action)
        errors.append(info["lateral_offset"])
        camera_errors.append(info["sensor_camera_lateral"] - info["lateral_offset"])
        steps += 1
        done = term or trunc
    elapsed = time.perf_counter() - start
    weights = info.get("estimate_weights")
    env.close()
    return {
        "true_lane_weight": float(weights[info["bias_index"]]) if weights is not None else None,
        "steps": steps,
        "final_lateral_offset_m": errors[-1],
        "lateral_rmse_m": float(np.sqrt(np.mean(np.square(errors)))),
        "camera_bias_m": info["bias"],
        "mean_camera_error_m": float(np.mean(camera_errors)),
        "steps_per_s": steps / elapsed,
        "terminated": bool(term),
    }


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected an episode length in s > 0, got {text!r}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a seed (an integer >= 0), got {text!r}")
    return value


@console_script(PROG)
def demo_main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``hasa-demo``; returns the exit status (0 ok, 2 a bad argument)."""
    parser = ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    add_version(parser)
    parser.add_argument("--seed", type=_seed, default=0, help="episode seed (default 0)")
    parser.add_argument(
        "--seconds", type=_seconds, default=30.0, help="episode length in s (> 0; default 30)"
    )
    args = parser.parse_args(argv)
    try:
        gym.make(hasa_env.ENV_IDS[0], config={"time_limit": args.seconds}).close()
    except ConfigError as exc:
        error(PROG, f"--seconds: {exc}")
        return EXIT_USAGE
    print(
        f"hasa-env {hasa_env.__version__}: one {args.seconds:g} s drive per env, seed {args.seed}"
    )
    for env_id in (*hasa_env.ENV_IDS, *advisor_tasks.ADVISOR_ENV_IDS):
        r = _drive(env_id, args.seed, args.seconds)
        weight = r["true_lane_weight"]
        print(
            f"{env_id:40s} steps {r['steps']:5d}  final y {r['final_lateral_offset_m']:+.3f} m  "
            f"RMS y {r['lateral_rmse_m']:.3f} m  camera bias {r['camera_bias_m']:+.1f} m "
            f"(camera error {r['mean_camera_error_m']:+.2f} m)  {r['steps_per_s']:,.0f} steps/s"
            + (f"  true lane's weight {weight:.2f}" if weight is not None else "")
        )
    return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(demo_main())
