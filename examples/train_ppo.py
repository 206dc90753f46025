"""Train Stable-Baselines3 PPO to keep the lane, and compare it with a human and zero steering.

Two observation variants, both steering only (the acceleration is held at
0 m/s^2, so the car keeps its 15 m/s) and acting at 10 Hz
(``--action-repeat 10`` of the 100 Hz simulation):

- ``camera``: the env's sensors (speed, the *biased* camera, heading, IMU,
  steering). Trained on the native vector env (``hasa_env.rl.make_vector_env``)
  through ``hasa_env.rl.SB3VecEnv``, with ``config["action_repeat"]``.
- ``estimator``: the human-as-advisor estimate of the Gaussian-mixture EKF
  (``estimators.wrappers.EstimatorObservationWrapper``: mixture mean and std
  of [v_x, y, v_y, b] and the lane weights). The estimator reads a human's
  steering; here a synthetic driver who sees the true lane advises
  (``hasa_env.rl.HumanAdvisor``) while PPO drives. The estimator needs every
  100 Hz sample, so the env runs at 100 Hz and ``hasa_env.rl.ActionRepeat``
  holds PPO's action for 10 samples; single envs in SB3's ``DummyVecEnv``
  (the vector estimator wrapper cannot reset single cars, which SB3's
  same-step autoreset needs).

Episodes: 30 s on the straight road, two equally likely lane centres (camera
bias 0 or -1.8 m), start at y = -0.5 m with std 0.5 m and heading std
0.02 rad. (From the paper's exact start, y = -0.5 m and heading 0, zero
steering would hold y = -0.5 m forever on a straight road: nothing disturbs
the car.) Every policy is evaluated on the same seeded episodes, each lane
hypothesis equally often, in the 100 Hz env; the return is the sum of the
100 Hz rewards over the episode (policies acting at 10 Hz hold their action).

Usage::

    python examples/train_ppo.py                          # both variants (50k / 20k steps)
    python examples/train_ppo.py --variant camera --timesteps 20000 --num-envs 8 --seed 1

Needs the RL extra (``pip install "hasa-env[rl]"``: stable-baselines3, torch).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym

import hasa_env  # noqa: F401 - registers the env ids
from hasa_env.drivers import SpeedProfile, SyntheticDriver, population
from hasa_env.rl import (
    ActionRepeat,
    ConstantSteering,
    DriverPolicy,
    EvalResult,
    HumanAdvisor,
    SB3Policy,
    SteeringOnly,
    evaluate,
    make_vector_env,
    require_sb3,
)
from hasa_env.sim.config import deep_merge

ENV_ID = "hasa_env/LaneKeeping-v0"
BASE_CONFIG: dict[str, Any] = {
    "initial_state": {"lateral_offset_std": 0.5, "heading_std": 0.02},
}
"""The task: the default env (100 Hz, 30 s, lanes {0, -1.8} m) with a random start."""
DEFAULT_TIMESTEPS = {"camera": 50_000, "estimator": 20_000}
"""PPO steps per variant; the estimator variant costs ~10x more per step (EKF at 100 Hz)."""


def advisor_driver(name: str = "Ill", seed: int = 0) -> SyntheticDriver:
    """Driver ``name`` of the seeded "paper" population, holding its initial speed."""
    drivers = {p.name: p for p in population("paper", seed)}
    if name not in drivers:
        raise SystemExit(f"unknown driver {name!r}; choose one of {', '.join(drivers)}")
    return SyntheticDriver(dataclasses.replace(drivers[name], speed=SpeedProfile.hold()))


def camera_env(config: dict[str, Any], repeat: int) -> gym.Env:
    """Single 100 Hz env, steering only, action held for ``repeat`` samples (evaluation)."""
    return ActionRepeat(SteeringOnly(gym.make(ENV_ID, config=config)), repeat)


def estimator_env(config: dict[str, Any], repeat: int, driver_name: str, population_seed: int):
    """100 Hz env -> steering only -> human advisor -> estimate observation -> action repeat."""
    from estimators.gm_ekf import FilterSettings, GaussianMixtureEKF
    from estimators.wrappers import EstimatorObservationWrapper
    from hasa_env.steering.models import GeneralizedModel

    env = SteeringOnly(gym.make(ENV_ID, config=config))
    env = HumanAdvisor(env, advisor_driver(driver_name, population_seed))
    ekf = GaussianMixtureEKF(
        GeneralizedModel.paper().arx(), FilterSettings.from_env_config(env.unwrapped.config)
    )
    return ActionRepeat(EstimatorObservationWrapper(env, ekf), repeat)


def train(
    variant: str, timesteps: int, seed: int, num_envs: int, repeat: int, args: argparse.Namespace
) -> tuple[Any, float]:
    """Train PPO on one variant; returns (model, wall-clock training time in s)."""
    require_sb3()
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    from hasa_env.rl import SB3VecEnv

    if variant == "camera":
        config = deep_merge(BASE_CONFIG, {"action_repeat": repeat})
        venv = SB3VecEnv(make_vector_env(ENV_ID, num_envs, config, steering_only=True))
    else:

        def make() -> gym.Env:
            return estimator_env(BASE_CONFIG, repeat, args.driver, args.population_seed)

        venv = DummyVecEnv([make for _ in range(num_envs)])
    venv = VecMonitor(venv)
    venv.seed(seed)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=max(16, 2048 // num_envs),
        batch_size=256,
        learning_rate=3e-4,
        gamma=0.99,
        seed=seed,
        device="cpu",
        verbose=0,
    )
    start = time.perf_counter()
    model.learn(total_timesteps=timesteps)
    elapsed = time.perf_counter() - start
    venv.close()
    return model, elapsed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variant", choices=("camera", "estimator", "both"), default="both")
    parser.add_argument(
        "--timesteps",
        type=int,
        default=None,
        help="PPO steps per variant (default: camera 50000, estimator 20000)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument(
        "--action-repeat", type=int, default=10, help="100 Hz samples per policy step"
    )
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--driver", default="Ill", help="synthetic driver (advisor, reference)")
    parser.add_argument("--population-seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--save", default=None, help="save the models as <SAVE>_<variant>.zip")
    args = parser.parse_args(argv)
    if (args.timesteps is not None and args.timesteps < 1) or min(
        args.num_envs, args.action_repeat, args.eval_episodes
    ) < 1:
        parser.error("--timesteps, --num-envs, --action-repeat, --eval-episodes must be positive")

    require_sb3()
    import torch

    torch.set_num_threads(args.threads)
    variants = ("camera", "estimator") if args.variant == "both" else (args.variant,)
    repeat = args.action_repeat
    eval_seed = 10_000 + args.seed  # episodes never seen in training

    runs: list[tuple[Any, Callable[[], gym.Env]]] = [
        (ConstantSteering(), lambda: SteeringOnly(gym.make(ENV_ID, config=BASE_CONFIG))),
        (
            DriverPolicy(advisor_driver(args.driver, args.population_seed)),
            lambda: SteeringOnly(gym.make(ENV_ID, config=BASE_CONFIG)),
        ),
    ]
    times: dict[str, tuple[int, float]] = {}
    for variant in variants:
        steps = args.timesteps or DEFAULT_TIMESTEPS[variant]
        print(f"training PPO ({variant}) for {steps} steps on {args.num_envs} envs ...")
        model, elapsed = train(variant, steps, args.seed, args.num_envs, repeat, args)
        times[variant] = (steps, elapsed)
        print(f"  done in {elapsed:.1f} s ({steps / elapsed:.0f} steps/s)")
        if args.save:
            model.save(f"{args.save}_{variant}")
        if variant == "camera":
            factory: Callable[[], gym.Env] = lambda: camera_env(BASE_CONFIG, repeat)  # noqa: E731
        else:
            factory = lambda: estimator_env(  # noqa: E731
                BASE_CONFIG, repeat, args.driver, args.population_seed
            )
        runs.append((SB3Policy(model, name=f"PPO ({variant})"), factory))

    print(
        f"\nevaluation: {args.eval_episodes} episodes of 30 s, seeds {eval_seed}.., "
        f"lanes balanced; PPO acts every {repeat / 100:.2f} s"
    )
    results: list[EvalResult] = []
    for policy, factory in runs:
        results.append(evaluate(policy, factory, args.eval_episodes, eval_seed))
        print(results[-1].line())
    zero = results[0]
    for result in results[2:]:
        beats = (
            result.mean_return > zero.mean_return
            and result.mean_abs_lateral_error < zero.mean_abs_lateral_error
            and result.offroad_rate <= zero.offroad_rate
        )
        print(
            f"{result.name} beats zero steering (higher return, lower mean |y|, no more "
            f"off-road episodes): {'yes' if beats else 'NO'}"
        )
    for variant, (steps, elapsed) in times.items():
        print(f"training time PPO ({variant}): {elapsed:.1f} s for {steps} steps")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
