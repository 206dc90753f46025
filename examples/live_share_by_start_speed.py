"""How often the benchmark's generalized model counts as lane evidence on runs that start at
15-45 m/s (issue 25's live-share bar "on runs that start anywhere in 15-45 m/s").

For each population seed: fit and check the models as ``hasa-bench paper`` does
(``benchmarks.protocol.run.builtin_model``: the training runs, the prediction and lane-keeping
checks), take the generalized model's filter as the benchmark builds it
(``benchmarks.protocol.tasks.model_estimator``, the trust rule), drive the illustrative
driver "Ill" from each start speed (the training run's conditions with ``initial_state.speed``
set; the driver then keeps or changes speed as it does) and print per seed and start speed the
mean speed, the share of the time the steering was live and why it was not
(``estimators.calibration.steering_channel_shares``), and the lateral RMSE.

Run:  python examples/live_share_by_start_speed.py [--seeds 8300,8301] [--speeds 15,25,35,45]
      [--runs 6]
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.protocol.config import ILLUSTRATIVE
from benchmarks.protocol.run import builtin_model
from benchmarks.protocol.tasks import model_estimator
from estimators import run_estimator
from estimators.calibration import steering_channel_shares
from estimators.settings import FilterSettings
from hasa_cli import seed_list, speed_list
from hasa_env.drivers import SyntheticDriver, run_driver


def seed_rows(seed: int, speeds: list[float], runs: int) -> list[dict[str, Any]]:
    """One row per start speed of ``seed``: the runs' mean speed, steering shares and error."""
    config, plan, generalized = builtin_model(seed)
    rows = []
    for speed in speeds:
        frames = run_driver(
            SyntheticDriver(plan.params[ILLUSTRATIVE]),
            runs=runs,
            seed=seed * 1000 + int(round(speed)),
            config=config.training_speed_config(speed),
        )
        base = FilterSettings.from_env_config(frames[0].attrs["config"])
        result = run_estimator(model_estimator(generalized, base), frames)
        shares = {k: float(np.nanmean(v)) for k, v in steering_channel_shares(result).items()}
        rows.append(
            {
                "seed": seed,
                "start_speed": speed,
                "mean_speed": float(np.mean([f["speed"].mean() for f in frames])),
                **shares,
                "lateral_rmse": float(np.mean(result.lateral_rmse())),
            }
        )
    return rows


def main(argv: list[str] | None = None) -> pd.DataFrame:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--seeds", type=seed_list, default=(8300, 8301), help="population seeds (8300,8301)"
    )
    parser.add_argument(
        "--speeds", type=speed_list, default=(15.0, 25.0, 35.0, 45.0),
        help="start speeds, m/s (15,25,35,45)",
    )  # fmt: skip
    parser.add_argument("--runs", type=int, default=6, help="runs of 'Ill' per speed (6)")
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error(f"--runs must be at least 1, got {args.runs}")
    seeds, speeds = list(args.seeds), list(args.speeds)
    table = pd.DataFrame([row for seed in seeds for row in seed_rows(seed, speeds, args.runs)])
    with pd.option_context("display.width", 220, "display.float_format", "{:.3g}".format):
        print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
