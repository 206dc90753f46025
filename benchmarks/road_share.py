"""Does a steering model's one-step score show that it saw the road? Per driver archetype.

``python -m benchmarks.road_share [--population mixed] [--seeds 2500,2501,2502] [--size 12]
[--train-seed 2500] [--test-seeds 2501-2510] [--duration 30]``

For every driver of the population (each population seed): the road-blind AR(2) of the
steering (:class:`~hasa_env.steering.RoadBlindModel`, the benchmark's ``road_blind`` baseline) and the
generalized model (the paper's orders) are fitted on the driver's own run with
``--train-seed`` (``model.fit(run, sensor_std=0)``: the population's study conditions measure
the wheel's own reading) and scored one step ahead on its runs with ``--test-seeds``
(:func:`hasa_env.steering.scoring.score_runs`), on the straight track in the population's
``env_config``. Per archetype the table gives the mean R^2 on increments of both models, the
road share: the benchmark's road information (:func:`hasa_env.steering.road_information`,
1 - SSE_gen / SSE_AR2 of the one-step residuals, per run, averaged per driver; median over
drivers with a bootstrap interval over drivers),
SDLP and runs off the road. docs/design.md §7.9 reports it for "mixed".
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from benchmarks.protocol.intervals import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, percentile_interval
from hasa_env.drivers import POPULATIONS, population, run_population
from hasa_env.drivers.archetypes import ARCHETYPES, HumanParams, archetype_of
from hasa_env.steering import RoadBlindModel, road_information
from hasa_env.steering.models import GeneralizedModel
from hasa_env.steering.scoring import score_runs

__all__ = ["archetype_table", "driver_scores", "main"]

STRAIGHT = "hasa_env/LaneKeeping-v0"


def _runs_by_seed(
    params: Sequence[HumanParams], seeds: Sequence[int], config: Mapping[str, Any]
) -> dict[int, dict[str, Any]]:
    """{seed: {driver name: recording}}: every driver's run with each seed (all drivers in one
    vector env per seed; run 0 of ``run_population(seed=s)`` is ``run_driver(seed=s)``'s)."""
    return {
        s: {name: runs[0] for name, runs in run_population(params, 1, s, STRAIGHT, config).items()}
        for s in seeds
    }


def driver_scores(
    params: Sequence[HumanParams],
    config: Mapping[str, Any],
    train_seed: int,
    test_seeds: Sequence[int],
) -> list[dict[str, Any]]:
    """One row per driver: archetype, mean speed (m/s), SDLP (m), runs off the road, and per
    model ("road_blind", "generalized") the per-run R^2 on increments of the held-out runs."""
    runs = _runs_by_seed(params, [train_seed, *test_seeds], config)
    rows = []
    for p in params:
        train = runs[train_seed][p.name]
        test = [runs[s][p.name] for s in test_seeds]
        row: dict[str, Any] = {
            "driver": p.name,
            "archetype": archetype_of(p).name,
            "speed": float(np.mean([f["speed"].mean() for f in test])),
            "sdlp": float(np.mean([f["lateral_offset"].std() for f in test])),
            "off_road": sum(bool(f["terminated"].any()) for f in test),
            "runs": len(test),
        }
        residuals = {}
        for name, model in (("road_blind", RoadBlindModel()), ("generalized", GeneralizedModel())):
            with warnings.catch_warnings():  # a fit's warnings do not change its score
                warnings.simplefilter("ignore")
                fitted = model.fit(train, sensor_std=0.0)
            table = score_runs(fitted, test, free_run=False)
            row[name] = table["r2_increments"].to_numpy(dtype=np.float64)
            residuals[name] = [_one_step_residuals(fitted, f) for f in test]
        row["road_share"] = float(
            np.nanmean(
                [
                    road_information(mine, blind)
                    for mine, blind in zip(
                        residuals["generalized"], residuals["road_blind"], strict=True
                    )
                ]
            )
        )
        rows.append(row)
    return rows


def _one_step_residuals(model: Any, run: Any) -> np.ndarray:
    """Measured minus one-step predicted steering (rad), aligned with the run's rows."""
    features = model.features(run)
    prediction = np.asarray(model.predict_features(features), dtype=np.float64)
    return features["delta"].to_numpy(dtype=np.float64) - prediction


def _median_interval(values: np.ndarray) -> tuple[float, float]:
    """95 % bootstrap percentile interval of the median over drivers (the project's seed and
    resample count)."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    picks = rng.integers(0, len(values), (BOOTSTRAP_RESAMPLES, len(values)))
    low, high = percentile_interval(np.median(values[picks], axis=1)[:, None])
    return float(low[0]), float(high[0])


def archetype_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """The Markdown table of :func:`driver_scores`' rows, one line per archetype."""
    lines = [
        "| archetype | drivers | AR(2) R^2 inc | generalized R^2 inc | road share, median "
        "[95 % CI] | road share > 0 | SDLP (m), median [range] | off the road |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for archetype in [a for a in ARCHETYPES if any(r["archetype"] == a for r in rows)]:
        group = [r for r in rows if r["archetype"] == archetype]
        share = np.array([r["road_share"] for r in group])
        sdlp = np.array([r["sdlp"] for r in group])
        low, high = _median_interval(share)
        blind = np.mean([r["road_blind"].mean() for r in group])
        seeing = np.mean([r["generalized"].mean() for r in group])
        off = sum(r["off_road"] for r in group)
        lines.append(
            f"| {archetype} | {len(group)} | {blind:.3f} | {seeing:.3f} | "
            f"{np.median(share):.3f} [{low:.3f}, {high:.3f}] | {int((share > 0).sum())}/"
            f"{len(group)} | {np.median(sdlp):.2f} [{sdlp.min():.2f}-{sdlp.max():.2f}] | "
            f"{off}/{sum(r['runs'] for r in group)} runs |"
        )
    return "\n".join(lines)


def _seeds(text: str) -> list[int]:
    """ "2500,2501" or "2501-2510" (inclusive) as a list of seeds (an argparse type: a bad
    value is a usage error naming the option)."""
    out: list[int] = []
    try:
        for part in text.split(","):
            low, _, high = part.partition("-")
            out += list(range(int(low), int(high) + 1)) if high else [int(low)]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"comma-separated seeds or ranges A-B expected, got {text!r}"
        ) from None
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table (see the module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.road_share", description=__doc__)
    parser.add_argument("--population", default="mixed", choices=sorted(POPULATIONS))
    parser.add_argument("--seeds", type=_seeds, default="2500,2501,2502", help="population seeds")
    parser.add_argument("--size", type=int, default=12, help="drivers per population seed")
    parser.add_argument("--train-seed", type=int, default=2500)
    parser.add_argument("--test-seeds", type=_seeds, default="2501-2510")
    parser.add_argument("--duration", type=float, default=30.0, help="run length (s)")
    args = parser.parse_args(argv)
    config = dict(POPULATIONS[args.population].env_config) | {"time_limit": args.duration}
    rows = []
    for seed in args.seeds:
        rows += driver_scores(
            population(args.population, seed, args.size),
            config,
            args.train_seed,
            args.test_seeds,
        )
    print(archetype_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
