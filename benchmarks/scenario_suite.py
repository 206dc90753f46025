"""The scenario suite's table: every estimator of every scenario, one row each.

``hasa-bench paper --scenario all`` runs the protocol once per scenario
(:data:`hasa_env.scenarios.SCENARIOS`), writes each scenario's results into its own
folder and this table beside them (``scenarios.md``, ``scenarios.html``, ``scenarios.csv``): per scenario
and estimator, the lateral RMSE and the gain over the best steering-free baseline with
their 95 % hierarchical-bootstrap intervals, the time to decide, the share of the time the
steering channel was off (speed or curvature rule), and the runs that end
(or are at any step) confidently in a wrong lane, with exact binomial intervals.

Above it, one row per scenario says whether the scenario needs the steering at all
(:func:`difficulty_rows`): how the lane-centring baseline, the steering-free estimator that
solves the paper's scenario, fares there, against the suite's bar (issue 24): a scenario is
*hard* for it when it is confidently in a wrong lane at some step of at least 5 % of its
runs (``HARD_WRONG_SHARE``) or needs a median of at least 3 s to decide
(``HARD_DECIDE_TIME``; a median run that never decides counts). The runs it ends without
the true lane (wrong, undecided or refused) are shown beside it, not counted by the bar.
"""

from __future__ import annotations

import html
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from benchmarks.protocol.intervals import clopper_pearson
from benchmarks.protocol.results import BenchmarkResult
from benchmarks.report_sections import decision_time
from benchmarks.schema import ResultsSchemaError, table_problems
from benchmarks.tables import (
    Column,
    count_share,
    fixed,
    interval,
    missing,
    percent,
    render_html,
    render_markdown,
)

__all__ = [
    "HARD_DECIDE_TIME",
    "HARD_WRONG_SHARE",
    "SUITE_COLUMNS",
    "difficulty_rows",
    "format_suite",
    "html_suite",
    "suite_rows",
    "write_suite",
]

HARD_WRONG_SHARE = 0.05
"""The bar's share of runs confidently in a wrong lane at some step (issue 24)."""

HARD_DECIDE_TIME = 3.0
"""The bar's median time to decide (s; issue 24)."""

DIFFICULTY_BASELINE = "lane_centring"
"""The steering-free estimator the bar is measured on."""

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
    "wrong_decision_runs", "wrong_decision_runs_share_ci_low",
    "wrong_decision_runs_share_ci_high",
    "undecided_runs", "undecided_runs_share_ci_low", "undecided_runs_share_ci_high",
    "model_mismatch_runs", "model_mismatch_runs_share_ci_low", "model_mismatch_runs_share_ci_high",
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
    Column(count_share("wrong_decision_runs", "estimated_runs"), "decided wrong (incl. withheld)"),
]
"""The Markdown table's columns (the cells of the report's tables, :mod:`benchmarks.tables`)."""


def difficulty_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per scenario, the lane-centring baseline's row of :func:`suite_rows` judged by the bar.

    Returns one dict per scenario where that baseline estimated: ``scenario``, ``runs``,
    ``wrong_ever`` (runs whose reported weights were confidently in a wrong lane at some
    step), ``decided_wrong`` (runs that decided a wrong lane at some step: those, and the runs
    where the reversal rule withheld a wrong-lane decision, :attr:`EstimationResult.withheld
    <estimators.offline.EstimationResult>`) with its Clopper-Pearson interval,
    ``decide_median`` (s; None: the median run never decided), how its runs end
    (``ends_wrong``, ``ends_undecided``, ``ends_refused``: confidently wrong, undecided, a
    model mismatch) and ``hard``: the share of ``decided_wrong`` is at least
    :data:`HARD_WRONG_SHARE` or the median at least :data:`HARD_DECIDE_TIME` (or never).
    Rows made before withheld decisions were counted (no ``wrong_decision_runs``) use
    ``wrong_lane_ever_runs``.
    """
    out = []
    for row in rows:
        n = row.get("estimated_runs")
        if row.get("model") != DIFFICULTY_BASELINE or missing(n) or not n:
            continue
        n = int(n)
        ever = int(row.get("wrong_lane_ever_runs") or 0)
        counted: Any = row.get("wrong_decision_runs")
        wrong = ever if missing(counted) else int(counted)
        value: Any = row.get("time_to_decide_median")
        median = None if missing(value) else float(value)
        low, high = clopper_pearson(wrong, n)
        hard = wrong / n >= HARD_WRONG_SHARE or median is None or median >= HARD_DECIDE_TIME
        out.append({
            "scenario": row["scenario"], "runs": n, "wrong_ever": ever, "decided_wrong": wrong,
            "decided_wrong_share_ci_low": low, "decided_wrong_share_ci_high": high,
            "decide_median": median,
            "ends_wrong": int(row.get("wrong_lane_confident_runs") or 0),
            "ends_undecided": int(row.get("undecided_runs") or 0),
            "ends_refused": int(row.get("model_mismatch_runs") or 0), "hard": hard,
        })  # fmt: skip
    return out


_DIFFICULTY = [
    Column("scenario", "scenario", left=True),
    Column(count_share("decided_wrong", "runs"), "decided wrong at some step"),
    Column(lambda r: str(r["wrong_ever"]), "of which reported"),
    Column(
        lambda r: "never" if r["decide_median"] is None else f"{r['decide_median']:.2f}",
        "decides in (s), median",
    ),  # fmt: skip
    Column(
        lambda r: f"{r['ends_wrong']} / {r['ends_undecided']} / {r['ends_refused']}",
        "ends wrong / undecided / refused",
    ),  # fmt: skip
    Column(lambda r: "yes" if r["hard"] else "no", "hard for it (the bar)"),
]
_DIFFICULTY_TITLE = (
    f"The {DIFFICULTY_BASELINE} baseline (steering-free) "
    f"per scenario; hard = it decided (> 0.95) a wrong lane at some step of at least "
    f"{HARD_WRONG_SHARE:.0%} of its runs, or needs a median of at least {HARD_DECIDE_TIME:g} s "
    "to decide (never counts); a wrong decision counts whether its weights were reported or the "
    "reversal rule withheld it, sending the run back to its prior (of which reported: the "
    "runs whose reported weights show it); how its runs end is shown, not counted by the bar; "
    "k/n [95 % Clopper-Pearson interval]"
)


def format_suite(rows: list[dict[str, Any]]) -> str:
    """The table as Markdown: the difficulty table, then one block per scenario."""
    lines = []
    hard = difficulty_rows(rows)
    if hard:
        lines += ["### Does each scenario need the steering?", "", _DIFFICULTY_TITLE, "",
                  render_markdown(hard, _DIFFICULTY), ""]  # fmt: skip
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
    hard = difficulty_rows(rows)
    if hard:
        parts.append("<h2>Does each scenario need the steering?</h2>")
        parts.append(f"<p>{html.escape(_DIFFICULTY_TITLE)}</p>")
        parts.append(render_html(hard, _DIFFICULTY))
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
