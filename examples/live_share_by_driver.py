"""Which drivers the steering was not live for, and what they have in common (issue 25's
live-share bar; docs/design.md §8.35).

Reads a ``hasa-bench paper`` output (its ``results.json``: the per-run estimation rows and the
drivers' parameters), takes one model's runs on one track, and prints per driver (seed, name)
the mean over its runs of the share of the time the steering was live and why it was not
(docs/design.md §8.14), the median model-error ratio lambda (the steering innovations' variance
over the filter's, 1: consistent) and the driver's traits: archetype, speed behaviour (the
target speed it ramps to, or "holds" its start speed), command-noise std (rad, the motor
stage's OU noise before the neuromuscular lag), neuromuscular natural frequency (rad/s) and
damping, and delay (s). Then how much of the time not live the fewest drivers hold, and the
rank (Spearman) correlation of lambda and of the live share with each trait.

Run:  hasa-bench paper --no-plots --out out/ && python examples/live_share_by_driver.py out/
      [--model generalized] [--track straight] [--worst 10]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import pandas as pd

from benchmarks.live_by_driver import SHARES, TRAITS, by_driver, least_live_share


def model_runs(results: dict[str, Any], model: str, track: str) -> pd.DataFrame:
    """``model``'s runs on ``track`` from ``results.json``'s ``runs_estimation``."""
    runs = pd.DataFrame(results["runs_estimation"])
    if runs.empty:
        raise SystemExit("results.json has no estimation runs (no run was filtered)")
    chosen = runs[(runs["model"] == model) & (runs["track"] == track)]
    if chosen.empty:
        models = ", ".join(sorted(runs["model"].unique()))
        tracks = ", ".join(sorted(runs["track"].unique()))
        raise SystemExit(
            f"no runs of model {model!r} on track {track!r}; models: {models}; tracks: {tracks}"
        )
    return chosen.assign(driver=chosen["driver"].astype(str), seed=chosen["seed"].astype(int))


def concentration(runs: pd.DataFrame, counts: tuple[int, ...] = (3, 5, 10)) -> dict[int, float]:
    """The share of the time not live, summed over ``runs``, that the ``k`` drivers with the
    most of it hold, for each k in ``counts`` (the report's column is k = 5)."""
    return {k: least_live_share(runs, k) for k in counts}


def correlations(table: pd.DataFrame) -> pd.DataFrame:
    """Spearman rank correlation of lambda and of the live share with each trait."""
    columns = ["model_error", "steering_live_share", *TRAITS]
    ranks = table[columns].corr(method="spearman")
    return ranks.loc[["model_error", "steering_live_share"], list(TRAITS)]


def main(argv: list[str] | None = None) -> pd.DataFrame:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", type=Path, help="hasa-bench's output folder or results.json")
    parser.add_argument("--model", default="generalized", help="model name (default generalized)")
    parser.add_argument("--track", default="straight", help="straight or curved")
    parser.add_argument("--worst", type=int, default=10, help="drivers listed (least live first)")
    args = parser.parse_args(argv)
    path = args.results / "results.json" if args.results.is_dir() else args.results
    try:
        results = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SystemExit(f"{path}: cannot read hasa-bench results: {exc}") from None
    runs = model_runs(results, args.model, args.track)
    table = by_driver(runs, results["drivers"])
    shown = table.sort_values("steering_live_share").rename(columns=SHARES)
    columns = ["seed", "driver", "runs", *SHARES.values(), "model_error", "lateral_rmse",
               "archetype", "speed", "command_std", "neuromuscular_frequency",
               "neuromuscular_damping", "delay"]  # fmt: skip
    with pd.option_context("display.width", 250, "display.max_columns", 30):
        print(f"{args.model} on the {args.track} track, {len(table)} drivers, least live first:")
        print(shown[columns].head(args.worst).to_string(index=False, float_format="{:.3g}".format))
        weighted = float((table["steering_live_share"] * table["runs"]).sum() / table["runs"].sum())
        print(f"\nsteering live {weighted:.1%} of the time over all runs")
        for k, share in concentration(runs).items():
            print(f"the {k} least-live drivers hold {share:.0%} of the time it was not live")
        print("\nSpearman correlation with the drivers' traits:")
        print(correlations(table).to_string(float_format="{:+.2f}".format))
    return table


if __name__ == "__main__":
    main()
