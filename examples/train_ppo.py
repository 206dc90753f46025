"""Train Stable-Baselines3 PPO to keep the lane, and compare it with a human and zero steering.

Two tasks, both steering only (the acceleration is held at 0 m/s^2, so the car keeps its
15 m/s) and acting at 10 Hz (``--action-repeat 10`` of the 100 Hz simulation), both
trained on native vector envs through ``hasa_env.rl.SB3VecEnv``:

- ``camera``: ``hasa_env/LaneKeeping-v0``'s sensors (speed, the *biased* camera,
  heading, IMU, steering);
- ``advisor``: the human-as-advisor task ``hasa_env/LaneKeepingAdvisor-v0``
  (:mod:`advisor_tasks.env`): PPO drives; a synthetic human of the "paper"
  population (a new one each episode) advises by steering alongside, and the
  Gaussian-mixture EKF, stepping at every 100 Hz sample inside each 10 Hz step, turns
  that advice into the estimate PPO observes (lateral offset and its std, heading,
  speed, lane weights) with the raw sensors.

Episodes: 30 s on the straight road, two equally likely lane centres (camera bias 0 or
-1.8 m), start at y = -0.5 m with std 0.5 m and heading std 0.02 rad, under the "paper"
population's study conditions (crosswind and camber of 0.1 m/s^2; the advisor task
applies them by default, the other policies get them too). Every policy is evaluated on
the same seeded episodes, each lane hypothesis equally often: mean |y| of the true offset
at every 100 Hz sample, the return summed over the 100 Hz rewards (PPO's actions held for
10 samples; the advisor task evaluated at action_repeat 1 under ``ActionRepeat``, the same
episodes bit for bit), and the share of episodes that left the road.

PPO runs on normalized observations and rewards (SB3's ``VecNormalize``; the evaluation
uses the training's observation statistics), with a learning rate decaying linearly to 0:
the observations mix speeds of 15 m/s with offsets of centimetres, and without the
normalization the advisor-task policy of 300k steps kept the start offset of -0.5 m
whenever the camera bias was 0 (mean |y| 0.47 m).

Usage::

    python examples/train_ppo.py                        # both tasks (camera 150k, advisor 400k steps)
    python examples/train_ppo.py --variant advisor --curve docs/advisor_ppo_curve.png
    python examples/train_ppo.py --variant camera --timesteps 20000 --num-envs 8 --seed 1

Needs the RL extra (``pip install "hasa-env[rl]"``: stable-baselines3, torch).
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import advisor_tasks  # noqa: F401 - registers the advisor ids (and hasa_env's)
from hasa_env.drivers import POPULATIONS, SpeedProfile, SyntheticDriver, population
from hasa_env.rl import (
    ActionRepeat,
    ConstantSteering,
    DriverPolicy,
    EvalResult,
    SB3Policy,
    SteeringOnly,
    evaluate,
    make_vector_env,
    require_sb3,
)
from hasa_env.sim.config import deep_merge

CAMERA_ID = "hasa_env/LaneKeeping-v0"
ADVISOR_ID = "hasa_env/LaneKeepingAdvisor-v0"
CONDITIONS: dict[str, Any] = deep_merge(
    POPULATIONS["paper"].env_config,
    {
        "initial_state": {"lateral_offset_std": 0.5, "heading_std": 0.02},
        "action": {"max_steering": 0.1},
    },
)
"""The episodes: the default env (100 Hz, 30 s, lanes {0, -1.8} m), a random start, the
"paper" population's study conditions (disturbances; the wheel read without noise), and
steering actions within +-0.1 rad (lane keeping at 15 m/s needs a few hundredths; a policy
free to turn 0.5 rad throws the car about, which also throws the estimator off)."""
DEFAULT_TIMESTEPS = {"camera": 150_000, "advisor": 400_000}
"""PPO steps per task."""
DEFAULT_NUM_ENVS = {"camera": 16, "advisor": 64}
"""Cars per vector env: the advisor task's humans and estimators are cheaper per car in
larger batches."""


def advisor_driver(name: str = "Ill", seed: int = 0) -> SyntheticDriver:
    """Driver ``name`` of the seeded "paper" population, holding its initial speed."""
    drivers = {p.name: p for p in population("paper", seed)}
    if name not in drivers:
        raise SystemExit(f"unknown driver {name!r}; choose one of {', '.join(drivers)}")
    return SyntheticDriver(dataclasses.replace(drivers[name], speed=SpeedProfile.hold()))


def camera_env(repeat: int) -> gym.Env:
    """Single 100 Hz env, steering only, action held for ``repeat`` samples (evaluation)."""
    return ActionRepeat(SteeringOnly(gym.make(CAMERA_ID, config=CONDITIONS)), repeat)


def advisor_config(repeat: int) -> dict[str, Any]:
    """The advisor task's config: the episodes above at ``repeat`` samples per step."""
    return deep_merge(CONDITIONS, {"action_repeat": repeat})


def advisor_eval_env(repeat: int) -> gym.Env:
    """The advisor task at 100 Hz with each action held for ``repeat`` steps: the same
    episodes as ``action_repeat = repeat`` bit for bit (docs/design.md §12.2), with the
    return summed over the 100 Hz rewards as for the other policies."""
    return ActionRepeat(gym.make(ADVISOR_ID, config=advisor_config(1)), repeat)


class LateralOffsetCurve:
    """Mean |y| (m) of the true offset against the training steps, two ways: over each PPO
    rollout (the stochastic training policy, from the infos' ``substep_lateral_offset``:
    every 100 Hz sample) and at checkpoints, evaluating the deterministic policy on
    ``episodes`` fixed episodes (lanes balanced; seeds 20000.., never the final
    evaluation's). The best checkpoint is kept (:meth:`restore_best`): PPO's policy
    wanders from checkpoint to checkpoint (0.1-0.3 m on the same episodes)."""

    def __init__(self, every: int, episodes: int, repeat: int) -> None:
        self.every, self.episodes, self.repeat = every, episodes, repeat
        self.steps: list[int] = []
        self.rollout_mean_abs_y: list[float] = []
        self.checkpoint_steps: list[int] = []
        self.checkpoint_mean_abs_y: list[float] = []
        self.evaluation_seconds = 0.0
        self.best: tuple[int, float, Any, Any] | None = None
        self._total, self._count = 0.0, 0

    def add(self, infos: list[dict[str, Any]]) -> None:
        for info in infos:
            offsets = np.abs(np.asarray(info["substep_lateral_offset"]))
            self._total += float(offsets.sum())
            self._count += offsets.size

    def close_rollout(self, timesteps: int) -> None:
        if self._count:
            self.steps.append(int(timesteps))
            self.rollout_mean_abs_y.append(self._total / self._count)
        self._total, self._count = 0.0, 0

    def checkpoint(self, timesteps: int, model: Any, normalizer: Any) -> None:
        """Evaluate the policy now; keep its parameters if it is the best so far."""
        start = time.perf_counter()
        policy = SB3Policy(model, normalize=normalizer.normalize_obs)
        result = evaluate(policy, lambda: advisor_eval_env(self.repeat), self.episodes, 20_000)
        self.checkpoint_steps.append(int(timesteps))
        self.checkpoint_mean_abs_y.append(result.mean_abs_lateral_error)
        if self.best is None or result.mean_abs_lateral_error < self.best[1]:
            parameters = copy.deepcopy(model.policy.state_dict())
            self.best = (int(timesteps), result.mean_abs_lateral_error, parameters,
                         copy.deepcopy(normalizer.obs_rms))  # fmt: skip
        self.evaluation_seconds += time.perf_counter() - start

    def restore_best(self, model: Any, normalizer: Any) -> int | None:
        """Put the best checkpoint's parameters and observation statistics back; its step."""
        if self.best is None:
            return None
        steps, _, parameters, obs_rms = self.best
        model.policy.load_state_dict(parameters)
        normalizer.obs_rms = obs_rms
        return steps

    def save_plot(self, path: str, evaluated: float | None) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6.4, 3.8))
        ax.plot(self.steps, self.rollout_mean_abs_y, color="C0", alpha=0.6,
                label="training rollouts (stochastic policy)")  # fmt: skip
        ax.plot(self.checkpoint_steps, self.checkpoint_mean_abs_y, "o-", color="C1",
                label=f"deterministic policy, {self.episodes} checkpoint episodes")  # fmt: skip
        if self.best is not None:
            ax.plot([self.best[0]], [self.best[1]], "*", color="C3", ms=12, label="kept")
        if evaluated is not None:
            ax.axhline(evaluated, color="C2", ls="--",
                       label=f"kept policy, 20 evaluation episodes: {evaluated:.3f} m")  # fmt: skip
        ax.axhline(0.15, color="grey", lw=0.8, ls=":", label="0.15 m")
        ax.set_xlabel("PPO training steps (10 Hz env steps)")
        ax.set_ylabel("mean |y| (m)")
        ax.set_yscale("log")
        ax.set_title("PPO on LaneKeepingAdvisor-v0: the car drives, a human advises", fontsize=10)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=120)
        plt.close(fig)


def _curve_callback(curve: LateralOffsetCurve) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class Callback(BaseCallback):
        def _on_step(self) -> bool:
            curve.add(self.locals["infos"])
            return True

        def _on_rollout_end(self) -> None:
            curve.close_rollout(self.num_timesteps)
            due = len(curve.checkpoint_steps) * curve.every
            if curve.every and self.num_timesteps >= due:
                curve.checkpoint(self.num_timesteps, self.model, self.model.get_env())

    return Callback()


def train(
    variant: str, timesteps: int, seed: int, num_envs: int, repeat: int, curve: LateralOffsetCurve
) -> tuple[Any, Any, float]:
    """Train PPO on one task; returns (model, its VecNormalize, wall-clock training time in s)."""
    require_sb3()
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from hasa_env.rl import SB3VecEnv

    if variant == "camera":
        config = deep_merge(CONDITIONS, {"action_repeat": repeat})
        vector = make_vector_env(CAMERA_ID, num_envs, config, steering_only=True)
    else:
        vector = gym.make_vec(
            ADVISOR_ID,
            num_envs=num_envs,
            vectorization_mode="vector_entry_point",
            config=advisor_config(repeat),
        )
    # observations of very different scales (speeds of 15 m/s beside offsets of cm) and a
    # reward whose gradient is small near the lane centre: normalize both
    venv = VecNormalize(VecMonitor(SB3VecEnv(vector)), norm_obs=True, norm_reward=True, gamma=0.99)
    venv.seed(seed)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=max(16, 4096 // num_envs),
        batch_size=512,
        learning_rate=lambda remaining: 3e-4 * remaining,  # linear decay to 0
        gamma=0.99,
        seed=seed,
        device="cpu",
        verbose=0,
    )
    start = time.perf_counter()
    callback = _curve_callback(curve) if variant == "advisor" else None
    model.learn(total_timesteps=timesteps, progress_bar=True, callback=callback)
    elapsed = time.perf_counter() - start
    if variant == "advisor":
        elapsed -= curve.evaluation_seconds  # the checkpoints are not training
        kept = curve.restore_best(model, venv)
        if kept is not None:
            print(f"  kept the checkpoint of {kept} steps (best on the checkpoint episodes)")
    venv.training = False  # evaluation uses the training's observation statistics
    venv.close()
    return model, venv, elapsed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variant", choices=("camera", "advisor", "both"), default="both")
    parser.add_argument(
        "--timesteps",
        type=int,
        default=None,
        help="PPO steps per task (default: camera 150000, advisor 400000)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--num-envs", type=int, default=None, help="cars per vector env (camera 16, advisor 64)"
    )
    parser.add_argument(
        "--action-repeat", type=int, default=10, help="100 Hz samples per policy step"
    )
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--driver", default="Ill", help="the synthetic driver of the reference row")
    parser.add_argument("--population-seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--save", default=None, help="save the models as <SAVE>_<variant>.zip")
    parser.add_argument(
        "--curve", default=None, help="save the advisor task's |y| training curve (PNG)"
    )
    parser.add_argument(
        "--checkpoint-every",
        type=int,
        default=25_000,
        help="advisor task: training steps between checkpoints (0: none); each is evaluated "
        "on --checkpoint-episodes episodes of its own seeds (not timed) and the best is kept",
    )
    parser.add_argument("--checkpoint-episodes", type=int, default=8)
    args = parser.parse_args(argv)
    if (args.timesteps is not None and args.timesteps < 1) or min(
        args.num_envs or 1, args.action_repeat, args.eval_episodes
    ) < 1:
        parser.error("--timesteps, --num-envs, --action-repeat, --eval-episodes must be positive")

    require_sb3()
    import torch

    torch.set_num_threads(args.threads)
    variants = ("camera", "advisor") if args.variant == "both" else (args.variant,)
    repeat = args.action_repeat
    eval_seed = 10_000 + args.seed  # episodes never seen in training

    def plain() -> gym.Env:
        return SteeringOnly(gym.make(CAMERA_ID, config=CONDITIONS))

    runs: list[tuple[Any, Callable[[], gym.Env]]] = [
        (ConstantSteering(), plain),
        (DriverPolicy(advisor_driver(args.driver, args.population_seed)), plain),
    ]
    times: dict[str, tuple[int, float]] = {}
    curve = LateralOffsetCurve(args.checkpoint_every, args.checkpoint_episodes, repeat)
    for variant in variants:
        steps = args.timesteps or DEFAULT_TIMESTEPS[variant]
        num_envs = args.num_envs or DEFAULT_NUM_ENVS[variant]
        print(f"training PPO ({variant}) for {steps} steps on {num_envs} envs ...")
        model, normalizer, elapsed = train(variant, steps, args.seed, num_envs, repeat, curve)
        times[variant] = (steps, elapsed)
        print(f"  done in {elapsed:.1f} s ({steps / elapsed:.0f} steps/s)")
        if args.save:
            model.save(f"{args.save}_{variant}")
            normalizer.save(f"{args.save}_{variant}_vecnormalize.pkl")
        if variant == "camera":
            factory: Callable[[], gym.Env] = lambda: camera_env(repeat)  # noqa: E731
        else:
            factory = lambda: advisor_eval_env(repeat)  # noqa: E731
        policy = SB3Policy(model, name=f"PPO ({variant})", normalize=normalizer.normalize_obs)
        runs.append((policy, factory))

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
    if args.curve and curve.steps:
        evaluated = next(
            (r.mean_abs_lateral_error for r in results if r.name == "PPO (advisor)"), None
        )
        curve.save_plot(args.curve, evaluated)
        print(f"wrote {args.curve}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
