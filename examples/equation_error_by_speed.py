"""The generalized model's equation error by speed, and what filtering with it at the speed, or
on the run itself, would give (docs/design.md §8.33; issue 25's live-share bar).

The benchmark's generalized model (fitted and checked as ``hasa-bench paper`` does,
``benchmarks.protocol.run.builtin_model``) has one equation error for every speed: the level
and the AR(2) of its one-step residuals pooled over its training runs (§8.32). The population's
drivers add their command noise before the neuromuscular lag scaled by ``(15 / v)^2``, the
steering a given lateral acceleration needs (§7.2), and their remnant after it unscaled; so the
residuals of one model are larger and more autocorrelated at low speed than at high speed.

``--speeds`` (default): for each population seed and start speed of "Ill" (the runs of
``examples/live_share_by_start_speed.py``), the one-step residuals of the model on the true
state (:func:`estimators.tuning.steering_residuals`): their level, their lag-1 and lag-2
autocorrelation, the lag-1 autocorrelation left after whitening by the pooled AR; then the
runs filtered twice, with the trust rule's filter (``pooled``) and with the same filter given
the level and the AR(2) measured on 4 more runs of "Ill" from that start speed, seeds of their
own (``at speed``): the steering's live share, lateral RMSE and NEES, runs confidently in the
wrong lane at some step.

``--scenarios S1,S2``: instead, each scored run of those scenarios filtered with the level and
the AR(2) of the model's residuals on that run itself (``own run``; in-sample, an upper bound
for any online estimate of the equation error) against the pooled one; live share, lateral
RMSE, NEES, lane ECE, runs ending / ever confidently wrong.

Run:  python examples/equation_error_by_speed.py [--seeds 8700,8701] [--speeds 15,25,35,45]
      [--runs 6]
      python examples/equation_error_by_speed.py --scenarios paper,close_hypotheses
      [--seeds 8700] [--runs 94]
"""

from __future__ import annotations

import argparse
import copy
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.protocol.config import ILLUSTRATIVE, ProtocolConfig
from benchmarks.protocol.models import FittedModel
from benchmarks.protocol.plan import load_frames
from benchmarks.protocol.run import builtin_model
from benchmarks.protocol.tasks import model_estimator
from estimators import run_estimator
from estimators.calibration import (
    expected_calibration_error,
    lane_calibration_bins,
    steering_channel_shares,
)
from estimators.offline import EstimationResult
from estimators.settings import FilterSettings
from estimators.tuning import steering_residuals
from hasa_cli import seed_list, speed_list
from hasa_env.drivers import SyntheticDriver, run_driver
from hasa_env.scenarios import SCENARIOS
from hasa_env.steering.equation_error import equation_error_autoregression

ORDER = 2
"""Lags of the equation error's AR measured at a speed or on a run (the benchmark's)."""


def residuals(fm: FittedModel, frames: list[pd.DataFrame]) -> list[np.ndarray]:
    """Per run, the model's one-step residuals on the true state (rad)."""
    arx, lag = fm.model.arx(), int(getattr(fm.model, "decision_lag", 1))
    return [steering_residuals(arx, frame, decision_lag=lag) for frame in frames]


def autocorrelation(series: list[np.ndarray], lags: int) -> np.ndarray:
    """Lag 1..``lags`` autocorrelation pooled over runs (each run's mean removed)."""
    products = np.zeros(lags + 1)
    for x in series:
        x = x - x.mean()
        products += [np.dot(x[k:], x[: x.size - k]) for k in range(lags + 1)]
    return products[1:] / products[0]


def whitened(x: np.ndarray, ar: tuple[float, ...]) -> np.ndarray:
    """``x(k) - sum_i r_i x(k - i)`` from the first sample with a full history."""
    p = len(ar)
    return x[p:] - sum(r * x[p - i : x.size - i] for i, r in enumerate(ar, 1))


def with_equation_error(fm: FittedModel, series: list[np.ndarray]) -> FittedModel:
    """``fm`` with the level (RMS) and AR(2) of ``series`` as its equation error."""
    model = copy.copy(fm.model)
    model.equation_error_ar = equation_error_autoregression(series, ORDER)
    level = float(np.sqrt(np.mean(np.concatenate(series) ** 2)))
    training = replace(fm.training, whitened_residual_std=None)
    return replace(fm, model=model, residual_std=level, training=training)


def scores(results: list[EstimationResult]) -> dict[str, float]:
    """Live share, lateral RMSE and NEES, lane ECE, runs ending / ever confidently wrong."""
    bins = sum(lane_calibration_bins(r).sum(axis=0) for r in results)
    return {
        "live": float(
            np.nanmean(np.concatenate([steering_channel_shares(r)["live"] for r in results]))
        ),
        "lateral_rmse": float(np.mean(np.concatenate([r.lateral_rmse() for r in results]))),
        "lateral_nees": float(np.nanmean(np.concatenate([r.lateral_nees() for r in results]))),
        "lane_ece": expected_calibration_error(bins),
        "ends_wrong": int(sum(r.wrong_lane_confident().sum() for r in results)),
        "ever_wrong": int(sum(r.wrong_decision_ever().sum() for r in results)),
    }


def ill_runs(
    config: ProtocolConfig, plan: Any, seed: int, speed: float, runs: int, offset: int
) -> list[pd.DataFrame]:
    """``runs`` runs of "Ill" from start ``speed`` (m/s), seeds ``seed * 1000 + speed +
    offset`` (offset 0: those of examples/live_share_by_start_speed.py)."""
    return run_driver(
        SyntheticDriver(plan.params[ILLUSTRATIVE]),
        runs=runs,
        seed=seed * 1000 + int(round(speed)) + offset,
        config=config.training_speed_config(speed),
    )


def speed_rows(seed: int, speeds: list[float], runs: int) -> list[dict[str, Any]]:
    """Per start speed of ``seed``: the residuals' statistics, then pooled vs at speed."""
    config, plan, fm = builtin_model(seed)
    rows = []
    for speed in speeds:
        test = ill_runs(config, plan, seed, speed, runs, 0)
        calibration = ill_runs(config, plan, seed, speed, 4, 500)
        own = residuals(fm, test)
        base = FilterSettings.from_env_config(test[0].attrs["config"])
        at_speed = with_equation_error(fm, residuals(fm, calibration))
        stats = {
            "seed": seed,
            "start_speed": speed,
            "mean_speed": float(np.mean([f["speed"].mean() for f in test])),
            "residual_rms": float(np.sqrt(np.mean(np.concatenate(own) ** 2))),
            "pooled_level": fm.residual_std,
            "acf1": autocorrelation(own, 2)[0],
            "acf2": autocorrelation(own, 2)[1],
            "whitened_acf1": autocorrelation(
                [whitened(x, fm.model.equation_error_ar) for x in own], 1
            )[0],
        }
        for name, model in (("pooled", fm), ("at speed", at_speed)):
            result = run_estimator(model_estimator(model, base), test)
            rows.append(
                stats
                | {
                    "equation_error": name,
                    "ar": tuple(round(r, 3) for r in model.model.equation_error_ar),
                }
                | scores([result])
            )
    return rows


def own_run_rows(seed: int, scenario: str, runs: int) -> list[dict[str, Any]]:
    """``scenario``'s first ``runs`` scored runs of ``seed``: pooled vs each run's own."""
    _, plan, fm = builtin_model(seed, "generalized", scenario)
    frames = load_frames(plan.main[:runs], plan.track, plan.env_config, plan.params)
    base = FilterSettings.from_env_config(frames[0].attrs["config"])
    pooled = [run_estimator(model_estimator(fm, base), frames)]
    own = [
        run_estimator(model_estimator(with_equation_error(fm, residuals(fm, [f])), base), [f])
        for f in frames
    ]
    head = {"scenario": scenario, "seed": seed, "runs": len(frames)}
    return [
        head | {"equation_error": "pooled"} | scores(pooled),
        head | {"equation_error": "own run"} | scores(own),
    ]


def main(argv: list[str] | None = None) -> pd.DataFrame:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--seeds", type=seed_list, default=(8700, 8701), help="population seeds (8700,8701)"
    )
    parser.add_argument(
        "--speeds", type=speed_list, default=(15.0, 25.0, 35.0, 45.0),
        help="start speeds, m/s (15,25,35,45)",
    )  # fmt: skip
    parser.add_argument(
        "--scenarios", default="", help="filter each scored run with its own equation error"
    )
    parser.add_argument(
        "--runs", type=int, default=None, help="runs per speed (6) / per scenario (all)"
    )
    args = parser.parse_args(argv)
    seeds, speeds = list(args.seeds), list(args.speeds)
    scenarios = [s for s in args.scenarios.split(",") if s.strip()]
    unknown = sorted(set(scenarios) - set(SCENARIOS))
    if unknown:
        parser.error(f"unknown scenario(s) {unknown}; known: {', '.join(SCENARIOS)}")
    if args.runs is not None and args.runs < 1:
        parser.error(f"--runs must be at least 1, got {args.runs}")
    if scenarios:
        runs = 10**6 if args.runs is None else args.runs
        rows = [r for s in scenarios for seed in seeds for r in own_run_rows(seed, s, runs)]
    else:
        runs = 6 if args.runs is None else args.runs
        rows = [r for seed in seeds for r in speed_rows(seed, speeds, runs)]
    table = pd.DataFrame(rows)
    with pd.option_context("display.width", 250, "display.float_format", "{:.3g}".format):
        print(table.to_string(index=False))
    return table


if __name__ == "__main__":
    main()
