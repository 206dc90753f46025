"""Tuning the synthetic population's steering noise to human statistics (paper table 1).

``python -m benchmarks.population_tuning [--population paper] [--seeds 0,1,2]
[--grid 0.5,1,2] [--pedal-grid 0,0.5,2] [--write docs/population_tuning.md]``

What is matched: the one-step steering RMSE of the two fitted models (two-point
and generalized, fitted on each seed's training run like ``hasa-bench paper``),
scored on the *measured* steering, per driver, against the paper's table 1
converted to road-wheel radians (divided by the steering ratio 15). The
target: the median over drivers of ours / the paper's in [1/3, 3] for both
models. The constraint: the drivers must still drive like people keeping a
lane (standard deviation of the lateral position, SDLP, of tenths of a metre;
no run off the road). Nothing here looks at the paper's table 2 (estimation):
the protocol runs without the estimator (``ProtocolConfig(estimate=False)``).

The knob is the population's ``command_scale`` (the command noise before the
neuromuscular lag, :class:`hasa_env.drivers.MotorParams`); ``--grid`` scores
the population with the command noise scaled by each factor (drivers and runs
otherwise the same), so the chosen value's place among its neighbours is
visible. ``--pedal-grid`` does the same for the pedal remnant (the speed's
wander, :class:`hasa_env.drivers.SpeedProfile`; 0 removes it), which is not
calibrated but chosen as a plain human figure (docs/design.md §7.4): the grid
shows what the numbers owe to it. ``--write`` writes the Markdown report with a JSON block of every
number; ``tests/test_population_tuning.py`` reruns one seed and checks that the report has the
structure :func:`write_report` writes (its command, sections and tables), not pasted numbers.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from collections.abc import Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.protocol import ProtocolConfig, run_protocol
from benchmarks.protocol.aggregate import confidence_interval
from hasa_env.drivers import POPULATIONS

__all__ = ["RANGE", "command_parser", "evaluate", "main", "write_report"]

RANGE = (1.0 / 3.0, 3.0)
"""The accepted range of the median ours / paper one-step RMSE (issue 10)."""
MODELS = ("two_point", "generalized")
JSON_START = "<!-- population-tuning-json"
JSON_END = "-->"


@contextlib.contextmanager
def _variant(
    population: str, command_scale: float | None, pedal_scale: float | None = None
) -> Iterator[str]:
    """The name of ``population`` with its command noise and / or pedal remnant scaled
    (registered while in use; the same drivers otherwise)."""
    if command_scale is None and pedal_scale is None:
        yield population
        return
    spec = POPULATIONS[population]
    command = 1.0 if command_scale is None else command_scale
    pedal_factor = 1.0 if pedal_scale is None else pedal_scale
    name = f"{population}@command_scale={command:g},pedal_scale={pedal_factor:g}"
    # pedal x 0 is no pedal remnant at all (its draws come from a stream of their own)
    pedal = None if spec.pedal is None or pedal_factor == 0 else spec.pedal.scaled(pedal_factor)
    POPULATIONS[name] = replace(
        spec,
        command_scale=spec.command_scale * command,
        pedal=pedal,
        seed_key=spec.seed_key or population,
    )
    try:
        yield name
    finally:
        del POPULATIONS[name]


def evaluate(
    population: str = "paper",
    seeds: Sequence[int] = (0, 1, 2, 3, 4),
    command_scale: float | None = None,
    workers: int = 1,
    pedal_scale: float | None = None,
) -> dict[str, Any]:
    """The calibration numbers of a population (see the module docstring).

    Returns:
        ``{"population", "command_scale", "pedal_scale", "seeds", "per_seed": [{seed, two_point,
        generalized (median ours/paper), sdlp (m, mean over drivers), max_abs_lateral_offset
        (m), left_road_runs, runs}], "two_point", "generalized": {mean, ci_low, ci_high},
        "sdlp", "left_road_runs", "within_range"}``.
    """
    with _variant(population, command_scale, pedal_scale) as name:
        config = ProtocolConfig(
            population=name,
            seeds=tuple(seeds),
            estimate=False,
            curved_runs=0,
            training_drivers=0,  # table 1 is of a fit on the illustrative participant
            generalized_orders="paper",  # ... with the paper's orders
        )
        result = run_protocol(config, workers=workers)
    per_seed = []
    for seed in seeds:
        rows = [r for r in result.steering if r["seed"] == seed]
        entry: dict[str, Any] = {"seed": int(seed)}
        for model in MODELS:
            ratios = [r["rmse_over_paper"] for r in rows if r["model"] == model]
            ratios = [v for v in ratios if v is not None and math.isfinite(v)]
            entry[model] = float(np.median(ratios)) if ratios else math.nan
        driving = [r for r in rows if r["model"] == MODELS[0]]
        entry["sdlp"] = float(np.mean([r["sdlp"] for r in driving]))
        entry["max_abs_lateral_offset"] = float(max(r["max_abs_lateral_offset"] for r in driving))
        entry["left_road_runs"] = int(sum(r["left_road_runs"] for r in driving))
        entry["runs"] = int(sum(r["n_runs"] for r in driving))
        entry["flags"] = {
            m["name"]: list((m.get("checks") or {}).get("flags") or [])
            for m in result.models
            if m["seed"] == seed and m["name"] in MODELS
        }
        per_seed.append(entry)
    out: dict[str, Any] = {
        "population": population,
        "command_scale": 1.0 if command_scale is None else float(command_scale),
        "pedal_scale": 1.0 if pedal_scale is None else float(pedal_scale),
        "seeds": [int(s) for s in seeds],
        "per_seed": per_seed,
    }
    for model in MODELS:
        mean, low, high = confidence_interval([e[model] for e in per_seed])
        out[model] = {"mean": mean, "ci_low": low, "ci_high": high}
    out["sdlp"] = float(np.mean([e["sdlp"] for e in per_seed]))
    out["max_abs_lateral_offset"] = float(max(e["max_abs_lateral_offset"] for e in per_seed))
    out["left_road_runs"] = int(sum(e["left_road_runs"] for e in per_seed))
    out["within_range"] = bool(all(RANGE[0] <= e[m] <= RANGE[1] for e in per_seed for m in MODELS))
    out["within_range_unflagged"] = bool(
        all(
            RANGE[0] <= e[m] <= RANGE[1]
            for e in per_seed
            for m in MODELS
            if "collinear_features" not in e["flags"].get(m, [])
        )
    )
    return out


def _row(entry: dict[str, Any], label: str) -> str:
    def ratio(model: str) -> str:
        v = entry[model]
        if isinstance(v, dict):
            if math.isfinite(v["ci_low"]):
                return f"{v['mean']:.2f} [{v['ci_low']:.2f}, {v['ci_high']:.2f}]"
            return f"{v['mean']:.2f}"
        return f"{v:.2f}"

    flags = entry.get("flags")
    shown = (
        "; ".join(f"{m}: {', '.join(f)}" for m, f in flags.items() if f) or "-"
        if isinstance(flags, dict)
        else ""
    )
    return (
        f"| {label} | {ratio('two_point')} | {ratio('generalized')} | {entry['sdlp']:.3f} | "
        f"{entry['max_abs_lateral_offset']:.2f} | {entry['left_road_runs']} | {shown} |"
    )


_TABLE_HEADER = (
    "| | two-point: ours / paper | generalized: ours / paper | SDLP (m) | max abs(y) (m) "
    "| runs off the road | flagged fits |\n|---|---|---|---|---|---|---|"
)
"""The header of every table of the report (one :func:`_row` per line below it)."""


def _report_introduction(
    chosen: dict[str, Any], grid: Sequence[dict[str, Any]], pedal_grid: Sequence[dict[str, Any]]
) -> list[str]:
    """The report's title, how to rerun it, what is matched and the knob turned."""
    seeds = ",".join(str(s) for s in chosen["seeds"])
    factors = ",".join(f"{g['command_scale']:g}" for g in grid)
    pedal_factors = ",".join(f"{g['pedal_scale']:g}" for g in pedal_grid)
    pedal_option = f" --pedal-grid {pedal_factors}" if pedal_grid else ""
    spec = POPULATIONS[chosen["population"]]
    return [
        "# Tuning the synthetic population to the paper's table 1",
        "",
        "Written by `python -m benchmarks.population_tuning --seeds "
        f"{seeds} --grid {factors}{pedal_option} --write "
        "docs/population_tuning.md`; rerun it to check every number here "
        "(`tests/test_population_tuning.py` reruns one seed).",
        "",
        "**What is matched.** The one-step steering RMSE of the two fitted models (two-point "
        "and generalized, paper orders, fitted on each seed's training run of driver 'Ill' as "
        "`hasa-bench paper` does), scored on the measured steering, per driver, against the "
        "paper's table 1 converted to road-wheel radians (the paper's steering-wheel values "
        "divided by the steering ratio 15). Target: the median over drivers of ours / the "
        "paper's in [1/3, 3] for both models, on every seed. Constraint: the drivers still keep "
        "their lane like people (SDLP of tenths of a metre, no run off the road). The paper's "
        "table 2 (estimation) is not looked at: the protocol runs without the estimator.",
        "",
        f"**The knob.** The population {chosen['population']!r}: {spec.description}",
        "",
        "Its drivers' command noise before the neuromuscular lag (`MotorParams.command_std`, an "
        "OU process, scaled like the steering a lateral acceleration needs) sets the one-step "
        "error of any model; the remnant after the lag (broadband, tremor, signal-dependent) is "
        f"scaled by {spec.remnant_scale:g}, the command noise by {spec.command_scale:g}. The "
        "population is studied under the env settings "
        f"`{json.dumps(dict(spec.env_config), sort_keys=True)}` (a wheel study's steering "
        "signal without automotive sensor noise; crosswind and road camber exciting the loop).",
        "",
    ]


def _shipped_section(chosen: dict[str, Any]) -> list[str]:
    """The table of the population as shipped (mean over seeds, then each seed), whether it
    is within :data:`RANGE`, and what the pedal remnant does for a training run."""
    seeds = ",".join(str(s) for s in chosen["seeds"])
    return [
        f"## The population as shipped (seeds {seeds}; means over seeds with 95 % Student-t "
        "intervals)",
        "",
        _TABLE_HEADER,
        _row(chosen, "shipped"),
        *(_row(e, f"seed {e['seed']}") for e in chosen["per_seed"]),
        "",
        f"Within [1/3, 3] on every seed: **{'yes' if chosen['within_range'] else 'no'}**; on "
        "every seed whose fit the training data identify (no `collinear_features` flag): "
        f"**{'yes' if chosen['within_range_unflagged'] else 'no'}**.",
        "",
        "On a seed whose driver 'Ill' holds 15 m/s, only the pedal remnant (docs/design.md "
        "§7.4) moves the training run's speed, by a few tenths of a m/s. Without it (pedal x 0 "
        "below) the bearings and v_y of that run are collinear (§6.5), the fit is flagged "
        "`collinear_features` and the generalized model, whose v_y terms then stand in for a "
        "speed-dependent part of the bearings, mispredicts the drivers who speed up to 30-45 "
        "m/s. With it the fits stay close to collinear (a flag may remain) but predict within "
        "the range. One training run without speed changes remains the protocol's weak point: "
        "shown here, not calibrated away.",
        "",
    ]


def _sensitivity_sections(
    grid: Sequence[dict[str, Any]], pedal_grid: Sequence[dict[str, Any]]
) -> list[str]:
    """The tables of the command noise and (if scored) the pedal remnant scaled."""
    return [
        "## Sensitivity: the command noise scaled (same drivers and runs otherwise)",
        "",
        _TABLE_HEADER,
        *(_row(g, f"x {g['command_scale']:g}") for g in grid),
        "",
        *(
            [
                "## Sensitivity: the pedal remnant scaled (same drivers and runs otherwise)",
                "",
                "The pedal remnant is not a calibration knob: it is set from a plain human "
                "figure (a held speed wandering by a std of 0.1-0.4 m/s, docs/design.md §7.4). "
                "Scaled by 0 (every driver holds its speed exactly, as before it existed), 0.5 "
                "and 2:",
                "",
                _TABLE_HEADER,
                *(_row(g, f"pedal x {g['pedal_scale']:g}") for g in pedal_grid),
                "",
            ]
            if pedal_grid
            else []
        ),
    ]


def _report_conclusion(
    chosen: dict[str, Any], grid: Sequence[dict[str, Any]], pedal_grid: Sequence[dict[str, Any]]
) -> list[str]:
    """What the numbers support, then every number as the JSON block :func:`read_report` reads."""
    return [
        "## What this does and does not support",
        "",
        "The population reproduces the paper's one-step steering error magnitudes (table 1) "
        "while lane keeping stays human-like; it does not reproduce human steering in "
        "general (no learning, no fatigue, no visual occlusion, three controller archetypes "
        "only), and the estimation results of the benchmark (table 2) are measured on it, not "
        "matched to the paper.",
        "",
        JSON_START,
        json.dumps(
            {"chosen": chosen, "grid": list(grid), "pedal_grid": list(pedal_grid)},
            indent=1,
            sort_keys=True,
        ),
        JSON_END,
        "",
    ]


def write_report(
    chosen: dict[str, Any],
    grid: Sequence[dict[str, Any]],
    path: Path,
    pedal_grid: Sequence[dict[str, Any]] = (),
) -> None:
    """The Markdown tuning report with its numbers as a JSON block."""
    lines = [
        *_report_introduction(chosen, grid, pedal_grid),
        *_shipped_section(chosen),
        *_sensitivity_sections(grid, pedal_grid),
        *_report_conclusion(chosen, grid, pedal_grid),
    ]
    path.write_text("\n".join(lines), encoding="utf-8")


def read_report(path: Path) -> dict[str, Any]:
    """The JSON block of a report written by :func:`write_report`."""
    text = path.read_text(encoding="utf-8")
    start = text.index(JSON_START) + len(JSON_START)
    return json.loads(text[start : text.index(JSON_END, start)])


def command_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m benchmarks.population_tuning`` (the report's header
    names one; tests parse it)."""
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.population_tuning", allow_abbrev=False
    )
    parser.add_argument("--population", default="paper")
    parser.add_argument("--seeds", default="0,1,2,3,4", help="population seeds (comma-separated)")
    parser.add_argument("--grid", default="", help="command-noise factors, e.g. 0.5,1,2")
    parser.add_argument(
        "--pedal-grid", default="", help="pedal-remnant factors, e.g. 0,0.5,2 (0: none)"
    )
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--write", metavar="FILE", help="write the Markdown report here")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = command_parser().parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    chosen = evaluate(args.population, seeds, workers=args.workers)
    grid = [
        evaluate(args.population, seeds, float(g), workers=args.workers)
        for g in args.grid.split(",")
        if g.strip()
    ]
    pedal_grid = [
        evaluate(args.population, seeds, workers=args.workers, pedal_scale=float(g))
        for g in args.pedal_grid.split(",")
        if g.strip()
    ]
    print(
        "| | two-point | generalized | SDLP (m) | max abs(y) (m) | off road | flagged |\n|---|---|---|---|---|---|---|"
    )
    print(_row(chosen, "shipped"))
    for g in grid:
        print(_row(g, f"x {g['command_scale']:g}"))
    for g in pedal_grid:
        print(_row(g, f"pedal x {g['pedal_scale']:g}"))
    if args.write:
        write_report(chosen, grid, Path(args.write), pedal_grid)
        print(f"wrote {args.write}", file=sys.stderr)
    return 0 if chosen["within_range_unflagged"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
