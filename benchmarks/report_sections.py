"""The tables of a benchmark result: their columns, cell formats, captions and rows.

:func:`report_sections` gives (key, title, rows, columns, group) of each table, in the
order :mod:`benchmarks.report` prints them (its module docstring lists them);
:func:`pooled` averages the per-seed per-driver rows over seeds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, cast

import numpy as np
import pandas as pd

from benchmarks.live_by_driver import LEAST_LIVE_DRIVERS, least_live_drivers, least_live_share
from benchmarks.protocol import BenchmarkResult
from benchmarks.protocol.intervals import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED
from benchmarks.tables import (
    Column,
    count_share,
    fixed,
    interval,
    missing,
    percent,
    scientific,
    text,
)
from estimators.calibration import CALIBRATION_BINS
from hasa_env.steering.loading import PAPER_STEERING_RATIO

__all__ = ["Section", "checks_rows", "decision_time", "pooled", "report_sections"]


def _paper(value: Any) -> str:
    return "" if missing(value) else f"{value:.2g}"


def _paper_pct(value: Any) -> str:
    return "" if missing(value) else f"{100 * value:.0f}%"


def _ratio(value: Any) -> str:
    return "-" if missing(value) else f"{value:.2f}"


def _stability(row: dict[str, Any], rank: str) -> str:
    """ "rank of models (share of bootstrap replicates holding it)", e.g. "2 of 4 (85%)"."""
    value, share, models = row.get(rank), row.get(f"{rank}_stability"), row.get(f"{rank}_models")
    share, models = cast(Any, share), cast(Any, models)  # missing() checks them
    if value is None:
        return "-"
    shown = f"{value}" if missing(models) else f"{value} of {int(models)}"
    return shown if missing(share) else f"{shown} ({100 * share:.0f}%)"


def decision_time(row: dict[str, Any]) -> str:
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
    Column(interval(fixed(3), "road_information"), "road info [95% CI]"),
    Column(interval(percent, "rmse_decrease_vs_two_point"), "RMSE dec. [95% CI]"),
    Column(interval(fixed(2), "rmse_over_paper_median"), "ours/paper [95% CI]"),
    Column(interval(fixed(3), "lateral_rmse"), "lat. RMSE (m) [95% CI]"),
    Column(
        interval(fixed(3), "gain_over_steering_free"), "gain over best steering-free (m) [95% CI]"
    ),
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
    Column(count_share("wrong_lane_ever_runs", "estimated_runs"), "ever conf. wrong"),
    Column(count_share("wrong_decision_runs", "estimated_runs"), "decided wrong (incl. withheld)"),
    Column(count_share("undecided_runs", "estimated_runs"), "undecided"),
    Column(count_share("model_mismatch_runs", "estimated_runs"), "model mismatch"),
    Column(decision_time, "decides in (s) median / p90"),
    Column(count_share("never_decided_runs", "estimated_runs"), "never decided"),
    Column(interval(percent, "decided_time_share"), "time decided [95% CI]"),
    Column(interval(percent, "steering_off_share"), "steering off [95% CI]"),
    Column(interval(percent, "steering_live_share"), "steering live [95% CI]"),
    Column(interval(fixed(3), "lateral_rmse_after_decision"), "lat. RMSE after dec. (m) [95% CI]"),
    Column(interval(fixed(2), "lateral_nees"), "lat. NEES [95% CI]"),
    Column(interval(fixed(3), "lane_ece"), "lane ECE [95% CI]"),
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
    Column("road_information", "road info", fixed(3)),
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
    Column(lambda r: _prediction_cell(r.get("prediction")), "predicts (vs own past)", left=True),
    Column(lambda r: _bends_cell(r.get("bends")), "steering on bends", left=True),
]


def _bends_cell(bends: tuple[Any, Any] | None) -> str:
    """How the estimator uses the model's steering on bends, from its filter's
    ``steering_curvature_feedforward`` and ``steering_curvature_limit`` (1/m; None: no limit):
    "feed-forward G 2.1" (docs/design.md §8.28), "off above 0.0002 1/m" or "counts"."""
    if bends is None or bends[0] is None:
        return "-"
    feedforward, limit = bends
    if feedforward:
        return f"feed-forward G {feedforward:.3g}"
    return "counts" if limit is None else f"off above {limit:.2g} 1/m"


def _prediction_cell(levels: tuple[float, float] | None) -> str:
    """The prediction check in a cell: the model's one-step residual over the lane-free one,
    "0.97 x" or "153 x: no better" (docs/design.md §8.13.1)."""
    if not levels or levels[1] is None or levels[0] is None:
        return "-"
    model, lane_free = levels
    if lane_free <= 0:
        return "no better" if model > 0 else "-"
    ratio = model / lane_free
    return f"{ratio:.3g} x" + (": no better" if ratio >= 1 else "")


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
    Column("road_information", "road info", fixed(3)),
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

_MEAN_KEYS = ("rmse", "r2", "r2_increments", "road_information", "rmse_decrease_vs_two_point",
              "free_run_rmse",
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


def checks_rows(result: BenchmarkResult) -> list[dict[str, Any]]:
    rows = []
    for m in result.models:
        checks = m.get("checks") or {}
        if m.get("error") or not (checks or m.get("lane_keeping")):
            continue
        levels = (m.get("prediction_residual_std"), m.get("lane_free_residual_std"))
        bends = (m.get("steering_curvature_feedforward"), m.get("steering_curvature_limit"))
        rows.append(
            {"name": m["name"], "kind": m.get("kind"), "seed": m.get("seed"), **checks}
            | {"lane_keeping": m.get("lane_keeping")}
            | {"prediction": levels if None not in levels else None}
            | {"bends": bends}
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


_ROAD_INFO = (
    "road info = 1 - SSE / SSE of the road-blind AR(2) baseline on the same runs' one-step "
    "prediction (the share of what the baseline misses that the model explains from the road; "
    "0: no better than blind to it)"
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
            f"paper's converted to road-wheel rad (paper / {PAPER_STEERING_RATIO:g}); {_ROAD_INFO}; rank "
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
            "(mean (y_hat - y)^2 / sigma^2; 1: the reported std is right), the lane ECE "
            "(expected calibration error of the lane probabilities, every step and hypothesis; "
            "0: they mean what they say; the reliability table below), steering off = share of "
            "a run's time the steering channel is switched off, steering live = share of it "
            "the steering counts as lane evidence at half its weight or more (used, not gated, "
            "no mismatch, evidence scale <= 2), and the curved "
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


def _reliability_cell(index: int) -> Any:
    def cell(row: dict[str, Any]) -> str:
        bins = row.get("reliability") or []
        entry = bins[index] if index < len(bins) else None
        return "" if entry is None else f"{entry[1]:.2f} ({entry[2]})"

    return cell


_RELIABILITY_COLUMNS = [
    Column("model", "Estimator", left=True),
    *(
        Column(_reliability_cell(b), f"{b / CALIBRATION_BINS:.1f}-{(b + 1) / CALIBRATION_BINS:.1f}")
        for b in range(CALIBRATION_BINS)
    ),
]


def _reliability_section(result: BenchmarkResult) -> Section:
    return (
        "reliability",
        "Reliability of the lane probabilities (main track): every (step, hypothesis) pair by "
        "the probability the estimator gave the hypothesis (columns); each cell is the share "
        "of those pairs whose hypothesis was the true lane (calibrated: inside the column's "
        "range) and, in brackets, how many pairs fell there",
        [r for r in result.summary if r.get("reliability")],
        _RELIABILITY_COLUMNS,
        None,
    )


_SHARE_COLUMNS = {
    state: Column(f"steering_{state}_share", header, percent)
    for state, header in (
        ("live", "live"),
        ("off", "off (speed, curvature)"),
        ("unused", "unused (missing, gated)"),
        ("mismatch", "model mismatch"),
        ("tempered_model_error", "tempered: model error"),
        ("tempered_autocorrelation", "tempered: autocorrelation"),
    )
}
"""The report's column of each state of the steering channel (its per-run share)."""

_CHANNEL_COLUMNS = [
    Column("model", "Estimator", left=True),
    Column("runs", "runs"),
    *_SHARE_COLUMNS.values(),
    Column("least_live_share", "not live: the 5 least-live drivers' share", percent),
]


def channel_rows(result: BenchmarkResult) -> list[dict[str, Any]]:
    """Per estimator with a steering channel, the mean over its main-track runs of each share
    of :func:`estimators.calibration.steering_channel_shares` (the per-run columns of
    ``runs_estimation``; rows from before these columns give none)."""
    keys = [str(c.key) for c in _CHANNEL_COLUMNS[2:-1]]
    frame = pd.DataFrame(result.runs_estimation)
    if frame.empty or not set(keys) <= set(frame.columns):
        return []
    main = frame[(frame["track"] == result.config.get("track", "straight"))]
    main = main[main["steering_live_share"].notna()]
    table = main.groupby("model", sort=False)[keys].mean()
    table.insert(0, "runs", main.groupby("model", sort=False).size())
    table["least_live_share"] = [least_live_share(main[main["model"] == m]) for m in table.index]
    return [{"model": model, **row} for model, row in table.to_dict("index").items()]


def _channel_section(result: BenchmarkResult) -> Section:
    return (
        "steering_channel",
        "Why the steering was or was not lane evidence (main track, mean over runs of each "
        "run's share of its steps, docs/design.md §8.14): live (counted at half its weight or "
        "more), off by the speed or curvature rule, unused (reading missing or gated), in "
        "model mismatch, or tempered below half its weight by the model-error ratio lambda "
        "alone or by the autocorrelation of the steering innovations; the last column: the "
        f"share of the time not live (summed over runs) that the {LEAST_LIVE_DRIVERS} drivers "
        "with the most of it hold (near 100 %: a few drivers make the shortfall, "
        "docs/design.md §8.35)",
        channel_rows(result),
        _CHANNEL_COLUMNS,
        None,
    )


_LEAST_LIVE_COLUMNS = [
    Column("model", "Estimator", left=True),
    Column("seed", "seed"),
    Column("driver", "driver", left=True),
    Column("runs", "runs"),
    *(
        _SHARE_COLUMNS[state]
        for state in ("live", "tempered_model_error", "tempered_autocorrelation", "mismatch")
    ),
    Column("model_error", "median lambda", fixed(2)),
    Column("archetype", "archetype", left=True),
    Column("command_std", "command noise std (rad)", fixed(4)),
]


def _least_live_section(result: BenchmarkResult) -> Section:
    return (
        "least_live_drivers",
        f"The {LEAST_LIVE_DRIVERS} drivers (seed, name) that hold the most of each steering "
        "model's time not live (main track; mean over each driver's runs): tempered by the "
        "model-error ratio lambda (its median over the runs: the driver's steering noisier than "
        "the model's level) or by the autocorrelation of the innovations (the driver's dynamics "
        "not the model's), with the driver's archetype and command-noise std (recorded "
        "drivers: unknown; docs/design.md §8.35; examples/live_share_by_driver.py prints every "
        "driver)",
        least_live_drivers(result, LEAST_LIVE_DRIVERS),
        _LEAST_LIVE_COLUMNS,
        "model",
    )


def _checks_section(result: BenchmarkResult) -> Section:
    return (
        "checks",
        "The fits' checks per seed (docs/design.md §6.5): ridge penalty chosen by blocked "
        "cross-validation on the training run, condition number of the standardized design, "
        "largest AR pole, lane-offset identifiability with the steering-sensor noise; "
        "whether the model, driving 4 cars itself on the training run's conditions, "
        "keeps them on the road (docs/design.md §8.11), and its one-step residual on the "
        "training run's steering over that of a lane-free autoregression of its order "
        "(docs/design.md §8.13.1); a model that does not drive, or predicts no better, gives "
        "the estimator no lane evidence; on bends, the estimator either takes the bend's steady "
        "steering G kappa off the measured steering (a straight-road fit that pins G down, "
        "docs/design.md §8.28) or switches the steering off above the curvature it was fitted on",
        checks_rows(result),
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
            f"with the paper's 'R^2 Acc'); {_ROAD_INFO}; free-run RMSE over the runs whose free "
            "run stayed "
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


def report_sections(result: BenchmarkResult) -> list[Section]:
    """Every table of the report, in order."""
    return [
        *_verdict_sections(result),
        _reliability_section(result),
        _channel_section(result),
        _least_live_section(result),
        _checks_section(result),
        *_steering_sections(result),
        *_estimation_sections(result),
    ]
