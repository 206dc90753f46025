"""Aggregation of per-run rows into per-driver tables and the summary."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchmarks import paper_values
from benchmarks.protocol.config import BASELINES, BUILTIN_MODELS, ILLUSTRATIVE

__all__ = ["aggregate_estimation", "aggregate_steering", "summarize"]


def _mean(values: Sequence[float]) -> float:
    arr = np.asarray(values, dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    return float(arr.mean()) if arr.size else float("nan")


def _std(values: Sequence[float]) -> float:
    arr = np.asarray(values, dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    return float(arr.std(ddof=1)) if arr.size > 1 else float("nan")


def aggregate_steering(rows: Sequence[dict[str, Any]], models: Sequence[str]) -> list[dict]:
    """Per (driver, model): means over runs; RMSE decrease vs the two-point model; paper values."""
    grouped: dict[tuple[str, str], list[dict]] = defaultdict(list)
    order: list[str] = []
    for row in rows:
        if row["driver"] not in order:
            order.append(row["driver"])
        grouped[(row["driver"], row["model"])].append(row)
    out = []
    for driver in order:
        base = grouped.get((driver, "two_point"))
        base_rmse = _mean([r["rmse"] for r in base]) if base else float("nan")
        for model in models:
            runs = grouped.get((driver, model))
            if not runs:
                continue
            rmse = _mean([r["rmse"] for r in runs])
            p_values = np.array([r["ljung_box_p"] for r in runs], dtype=np.float64)
            finite_p = p_values[np.isfinite(p_values)]
            entry = {
                "driver": driver,
                "track": runs[0]["track"],
                "model": model,
                "n_runs": len(runs),
                "n_samples": int(sum(r["n"] for r in runs)),
                "rmse": rmse,
                "rmse_std": _std([r["rmse"] for r in runs]),
                "r2": _mean([r["r2"] for r in runs]),
                "r2_increments": _mean([r["r2_increments"] for r in runs]),
                "rmse_decrease_vs_two_point": (
                    None if model == "two_point" else 1.0 - rmse / base_rmse
                ),
                "ljung_box_p_median": float(np.median(finite_p)) if finite_p.size else None,
                "white_runs": int(np.sum(finite_p > 0.05)),
            }
            entry.update(_paper_steering(driver, model, runs[0]["track"]))
            out.append(entry)
    return out


def _paper_steering(driver: str, model: str, track: str) -> dict[str, Any]:
    keys = {"paper_rmse": None, "paper_r2": None, "paper_rmse_decrease": None}
    if track == "curved":
        if model in paper_values.CURVED and driver == ILLUSTRATIVE:
            r2, rmse = paper_values.CURVED[model]
            keys.update(paper_rmse=rmse, paper_r2=r2)
            if model == "generalized":
                base = paper_values.CURVED["two_point"][1]
                keys["paper_rmse_decrease"] = 1.0 - rmse / base
        return keys
    values = paper_values.TABLE_1.get(driver)
    if values is None or model not in BUILTIN_MODELS:
        return keys
    if model == "two_point":
        keys.update(paper_rmse=values[0], paper_r2=values[1])
    else:
        keys.update(paper_rmse=values[2], paper_r2=values[3], paper_rmse_decrease=values[4])
    return keys


def aggregate_estimation(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    grouped: dict[tuple[str, str], list[dict]] = defaultdict(list)
    order: list[tuple[str, str]] = []
    for row in rows:
        key = (row["driver"], row["model"])
        if key not in grouped:
            order.append(key)
        grouped[key].append(row)
    out = []
    for driver, model in order:
        runs = grouped[(driver, model)]
        rmse = [r["lateral_rmse"] for r in runs]
        steps = np.array(
            [np.nan if r["steps_to_decide"] is None else r["steps_to_decide"] for r in runs]
        )
        decided = steps[np.isfinite(steps)]
        entry = {
            "driver": driver,
            "model": model,
            "n_runs": len(runs),
            "lateral_rmse_mean": _mean(rmse),
            "lateral_rmse_std": _std(rmse),
            "lateral_rmse_max": float(np.nanmax(rmse)) if runs else None,
            "steps_to_decide_median": float(np.median(decided)) if decided.size else None,
            "steps_to_decide_max": float(np.max(decided)) if decided.size else None,
            "decided_runs": int(decided.size),
            "true_lane_final_runs": int(sum(r["true_lane_final"] for r in runs)),
            "paper_lateral_rmse_mean": None,
            "paper_lateral_rmse_std": None,
        }
        paper = paper_values.TABLE_2.get(driver)
        if paper is not None and model in BUILTIN_MODELS:
            offset = 0 if model == "two_point" else 2
            entry["paper_lateral_rmse_mean"] = paper[offset]
            entry["paper_lateral_rmse_std"] = paper[offset + 1]
        elif model == "no_steering":
            entry["paper_lateral_rmse_mean"] = paper_values.NO_STEERING_LATERAL_RMSE
        out.append(entry)
    return out


def summarize(
    steering: Sequence[dict], estimation: Sequence[dict], models: Sequence[str]
) -> list[dict[str, Any]]:
    """Per model: means over drivers; ranks by lateral RMSE and by steering RMSE."""
    rows = []
    for name in list(models) + [b for b in BASELINES]:
        s = [r for r in steering if r["model"] == name]
        e = [r for r in estimation if r["model"] == name]
        if not s and not e:
            continue
        rows.append(
            {
                "model": name,
                "kind": "builtin"
                if name in BUILTIN_MODELS
                else ("baseline" if name in BASELINES else "user"),
                "drivers": len({r["driver"] for r in (s or e)}),
                "rmse": _mean([r["rmse"] for r in s]) if s else None,
                "r2_increments": _mean([r["r2_increments"] for r in s]) if s else None,
                "rmse_decrease_vs_two_point": _mean(
                    [r["rmse_decrease_vs_two_point"] for r in s if r["model"] != "two_point"]
                )
                if s and name != "two_point"
                else None,
                "white_runs": int(sum(r["white_runs"] for r in s)) if s else None,
                "runs": int(sum(r["n_runs"] for r in s)) if s else int(sum(r["n_runs"] for r in e)),
                "lateral_rmse": _mean([r["lateral_rmse_mean"] for r in e]) if e else None,
                "decided_runs": int(sum(r["decided_runs"] for r in e)) if e else None,
                "estimated_runs": int(sum(r["n_runs"] for r in e)) if e else None,
            }
        )
    for key, rank_key in (("rmse", "rank_steering"), ("lateral_rmse", "rank_lateral")):
        ranked = sorted(
            (r for r in rows if r["kind"] != "baseline" and _finite(r[key])),
            key=lambda r, key=key: r[key],
        )
        for i, r in enumerate(ranked, start=1):
            r[rank_key] = i
        for r in rows:
            r.setdefault(rank_key, None)
    return rows


def _finite(value: Any) -> bool:
    return value is not None and isinstance(value, int | float) and math.isfinite(value)
