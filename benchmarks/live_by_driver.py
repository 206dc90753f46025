"""Which drivers the steering was not live for, and what they have in common (issue 25's
live-share bar; docs/design.md §8.35): per driver (seed, name), the mean over its runs of the
share of the time the steering was live and why it was not (docs/design.md §8.14), the median
model-error ratio lambda, and the driver's traits from the population (archetype, speed
behaviour, command-noise std, neuromuscular frequency and damping, delay; unknown for recorded
drivers). ``hasa-bench``'s report lists its least-live drivers (:func:`least_live_drivers`);
``examples/live_share_by_driver.py`` prints the whole table of one model."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pandas as pd

from benchmarks.protocol import BenchmarkResult

__all__ = [
    "LEAST_LIVE_DRIVERS",
    "SHARES",
    "TRAITS",
    "by_driver",
    "driver_traits",
    "least_live_drivers",
    "least_live_share",
]

LEAST_LIVE_DRIVERS = 5
"""How many least-live drivers the report names (and whose share of the time not live it
gives)."""

SHARES = {
    "steering_live_share": "live",
    "steering_tempered_model_error_share": "tempered: lambda",
    "steering_tempered_autocorrelation_share": "tempered: autocorr.",
    "steering_mismatch_share": "mismatch",
    "steering_off_share": "off",
    "steering_unused_share": "unused",
}
"""The per-run share columns of ``runs_estimation`` -> their short names."""

TRAITS = ("command_std", "neuromuscular_frequency", "neuromuscular_damping", "delay", "holds_speed")
"""The numeric traits of :func:`driver_traits` (``holds_speed``: 1 when the driver keeps its
start speed)."""


def driver_traits(drivers: Sequence[dict[str, Any]]) -> pd.DataFrame:
    """One row per (seed, driver) of ``results.json``'s ``drivers``: archetype, speed
    behaviour ("holds" or "to N m/s"), :data:`TRAITS` (NaN where a driver has no parameters:
    a recorded one)."""
    rows = []
    for entry in drivers:
        params = entry.get("parameters") or {}
        target = (params.get("speed") or {}).get("target_speed")
        rows.append(
            {
                "seed": int(entry["seed"]) if entry.get("seed") is not None else -1,
                "driver": str(entry["driver"]),
                "archetype": params.get("archetype", "?"),
                "speed": "holds" if target is None else f"to {target:.0f} m/s",
                "holds_speed": float(target is None),
                "command_std": (params.get("motor") or {}).get("command_std", float("nan")),
                "neuromuscular_frequency": params.get("neuromuscular_frequency", float("nan")),
                "neuromuscular_damping": params.get("neuromuscular_damping", float("nan")),
                "delay": params.get("delay", float("nan")),
            }
        )
    columns = ["seed", "driver", "archetype", "speed", *TRAITS]
    return pd.DataFrame(rows, columns=columns)


def _keyed(runs: pd.DataFrame) -> pd.DataFrame:
    """``runs`` with the driver keys of every table here: ``seed`` an integer (-1 for a
    recorded run, which has none) and ``driver`` a string, and ``not_live`` = 1 - live share."""
    return runs.assign(
        driver=runs["driver"].astype(str),
        seed=runs["seed"].fillna(-1).astype(int),
        not_live=1.0 - runs["steering_live_share"],
    )


def least_live_share(runs: pd.DataFrame, drivers: int = LEAST_LIVE_DRIVERS) -> float:
    """The share of the time the steering was not live, summed over ``runs`` (one
    estimator's, with ``seed``, ``driver`` and ``steering_live_share`` columns), that the
    ``drivers`` drivers (seed, name) with the most of it hold: near 1, a few drivers make the
    shortfall (docs/design.md §8.35). NaN: no time not live, or no driver columns."""
    if not {"seed", "driver", "steering_live_share"} <= set(runs.columns):
        return float("nan")
    not_live = _keyed(runs).groupby(["seed", "driver"])["not_live"].sum()
    total = float(not_live.sum())
    return float(not_live.nlargest(drivers).sum() / total) if total > 0 else float("nan")


def by_driver(runs: pd.DataFrame, drivers: Sequence[dict[str, Any]]) -> pd.DataFrame:
    """Per (seed, driver) of ``runs`` (one model's rows of ``runs_estimation`` on one track):
    the run count, the mean over its runs of each share of :data:`SHARES`, the median model-error
    ratio (``model_error``), the mean lateral RMSE and the not-live time in runs
    (``not_live_runs``: the sum over its runs of 1 - live share), with the traits."""
    table = (
        _keyed(runs)
        .groupby(["seed", "driver"])
        .agg(
            runs=("run", "size"),
            **{column: (column, "mean") for column in SHARES},
            model_error=("model_error_median", "median"),
            lateral_rmse=("lateral_rmse", "mean"),
            not_live_runs=("not_live", "sum"),
        )
    )
    traits = driver_traits(drivers)
    return table.reset_index().merge(traits, on=["seed", "driver"], how="left")


def least_live_drivers(
    result: BenchmarkResult, count: int = LEAST_LIVE_DRIVERS
) -> list[dict[str, Any]]:
    """Per steering model (built-in or user) on the main track, the ``count`` drivers that hold
    the most of its time not live (rows of :func:`by_driver` with ``model``; none for a model
    whose steering was live throughout, or without the share columns)."""
    frame = pd.DataFrame(result.runs_estimation)
    needed = {"model", "track", "seed", "driver", "run", *SHARES, "model_error_median"}
    if frame.empty or not needed <= set(frame.columns):
        return []
    kinds = {m["name"]: m.get("kind") for m in result.models}
    main = frame[frame["track"] == result.config.get("track", "straight")]
    main = main[main["steering_live_share"].notna()]
    rows: list[dict[str, Any]] = []
    for model in main["model"].unique():
        if kinds.get(model) not in ("builtin", "user"):
            continue
        table = by_driver(main[main["model"] == model], result.drivers)
        worst = table[table["not_live_runs"] > 0].nlargest(count, "not_live_runs")
        rows += [
            {"model": model, **{str(key): value for key, value in row.items()}}
            for row in worst.to_dict("records")
        ]
    return rows
