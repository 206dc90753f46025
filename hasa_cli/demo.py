"""``hasa-demo``: a short headless drive that prints a summary.

A proportional lane-keeping controller on the true state drives each
registered env for one episode; the summary shows what the env reports
(lateral error, camera bias, steps per second).
"""

from __future__ import annotations

import argparse
import math
import time

import gymnasium as gym
import numpy as np

import hasa_env


def _drive(env_id: str, seed: int, seconds: float) -> dict[str, float]:
    env = gym.make(env_id, config={"time_limit": seconds, "action": {"type": "physical"}})
    _, info = env.reset(seed=seed)
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
        _, _, term, trunc, info = env.step(np.array([steer, 0.0]))
        errors.append(info["lateral_offset"])
        camera_errors.append(info["sensor_camera_lateral"] - info["lateral_offset"])
        steps += 1
        done = term or trunc
    elapsed = time.perf_counter() - start
    return {
        "steps": steps,
        "final_lateral_offset_m": errors[-1],
        "lateral_rmse_m": float(np.sqrt(np.mean(np.square(errors)))),
        "camera_bias_m": info["bias"],
        "mean_camera_error_m": float(np.mean(camera_errors)),
        "steps_per_s": steps / elapsed,
        "terminated": bool(term),
    }


def demo_main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="hasa-demo", description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--seconds", type=float, default=30.0, help="episode length (s)")
    args = parser.parse_args(argv)
    print(
        f"hasa-env {hasa_env.__version__}: one {args.seconds:g} s drive per env, seed {args.seed}"
    )
    for env_id in hasa_env.ENV_IDS:
        r = _drive(env_id, args.seed, args.seconds)
        print(
            f"{env_id:32s} steps {r['steps']:5d}  final y {r['final_lateral_offset_m']:+.3f} m  "
            f"RMS y {r['lateral_rmse_m']:.3f} m  camera bias {r['camera_bias_m']:+.1f} m "
            f"(camera error {r['mean_camera_error_m']:+.2f} m)  {r['steps_per_s']:,.0f} steps/s"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(demo_main())
