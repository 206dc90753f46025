"""The scenario suite's table: every estimator of every scenario, one row each.

``hasa-bench paper --scenario all`` runs the protocol once per scenario
(:data:`hasa_env.scenarios.SCENARIOS`), writes each scenario's results into its own
folder and this table beside them (``scenarios.md``, ``scenarios.csv``): per scenario
and estimator, the lateral RMSE and the gain over the best steering-free baseline with
their 95 % hierarchical-bootstrap intervals, the time to decide, the share of the time the
steering channel was off (speed or curvature rule), and the runs that end
(or are at any step) confidently in a wrong lane, with exact binomial intervals.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from benchmarks.protocol.results import BenchmarkResult

__all__ = ["SUITE_COLUMNS", "format_suite", "suite_rows", "write_suite"]

SUITE_COLUMNS = (
    "scenario", "model", "kind", "estimated_runs",
    "lateral_rmse", "lateral_rmse_ci_low", "lateral_rmse_ci_high",
    "gain_over_steering_free", "gain_over_steering_free_ci_low",
    "gain_over_steering_free_ci_high",
    "time_to_decide_median", "time_to_decide_p90", "never_decided_runs",
    "steering_off_share",
    "wrong_lane_confident_runs", "wrong_lane_confident_runs_share_ci_high",
    "wrong_lane_ever_runs", "wrong_lane_ever_runs_share_ci_high",
)  # fmt: skip
"""The columns of ``scenarios.csv`` (the verdict's keys, :mod:`benchmarks.protocol.aggregate`)."""


def suite_rows(results: Mapping[str, BenchmarkResult]) -> list[dict[str, Any]]:
    """One row per (scenario, estimator) of the verdicts (models that estimated only)."""
    rows = []
    for scenario, result in results.items():
        for verdict in result.summary:
            if not verdict.get("estimated_runs"):
                continue
            rows.append({"scenario": scenario} | {k: verdict.get(k) for k in SUITE_COLUMNS[1:]})
    return rows


def _number(value: Any, digits: int) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, float) and math.isinf(value):
        return "never"
    return f"{value:.{digits}f}"


def _interval(row: Mapping[str, Any], key: str, digits: int = 3) -> str:
    low, high = row.get(f"{key}_ci_low"), row.get(f"{key}_ci_high")
    text = _number(row.get(key), digits)
    if low is None or high is None or text == "-":
        return text
    return f"{text} [{_number(low, digits)}, {_number(high, digits)}]"


def _percent(value: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{100 * value:.0f} %"


def _count(row: Mapping[str, Any], key: str) -> str:
    runs, count = row.get("estimated_runs"), row.get(key)
    if not runs or count is None:
        return "-"
    high = row.get(f"{key}_share_ci_high")
    bound = "" if high is None else f" (<= {100 * high:.0f} %)"
    return f"{int(count)}/{int(runs)}{bound}"


def format_suite(rows: list[dict[str, Any]]) -> str:
    """The table as Markdown, one block per scenario."""
    head = (
        "| Estimator | kind | lat. RMSE (m) [95% CI] | gain over best steering-free (m) "
        "[95% CI] | decides in (s) median / p90 | never decided | steering off | ends conf. "
        "wrong (95% upper) | ever conf. wrong (95% upper) |"
    )
    lines = []
    for scenario, part in pd.DataFrame(rows).groupby("scenario", sort=False):
        lines += [f"### {scenario}", "", head, "|" + "---|" * 9]
        for record in part.to_dict("records"):
            row = {str(k): v for k, v in record.items()}
            timing = (
                f"{_number(row['time_to_decide_median'], 2)} / "
                f"{_number(row['time_to_decide_p90'], 2)}"
            )
            lines.append(
                f"| {row['model']} | {row['kind']} | {_interval(row, 'lateral_rmse')} | "
                f"{_interval(row, 'gain_over_steering_free')} | {timing} | "
                f"{_count(row, 'never_decided_runs')} | {_percent(row.get('steering_off_share'))} | "
                f"{_count(row, 'wrong_lane_confident_runs')} | "
                f"{_count(row, 'wrong_lane_ever_runs')} |"
            )
        lines.append("")
    return "\n".join(lines)


def write_suite(rows: list[dict[str, Any]], out: Path) -> list[Path]:
    """``scenarios.md`` and ``scenarios.csv`` in ``out``; returns their paths."""
    md, csv = out / "scenarios.md", out / "scenarios.csv"
    md.write_text("# The scenario suite\n\n" + format_suite(rows) + "\n", encoding="utf-8")
    pd.DataFrame(rows, columns=list(SUITE_COLUMNS)).to_csv(csv, index=False)
    return [md, csv]
