"""What a level of the equation error per driver would buy (issue 25's live share; an
exploration, docs/design.md §8.35).

The benchmark's generalized model carries one speed-scaled equation error for every driver,
fitted on the training drivers' held-out residuals (docs/design.md §8.34). Drivers differ in
their command noise and neuromuscular lag, and the evidence rule tempers the steering of those
whose residuals are larger than that level (the model-error ratio lambda) or more
autocorrelated. Here each driver first drives one calibration run, not scored; the model keeps
its coefficients and only its speed-scaled error (coloured std, correlation, white std) is
refitted on that run (:func:`estimators.tuning.speed_scaled_equation_error`, in sample; the
trust rule's gain measured there too). The driver's next runs are filtered with both errors,
the pooled one and the driver's own, and the table gives per seed and error the share of the
time the steering was live and why not (``estimators.calibration.steering_channel_shares``),
the share of the time the true lane's weight was above 0.95 (decided right), the lateral
RMSE, the runs ever and finally confidently in a wrong lane (weight above 0.95),
the runs ending refused (``model_mismatch``) and the drivers whose own error was not
identified (they keep the pooled one).

Run:  python examples/per_driver_error_level.py [--seeds 8300,8301] [--runs 4] [--csv rows.csv]
      [--at-least-pooled]
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.protocol.run import builtin_model
from benchmarks.protocol.tasks import model_estimator
from estimators import run_estimator
from estimators.calibration import steering_channel_shares
from estimators.settings import FilterSettings
from estimators.tuning import speed_scaled_equation_error, speed_scaled_gain
from hasa_cli import seed_list
from hasa_env.drivers import SyntheticDriver, run_driver

THRESHOLD = 0.95


def with_driver_level(
    fitted: Any, calibration: pd.DataFrame, at_least_pooled: bool = False
) -> tuple[Any, bool]:
    """``fitted`` (a FittedModel) with its speed-scaled error refitted on one calibration run
    of a driver, and whether one was found (not: ``fitted`` as it is). ``at_least_pooled``:
    each level (coloured and white std) no smaller than the pooled one, so the driver's own
    level can only make the steering count less than the pooled level does."""
    model = copy.deepcopy(fitted.model)
    found = speed_scaled_equation_error(model, [calibration])
    if found is None:
        return fitted, False
    if at_least_pooled:
        pooled = fitted.model.equation_error_speed_scaled
        found = dataclasses.replace(
            found,
            coloured_std=max(found.coloured_std, pooled.coloured_std),
            white_std=max(found.white_std, pooled.white_std),
        )
    model.equation_error_speed_scaled = found
    training = dataclasses.replace(
        fitted.training, speed_scaled_gain=speed_scaled_gain(model, [calibration])
    )
    return dataclasses.replace(fitted, model=model, training=training), True


def summary(result: Any) -> dict[str, float]:
    """The runs' mean channel shares and lateral RMSE, and counts of their lane outcomes."""
    shares = {k: float(np.nanmean(v)) for k, v in steering_channel_shares(result).items()}
    decided_right = (result.true_lane_weight() > THRESHOLD) & result.valid
    return {
        **shares,
        "decided_right": float(np.mean(decided_right.sum(axis=1) / result.lengths)),
        "lateral_rmse": float(np.mean(result.lateral_rmse())),
        "ever_wrong": int(result.wrong_decision_ever(THRESHOLD).sum()),
        "ends_wrong": int(result.wrong_lane_confident(THRESHOLD).sum()),
        "ends_refused": int(np.sum(result.final_decision() == "model_mismatch")),
    }


def seed_rows(seed: int, runs: int, at_least_pooled: bool = False) -> list[dict[str, Any]]:
    """Per driver of ``seed``: one calibration run, ``runs`` scored runs filtered with the
    pooled error and with the driver's own."""
    config, plan, fitted = builtin_model(seed)
    rows = []
    for index, (name, params) in enumerate(plan.params.items()):
        frames = run_driver(
            SyntheticDriver(params),
            runs=runs + 1,
            seed=seed * 1000 + 100 + index,
            config=config.env_config(),
        )
        base = FilterSettings.from_env_config(frames[0].attrs["config"])
        own, found = with_driver_level(fitted, frames[0], at_least_pooled)
        for error, model in (("pooled", fitted), ("per driver", own)):
            result = run_estimator(model_estimator(model, base), frames[1:])
            rows.append(
                {
                    "seed": seed,
                    "driver": name,
                    "error": error,
                    "runs": runs,
                    "own_found": found,
                    **summary(result),
                }  # fmt: skip
            )
    return rows


def main(argv: list[str] | None = None) -> pd.DataFrame:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--seeds", type=seed_list, default=(8300, 8301), help="population seeds (8300,8301)"
    )
    parser.add_argument("--runs", type=int, default=4, help="scored runs per driver (4)")
    parser.add_argument("--csv", help="also write the per-driver rows to this CSV file")
    parser.add_argument(
        "--at-least-pooled", action="store_true",
        help="the driver's levels no smaller than the pooled ones (it can only count less)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error(f"--runs must be at least 1, got {args.runs}")
    drivers = pd.DataFrame(
        [row for seed in args.seeds for row in seed_rows(seed, args.runs, args.at_least_pooled)]
    )
    weighted = drivers.assign(
        **{k: drivers[k] * drivers["runs"] for k in ("live", "decided_right", "lateral_rmse")}
    ).groupby(["seed", "error"], sort=False)
    means = ["live", "decided_right", "lateral_rmse"]
    table = weighted[[*means, "runs"]].sum()
    table[means] = table[means].div(table["runs"], axis=0)
    counts = drivers.groupby(["seed", "error"], sort=False)
    table = table.join(counts[["ever_wrong", "ends_wrong", "ends_refused"]].sum())
    table["own_not_found"] = counts["own_found"].apply(lambda found: int((~found).sum()))
    with pd.option_context("display.width", 220, "display.float_format", "{:.3g}".format):
        print(table.reset_index().to_string(index=False))
    if args.csv:
        drivers.to_csv(args.csv, index=False)
    return drivers


if __name__ == "__main__":
    main()
