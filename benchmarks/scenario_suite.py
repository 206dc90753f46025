"""The scenario suite's table: every estimator of every scenario, one row each.

``hasa-bench paper --scenario all`` runs the protocol once per scenario
(:data:`hasa_env.scenarios.SCENARIOS`), writes each scenario's results into its own
folder and this table beside them (``scenarios.md``, ``scenarios.html``, ``scenarios.csv``): per scenario
and estimator, the lateral RMSE and the gain over the best steering-free baseline with
their 95 % hierarchical-bootstrap intervals, the time to decide, the share of the time the
steering channel was off (speed or curvature rule), and the runs that end
(or are at any step) confidently in a wrong lane, with exact binomial intervals.
"""

from __future__ import annotations

import html
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from benchmarks.protocol.results import BenchmarkResult
from benchmarks.report_sections import decision_time
from benchmarks.schema import ResultsSchemaError, table_problems
from benchmarks.tables import (
    Column,
    count_share,
    fixed,
    interval,
    percent,
    render_html,
    render_markdown,
)

__all__ = ["SUITE_COLUMNS", "format_suite", "html_suite", "suite_rows", "write_suite"]

SUITE_COLUMNS = (
    "scenario", "model", "kind", "estimated_runs",
    "lateral_rmse", "lateral_rmse_ci_low", "lateral_rmse_ci_high",
    "gain_over_steering_free", "gain_over_steering_free_ci_low",
    "gain_over_steering_free_ci_high",
    "time_to_decide_median", "time_to_decide_p90",
    "never_decided_runs", "never_decided_runs_share_ci_low", "never_decided_runs_share_ci_high",
    "steering_off_share", "steering_off_share_ci_low", "steering_off_share_ci_high",
    "steering_live_share", "steering_live_share_ci_low", "steering_live_share_ci_high",
    "wrong_lane_confident_runs", "wrong_lane_confident_runs_share_ci_low",
    "wrong_lane_confident_runs_share_ci_high",
    "wrong_lane_ever_runs", "wrong_lane_ever_runs_share_ci_low",
    "wrong_lane_ever_runs_share_ci_high",
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


_TABLE = [
    Column("model", "Estimator", left=True),
    Column("kind", "kind", left=True),
    Column(interval(fixed(3), "lateral_rmse"), "lat. RMSE (m) [95% CI]"),
    Column(
        interval(fixed(3), "gain_over_steering_free"),
        "gain over best steering-free (m) [95% CI]",
    ),
    Column(decision_time, "decides in (s) median / p90"),
    Column(count_share("never_decided_runs", "estimated_runs"), "never decided"),
    Column(interval(percent, "steering_off_share"), "steering off [95% CI]"),
    Column(interval(percent, "steering_live_share"), "steering live [95% CI]"),
    Column(count_share("wrong_lane_confident_runs", "estimated_runs"), "ends conf. wrong"),
    Column(count_share("wrong_lane_ever_runs", "estimated_runs"), "ever conf. wrong"),
]
"""The Markdown table's columns (the cells of the report's tables, :mod:`benchmarks.tables`)."""


def format_suite(rows: list[dict[str, Any]]) -> str:
    """The table as Markdown, one block per scenario."""
    lines = []
    for scenario in dict.fromkeys(row["scenario"] for row in rows):
        part = [row for row in rows if row["scenario"] == scenario]
        lines += [f"### {scenario}", "", render_markdown(part, _TABLE), ""]
    return "\n".join(lines)


def html_suite(rows: list[dict[str, Any]]) -> str:
    """The table as one self-contained HTML page (no script, nothing outside the file), one
    table per scenario linking to that scenario's report.html."""
    title = "The scenario suite"
    parts = [
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">',
        f"<title>{title}</title>",
        "<style>body { font-family: sans-serif; margin: 2em; } table { border-collapse: "
        "collapse; margin-bottom: 1.5em; } th, td { border: 1px solid #bbb; padding: 0.2em "
        "0.5em; text-align: left; } th { background: #eee; } .num { text-align: right; }</style>",
        f"</head>\n<body>\n<h1>{title}</h1>",
    ]
    for scenario in dict.fromkeys(row["scenario"] for row in rows):
        part = [row for row in rows if row["scenario"] == scenario]
        name = html.escape(str(scenario))
        parts.append(f'<h2 id="{name}">{name} (<a href="{name}/report.html">report</a>)</h2>')
        parts.append(render_html(part, _TABLE))
    return "\n".join([*parts, "</body>\n</html>\n"])


def write_suite(rows: list[dict[str, Any]], out: Path) -> list[Path]:
    """``scenarios.md``, ``scenarios.html`` and ``scenarios.csv`` in ``out``; returns their
    paths. Raises :class:`ResultsSchemaError` after writing them if the rows break the
    shipped schema (:mod:`benchmarks.schema`)."""
    md, page, csv = out / "scenarios.md", out / "scenarios.html", out / "scenarios.csv"
    md.write_text("# The scenario suite\n\n" + format_suite(rows) + "\n", encoding="utf-8")
    page.write_text(html_suite(rows), encoding="utf-8")
    pd.DataFrame(rows, columns=list(SUITE_COLUMNS)).to_csv(csv, index=False)
    problems = table_problems("scenarios.csv", rows)
    if problems:
        raise ResultsSchemaError(problems)
    return [md, page, csv]
