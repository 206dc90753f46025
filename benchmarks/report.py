"""Tables, CSV files and the Markdown report of a benchmark result.

:func:`format_tables` renders the tables for the terminal and
:func:`markdown_report` the report, both with the paper's published values
beside ours; :func:`write_outputs` writes ``results.json``, the CSV tables
(every per-seed row), ``report.md`` and the figures (:mod:`benchmarks.figures`).

The tables, in order:

1. the verdict over population seeds (or over the participants of recordings):
   per model, the mean of the per-seed values with its 95 % hierarchical
   percentile-bootstrap interval, the shares of runs counted with their exact
   (Clopper-Pearson) intervals, ranks among every ranked model and how often a
   model holds its rank (:func:`benchmarks.protocol.aggregate.verdict`,
   :mod:`benchmarks.protocol.intervals`);
2. the fits' checks per seed (ridge penalty, condition number, largest AR
   pole, stability, identifiability);
3. per driver, means over the seeds: steering prediction (paper table 1; the
   paper's RMSE converted from steering-wheel to road-wheel radians by the
   steering ratio 15), the curved track, lateral estimation (paper table 2).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.figures import write_figures
from benchmarks.protocol import BenchmarkResult
from benchmarks.protocol.intervals import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED
from benchmarks.protocol.results import json_clean
from benchmarks.tables import (
    Column,
    count_share,
    fixed,
    interval,
    missing,
    percent,
    render_markdown,
    render_text,
    scientific,
    text,
)
from hasa_env.steering.loading import PAPER_STEERING_RATIO

__all__ = ["format_tables", "write_outputs", "markdown_report", "CSV_TABLES", "pooled"]

CSV_TABLES = {
    "steering": "steering.csv",
    "curved": "curved.csv",
    "estimation": "estimation.csv",
    "curved_estimation": "curved_estimation.csv",
    "seed_summary": "seed_summary.csv",
    "summary": "summary.csv",
    "runs_steering": "runs_steering.csv",
    "runs_estimation": "runs_estimation.csv",
}
"""results attribute -> CSV file name."""


def _paper(value: Any) -> str:
    return "" if missing(value) else f"{value:.2g}"


def _paper_pct(value: Any) -> str:
    return "" if missing(value) else f"{100 * value:.0f}%"


def _ratio(value: Any) -> str:
    return "-" if missing(value) else f"{value:.2f}"


def _stability(row: dict[str, Any], rank: str) -> str:
    """ "rank of models (share of bootstrap replicates holding it)", e.g. "2 of 4 (85%)"."""
    value, share, models = row.get(rank), row.get(f"{rank}_stability"), row.get(f"{rank}_models")
    if value is None:
        return "-"
    shown = f"{value}" if missing(models) else f"{value} of {int(models)}"
    return shown if missing(share) else f"{shown} ({100 * share:.0f}%)"


def _decision_time(row: dict[str, Any]) -> str:
    """ "median / p90" of the time to decide; "never" for a quantile that is a run that never
    decided."""
    if not row.get("estimated_runs"):
        return "-"
    median, p90 = row.get("time_to_decide_median"), row.get("time_to_decide_p90")
    return " / ".join("never" if missing(v) else f"{v:.1f}" for v in (median, p90))


def _of(numerator: str, denominator: str) -> Any:
    def cell(row: dict[str, Any]) -> str:
        n, d = row.get(numerator), row.get(denominator)
        return "-" if n is None or d is None else f"{int(n)}/{int(d)}"

    return cell


_VERDICT_COLUMNS = [
    Column("model", "Model", left=True),
    Column("kind", "kind", left=True),
    Column(interval(scientific, "rmse"), "steering RMSE (rad) [95% CI]"),
    Column(interval(fixed(3), "r2_increments"), "R^2 inc [95% CI]"),
    Column(interval(percent, "rmse_decrease_vs_two_point"), "RMSE dec. [95% CI]"),
    Column(interval(fixed(2), "rmse_over_paper_median"), "ours/paper [95% CI]"),
    Column(interval(fixed(3), "lateral_rmse"), "lat. RMSE (m) [95% CI]"),
    Column(count_share("decided_runs", "estimated_runs"), "decided [95% CI]"),
    Column(lambda r: _stability(r, "rank_lateral"), "rank lat. (kept)"),
    Column(lambda r: _stability(r, "rank_steering"), "rank steer. (kept)"),
    Column("free_run_diverged", "free runs diverged"),
]

_SAFETY_COLUMNS = [
    Column("model", "Estimator", left=True),
    Column("kind", "kind", left=True),
    Column(interval(fixed(3), "lateral_rmse"), "lat. RMSE (m) [95% CI]"),
    Column(count_share("wrong_lane_confident_runs", "estimated_runs"), "confident wrong lane"),
    Column(count_share("undecided_runs", "estimated_runs"), "undecided"),
    Column(count_share("model_mismatch_runs", "estimated_runs"), "model mismatch"),
    Column(_decision_time, "decides in (s) median / p90"),
    Column(count_share("never_decided_runs", "estimated_runs"), "never decided"),
    Column(interval(percent, "decided_time_share"), "time decided [95% CI]"),
    Column(interval(fixed(3), "lateral_rmse_after_decision"), "lat. RMSE after dec. (m) [95% CI]"),
    Column(interval(fixed(2), "lateral_nees"), "lat. NEES [95% CI]"),
    Column(interval(fixed(3), "curved_lateral_rmse"), "curved lat. RMSE (m) [95% CI]"),
    Column(
        count_share("curved_wrong_lane_confident_runs", "curved_estimated_runs"),
        "curved conf. wrong",
    ),
]

_SEED_COLUMNS = [
    Column("seed", "seed"),
    Column("model", "Model", left=True),
    Column("rmse", "steering RMSE (rad)", scientific),
    Column("r2_increments", "R^2 inc", fixed(3)),
    Column("rmse_over_paper_median", "ours/paper", _ratio),
    Column("lateral_rmse", "lat. RMSE (m)", fixed(3)),
    Column(_of("decided_runs", "estimated_runs"), "decided"),
    Column("rank_lateral", "rank lat."),
    Column("rank_steering", "rank steer."),
]

_CHECK_COLUMNS = [
    Column("name", "Model", left=True),
    Column("seed", "seed"),
    Column("ridge_lambda", "ridge lambda", scientific),
    Column("condition_number", "condition no.", scientific),
    Column("ar_poles_max_abs", "max |AR pole|", fixed(3)),
    Column(lambda r: text(r.get("stable")), "stable"),
    Column(lambda r: text(r.get("identifiable")), "identifiable"),
    Column("lane_snr", "lane SNR", fixed(2)),
    Column(lambda r: ", ".join(r.get("flags") or []) or "-", "flags", left=True),
    Column(lambda r: _lane_keeping_cell(r.get("lane_keeping")), "drives (closed loop)", left=True),
]


def _lane_keeping_cell(outcome: dict[str, Any] | None) -> str:
    """The lane-keeping check in a cell: "on road, max |y| 0.54 m" or "off road 4/4 (3.7 s)"."""
    if not outcome:
        return "-"
    if outcome.get("error"):
        return "could not drive"
    if outcome.get("passed"):
        return f"on road, max |y| {outcome['max_abs_lateral_offset']:.2f} m"
    return f"off road {outcome['runs_left_road']}/{outcome['runs']} ({outcome['first_exit']:.1f} s)"


_STEERING_COLUMNS = [
    Column("driver", "Driver", left=True),
    Column("model", "Model", left=True),
    Column("rmse", "RMSE (rad)", scientific),
    Column("r2", "R^2", fixed(4)),
    Column("r2_increments", "R^2 inc", fixed(3)),
    Column("rmse_decrease_vs_two_point", "RMSE dec.", percent),
    Column("free_run_rmse", "free-run RMSE", scientific),
    Column(_of("white_runs", "n_runs"), "white (LB)"),
    Column("paper_rmse", "paper RMSE (rw)", _paper),
    Column("rmse_over_paper", "ours/paper", _ratio),
    Column("paper_r2", "paper R^2 Acc", _paper),
    Column("paper_rmse_decrease", "paper dec.", _paper_pct),
]

_ESTIMATION_COLUMNS = [
    Column("driver", "Driver", left=True),
    Column("model", "Model", left=True),
    Column("lateral_rmse_mean", "lat. RMSE mean (m)", fixed(3)),
    Column("lateral_rmse_std", "std (m)", fixed(3)),
    Column("lateral_rmse_max", "max (m)", fixed(3)),
    Column("steps_to_decide_median", "steps to decide", fixed(0)),
    Column(_of("decided_runs", "n_runs"), "decided"),
    Column(_of("true_lane_final_runs", "n_runs"), "true lane at end"),
    Column(_of("wrong_lane_confident_runs", "n_runs"), "conf. wrong"),
    Column(_of("undecided_runs", "n_runs"), "undecided"),
    Column(_of("model_mismatch_runs", "n_runs"), "mismatch"),
    Column("lateral_nees", "NEES", fixed(2)),
    Column("paper_lateral_rmse_mean", "paper mean (m)", _paper),
    Column("paper_lateral_rmse_std", "paper std (m)", _paper),
]

_MEAN_KEYS = ("rmse", "r2", "r2_increments", "rmse_decrease_vs_two_point", "free_run_rmse",
              "rmse_over_paper", "lateral_rmse_mean", "lateral_rmse_std", "lateral_rmse_max",
              "steps_to_decide_median", "final_true_lane_weight_mean", "lateral_nees",
              "nis_speed", "nis_camera", "nis_steering")  # fmt: skip
_SUM_KEYS = ("n_runs", "white_runs", "decided_runs", "true_lane_final_runs", "free_run_diverged",
             "degenerate_runs", "wrong_lane_confident_runs", "undecided_runs",
             "model_mismatch_runs")  # fmt: skip
_FIRST_KEYS = ("paper_rmse", "paper_r2", "paper_rmse_decrease", "paper_lateral_rmse_mean",
               "paper_lateral_rmse_std")  # fmt: skip


def _numeric_sum(values: pd.Series) -> int:
    """The sum of a column's numbers (anything else counts 0)."""
    return int(pd.to_numeric(values, errors="coerce").fillna(0).sum())


def pooled(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (driver, model), over seeds: means of the per-seed means, sums of the counts."""
    if not rows:
        return []
    frame = pd.DataFrame(list(rows))
    keys = [k for k in ("driver", "track", "model") if k in frame]
    agg: dict[str, tuple[str, Any]] = {}
    for key in _MEAN_KEYS:
        if key in frame:
            agg[key] = (
                key,
                lambda v: float(np.nanmean(v.astype(float))) if v.notna().any() else None,
            )
    for key in _SUM_KEYS:
        if key in frame:
            agg[key] = (key, _numeric_sum)
    for key in _FIRST_KEYS:
        if key in frame:
            agg[key] = (key, "first")
    agg["seeds"] = ("seed", "nunique")
    table = frame.groupby(keys, sort=False, dropna=False).agg(**agg).reset_index()
    return [
        {
            str(k): (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in r.items()
        }
        for r in table.to_dict(orient="records")
    ]


def _checks_rows(result: BenchmarkResult) -> list[dict[str, Any]]:
    rows = []
    for m in result.models:
        checks = m.get("checks") or {}
        if m.get("error") or not (checks or m.get("lane_keeping")):
            continue
        rows.append(
            {"name": m["name"], "kind": m.get("kind"), "seed": m.get("seed"), **checks}
            | {"lane_keeping": m.get("lane_keeping")}
        )
    return rows


Section = tuple[str, str, list[dict], list[Column], str | None]
"""(key, title, rows, columns, group) of one table."""


def _interval_note(cfg: dict[str, Any]) -> tuple[str, str]:
    """(over what, how the intervals were computed) for the verdict's captions."""
    seeds = cfg.get("seeds")
    if not seeds:
        return (
            "over the recordings (participants)",
            "95 % CI: percentile bootstrap over the participants, "
            f"{BOOTSTRAP_RESAMPLES} replicates, generator seed {BOOTSTRAP_SEED}",
        )
    over = f"over {len(seeds)} population seeds {seeds}"
    if len(seeds) == 1:
        return over, (
            "95 % CI: percentile bootstrap over the drivers of the one seed (use --seeds for "
            f"the seeds' spread), {BOOTSTRAP_RESAMPLES} replicates, generator seed {BOOTSTRAP_SEED}"
        )
    return over, (
        "95 % CI: hierarchical percentile bootstrap, seeds then drivers within seeds, "
        f"{BOOTSTRAP_RESAMPLES} replicates, generator seed {BOOTSTRAP_SEED}"
    )


def _verdict_sections(result: BenchmarkResult) -> list[Section]:
    """The verdict, the lane decisions and the per-seed table."""
    cfg = result.config
    over, ci = _interval_note(cfg)
    shares = "k/n [95 % CI] = runs counted / runs with the exact (Clopper-Pearson) interval"
    return [
        (
            "summary",
            f"Verdict {over}: per model, the mean over seeds of the per-seed mean over drivers "
            f"({ci}); ours/paper = median over drivers of our one-step steering RMSE / the "
            f"paper's converted to road-wheel rad (paper / {PAPER_STEERING_RATIO:g}); rank "
            "(kept) = overall rank among every built-in, user and baseline model (share of "
            f"bootstrap replicates on which it holds that rank); {shares}",
            result.summary,
            _VERDICT_COLUMNS,
            None,
        ),
        (
            "safety",
            f"Lane decisions {over} (a safety output): runs that end with more than "
            f"{float(cfg.get('weight_threshold', 0.95)):g} on a wrong lane, runs left undecided "
            "or with a model mismatch at the end (estimators.evidence), the lateral NEES "
            "(mean (y_hat - y)^2 / sigma^2; 1: the reported std is right), and the curved "
            f"track with the road ahead as a known input; decides in = time until the true "
            f"lane's weight first exceeds {float(cfg.get('weight_threshold', 0.95)):g}, median "
            "and 90th percentile over runs (never: that quantile is a run that never did), "
            "time decided = mean share of a run's time above it, lat. RMSE after dec. = over "
            f"the steps from which it stays above (runs that settle); {shares}; other "
            "intervals as in the verdict",
            [r for r in result.summary if r.get("estimated_runs")],
            _SAFETY_COLUMNS,
            None,
        ),
        (
            "seed_summary",
            "Per seed: means over drivers" + ("" if cfg.get("seeds") else " (recordings: one)"),
            result.seed_summary,
            _SEED_COLUMNS,
            "seed",
        ),
    ]


def _checks_section(result: BenchmarkResult) -> Section:
    return (
        "checks",
        "The fits' checks per seed (docs/design.md §6.5): ridge penalty chosen by blocked "
        "cross-validation on the training run, condition number of the standardized design, "
        "largest AR pole, lane-offset identifiability with the steering-sensor noise; "
        "and whether the model, driving 4 cars itself on the training run's conditions, "
        "keeps them on the road (docs/design.md §8.11: one that does not gives the "
        "estimator no lane evidence)",
        _checks_rows(result),
        _CHECK_COLUMNS,
        "name",
    )


def _steering_sections(result: BenchmarkResult) -> list[Section]:
    """Steering prediction per driver (paper table 1) and on the curved track."""
    cfg = result.config
    sections: list[Section] = [
        (
            "steering",
            "Steering prediction (paper table 1), per driver, means over seeds of the mean over "
            "the driver's validation runs: one step ahead with the measured past steering, "
            "scored on the measured steering; R^2 inc = R^2 on delta(k) - delta(k-1) (compare "
            "with the paper's 'R^2 Acc'); free-run RMSE over the runs whose free run stayed "
            f"bounded; white (LB) = runs whose residuals pass Ljung-Box at 5 % "
            f"({cfg.get('ljung_box_lags', 20)} lags); paper RMSE (rw) = the paper's steering-"
            f"wheel value / {PAPER_STEERING_RATIO:g}",
            pooled(result.steering),
            _STEERING_COLUMNS,
            "driver",
        )
    ]
    if result.curved:
        sections.append(
            (
                "curved",
                f"Curved track, driver {cfg.get('illustrative', 'Ill')} (paper section 3.3.2; the "
                "paper gives R^2 on delta and the RMSE)",
                pooled(result.curved),
                [
                    c if c.key != "paper_r2" else Column("paper_r2", "paper R^2", _paper)
                    for c in _STEERING_COLUMNS
                ],  # fmt: skip
                "driver",
            )
        )
    return sections


def _estimation_sections(result: BenchmarkResult) -> list[Section]:
    """Lateral estimation per driver (paper table 2) and on the curved track."""
    cfg = result.config
    threshold = float(cfg.get("weight_threshold", 0.95))
    sections: list[Section] = [
        (
            "estimation",
            "Lateral estimation (paper table 2), per driver, means over seeds: RMSE of the "
            "mixture's lateral-offset estimate over each run, mean/std/max over the driver's "
            f"validation runs; steps until the true lane's weight stays above {threshold:g} "
            "(median over decided runs)",
            pooled(result.estimation),
            _ESTIMATION_COLUMNS,
            "driver",
        )
    ]
    if result.curved_estimation:
        sections.append(
            (
                "curved_estimation",
                f"Lateral estimation on the curved track, driver {cfg.get('illustrative', 'Ill')}"
                " (the estimator given the road ahead; the paper has no such table)",
                pooled(result.curved_estimation),
                [c for c in _ESTIMATION_COLUMNS if not str(c.key).startswith("paper")],
                "driver",
            )
        )
    return sections


def _sections(result: BenchmarkResult) -> list[Section]:
    """Every table of the report, in order."""
    return [
        *_verdict_sections(result),
        _checks_section(result),
        *_steering_sections(result),
        *_estimation_sections(result),
    ]


def _source(cfg: dict[str, Any]) -> str:
    if cfg.get("recordings"):
        return f"recordings in {cfg['recordings']}"
    return (
        f"synthetic population {cfg['population']!r}, seeds {cfg['seeds']}: "
        f"{cfg['drivers']} drivers x {cfg['runs']} runs of {cfg['duration']:g} s on the "
        f"{cfg['track']} track ({cfg['illustrative']}: {cfg['ill_runs']}), "
        f"{cfg['curved_runs']} curved"
    )


def format_tables(result: BenchmarkResult) -> str:
    """The result's tables as plain text (ours beside the paper's published values)."""
    cfg = result.config
    parts = [
        f"hasa-bench: {_source(cfg)}; models fitted on run {cfg['training_run']} of "
        f"{cfg['illustrative']} (each seed's)"
    ]
    for _, title, rows, columns, group in _sections(result):
        parts.append("")
        parts.append(title)
        parts.append(render_text(rows, columns, group) if rows else "(no rows)")
    parts.extend(_findings(result, markdown=False))
    notes = _model_notes(result)
    if notes:
        parts.append("")
        parts.append("Notes on the models:")
        parts.extend(f"  {name}: {note}" for name, note in notes)
    if result.notes:
        parts.append("")
        parts.append("Notes on the runs:")
        parts.extend(f"  {note}" for note in result.notes)
    if result.errors:
        parts.append("")
        parts.append("ERRORS (these models are left out of the tables):")
        parts.extend(f"  {e['message']}" for e in result.errors)
    return "\n".join(parts)


def _model_notes(result: BenchmarkResult) -> list[tuple[str, str]]:
    """(model, note) once per model with a note (e.g. why it has no estimation rows)."""
    seen: dict[str, str] = {}
    for m in result.models:
        if m.get("note") and not m.get("error"):
            seen.setdefault(str(m["name"]), str(m["note"]))
    return list(seen.items())


UNSAFE_SHARE = 0.01
"""An estimator that ends more than this share of its runs (straight and curved) with more than
0.95 on a wrong lane is named in the findings (the bound of docs/design.md §8.11)."""


def _unsafe_estimators(result: BenchmarkResult) -> list[str]:
    """ "name a/b (x %)" of every estimator above :data:`UNSAFE_SHARE`, in summary order."""
    out = []
    for row in result.summary:
        wrong = row.get("wrong_lane_confident_runs")
        runs = row.get("estimated_runs")
        if wrong is None or not runs or not math.isfinite(float(runs)):
            continue
        wrong = float(wrong) + float(row.get("curved_wrong_lane_confident_runs") or 0.0)
        runs = float(runs) + float(row.get("curved_estimated_runs") or 0.0)
        if wrong > UNSAFE_SHARE * runs:
            out.append(f"{row['model']} {wrong:.0f}/{runs:.0f} ({wrong / runs:.1%})")
    return out


def _findings(result: BenchmarkResult, markdown: bool) -> list[str]:
    """Headline numbers next to the paper's claims (means over seeds, with intervals)."""
    by = {r["model"]: r for r in result.summary}
    gen, tp = by.get("generalized"), by.get("two_point")
    bullet = "- " if markdown else "  "
    lines: list[str] = []
    if not (gen and tp):
        return lines
    lines.append("")
    lines.append("Headline (ours vs the paper):")
    dec = interval(percent, "rmse_decrease_vs_two_point")(gen)
    lines.append(
        f"{bullet}steering RMSE decrease of the generalized model vs two-point: {dec} (paper: 85 %)"
    )
    lines.append(
        f"{bullet}one-step steering RMSE / the paper's (median over drivers): two-point "
        f"{interval(fixed(2), 'rmse_over_paper_median')(tp)}, generalized "
        f"{interval(fixed(2), 'rmse_over_paper_median')(gen)}"
    )
    lines.append(
        f"{bullet}lateral RMSE: generalized {interval(fixed(3), 'lateral_rmse')(gen)} m "
        f"(paper: under 0.25), two-point {interval(fixed(3), 'lateral_rmse')(tp)} m "
        "(paper: 0.93-1.0)"
    )
    base, oracle = by.get("no_steering"), by.get("oracle")
    if base and oracle:
        lines.append(
            f"{bullet}baselines: no steering {interval(fixed(3), 'lateral_rmse')(base)} m "
            f"(paper: 0.9), oracle {interval(fixed(3), 'lateral_rmse')(oracle)} m"
        )
    unsafe = _unsafe_estimators(result)
    if unsafe:
        lines.append(
            f"{bullet}confidently in the wrong lane (> 0.95) in more than "
            f"{UNSAFE_SHARE:.0%} of runs: " + ", ".join(unsafe)
        )
    flagged = [r for r in _checks_rows(result) if r.get("flags") and r.get("kind") != "baseline"]
    if flagged:
        shown = ", ".join(f"{r['name']} seed {r['seed']}: {', '.join(r['flags'])}" for r in flagged)
        lines.append(f"{bullet}flagged fits: {shown}")
    return lines


# --------------------------------------------------------------------- markdown
def markdown_report(result: BenchmarkResult, figures: dict[str, str]) -> str:
    """The Markdown report: configuration, tables, findings, figures, errors, versions."""
    lines = _markdown_head(result.config)
    for key, title, rows, columns, _ in _sections(result):
        lines.append(f"## {key.replace('_', ' ').capitalize()}")
        lines.append("")
        lines.append(title + ".")
        lines.append("")
        lines.append(render_markdown(rows, columns) if rows else "(no rows)")
        lines.append("")
    findings = _findings(result, markdown=True)
    if findings:
        lines.append("## Findings")
        lines.append("")
        lines.extend(findings[2:])
        lines.append("")
    if result.errors:
        lines.append("## Errors")
        lines.append("")
        lines.append("These models failed and are left out of the tables:")
        lines.append("")
        lines.extend(f"- `{e['model']}` ({e['stage']}): {e['message']}" for e in result.errors)
        lines.append("")
    lines.extend(_markdown_models(result))
    lines.extend(_markdown_figures(result.config, figures))
    if result.notes:
        lines.append("## Notes")
        lines.append("")
        lines.extend(f"- {n}" for n in result.notes)
        lines.append("")
    lines.extend(_markdown_run(result))
    return "\n".join(lines)


def _markdown_head(cfg: dict[str, Any]) -> list[str]:
    """The report's title, what it compares, the data and the configuration."""
    lines = ["# hasa-bench: the human-as-advisor benchmark", ""]
    lines.append(
        "Protocol of Mai et al. (sections 3.3 and 4.3; docs/design.md §9). Our numbers are "
        "what the code measured; the paper's published values are printed beside them for "
        "comparison, nothing is tuned toward them. The paper's steering RMSEs are steering-"
        f"wheel angles; beside ours they are divided by the steering ratio "
        f"{PAPER_STEERING_RATIO:g} (road-wheel rad)."
    )
    lines.append("")
    lines.append(f"Data: {_source(cfg)}.")
    lines.append("")
    lines.append("## Configuration")
    lines.append("")
    lines.append("```json")
    lines.append(json.dumps(json_clean(cfg), indent=2))
    lines.append("```")
    lines.append("")
    return lines


def _markdown_models(result: BenchmarkResult) -> list[str]:
    """One item per fitted model: parameters, identifiability, residual std, notes, warnings."""
    lines = ["## Models", ""]
    for m in result.models:
        if m.get("error"):
            continue
        params = m.get("parameters") or {}
        shown = ", ".join(f"{k} = {v:.4g}" for k, v in params.items())
        seed = "" if m.get("seed") is None else f", seed {m['seed']}"
        lines.append(f"- **{m['name']}** ({m['kind']}{seed}): {shown}")
        ident = m.get("identifiability")
        if ident:
            lines.append(f"  - {ident['message']}")
        if m.get("filter_residual_std") is not None:
            lines.append(
                f"  - filter steering-residual std (training run): "
                f"{m['filter_residual_std']:.3g} rad"
            )
        if m.get("note"):
            lines.append(f"  - {m['note']}")
        for w in m.get("warnings") or []:
            lines.append(f"  - warning: {w}")
    lines.append("")
    return lines


_FIGURE_CAPTIONS = {
    "steering_prediction": "Steering prediction vs measured on one validation run "
    "(paper Fig. 4) and the prediction error",
    "residual_acf": "Autocorrelation of the one-step residuals, training run and mean "
    "over the illustrative driver's validation runs (paper Fig. 5)",
    "lateral_estimate": "Lateral estimate vs truth and the true lane's weight on one "
    "validation run (paper Fig. 8)",
    "lateral_error": "Lateral error over the first seconds, mean and std over the "
    "illustrative driver's validation runs (paper Fig. 9)",
    "curved_steering": "Steering prediction on the curved track (paper Fig. 7)",
}


def _markdown_figures(cfg: dict[str, Any], figures: dict[str, str]) -> list[str]:
    """The figures with their captions (nothing without figures)."""
    if not figures:
        return []
    lines = ["## Figures", ""]
    first = (cfg.get("seeds") or [None])[0]
    if first is not None:
        lines.append(f"The figures show population seed {first}.")
        lines.append("")
    for key, name in figures.items():
        lines.append(f"### {_FIGURE_CAPTIONS.get(key, key)}")
        lines.append("")
        lines.append(f"![{key}]({name})")
        lines.append("")
    return lines


def _markdown_run(result: BenchmarkResult) -> list[str]:
    """How the protocol ran (executor, wall time) and the versions."""
    ex = result.executor
    return [
        "## Run",
        "",
        f"Executor: {ex['kind']}"
        + (f", {ex['workers']} workers" if ex.get("workers") else "")
        + (f", scheduler {ex['scheduler']}" if ex.get("scheduler") else "")
        + f", {ex['tasks']} tasks of up to {ex.get('batch_size')} runs. Protocol wall time "
        f"{result.timing.get('total', float('nan')):.1f} s (writing files and figures excluded).",
        "",
        "Versions: " + ", ".join(f"{k} {v}" for k, v in result.versions.items() if k != "platform"),
        "",
    ]


# ----------------------------------------------------------------------- output
def write_outputs(
    result: BenchmarkResult, out_dir: str | Path, *, figures: bool = True
) -> dict[str, Path]:
    """Write results.json, the CSV tables, report.md and (optionally) the figures.

    Returns:
        {name: path} of every file written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    doc = result.to_json_dict()
    path = out / "results.json"
    path.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    written["results.json"] = path
    for attribute, name in CSV_TABLES.items():
        frame = pd.DataFrame(list(doc[attribute]))
        if attribute in ("steering", "curved", "estimation", "summary") or not frame.empty:
            frame.to_csv(out / name, index=False)
            written[name] = out / name
    figure_names = write_figures(result, out) if figures else {}
    for name in figure_names.values():
        written[name] = out / name
    report = out / "report.md"
    report.write_text(markdown_report(result, figure_names), encoding="utf-8")
    written["report.md"] = report
    return written
