"""Aggregation of the per-run rows: per-driver tables, per-seed summaries, the verdict.

Three levels, all with pandas ``groupby``:

1. per (seed, driver, model): means over the driver's validation runs (the
   paper's tables 1 and 2, one set per population seed);
2. per (seed, model): means over drivers (:func:`summarize_seeds`), the
   ranks of the models on that seed;
3. per model, over seeds (:func:`verdict`): the mean of the per-seed values
   and a 95 % confidence interval from Student's t over the seeds::

       mean = (1/S) sum_s x_s
       half = t_{0.975, S-1} * sd(x_s) / sqrt(S)         (no interval with S = 1)

   Each seed draws a new population of drivers and new runs, so the per-seed
   values are independent draws of what the benchmark measures and the
   interval says how much a verdict depends on the draw. ``rank_stability``
   is the share of seeds on which a model holds its overall rank (the rank
   of its mean over seeds).

Degenerate runs are counted per row (``degenerate_runs``), left out of the
means and of ``n_runs``: a run whose rows carry a ``degenerate`` reason
(:func:`benchmarks.protocol.tasks.degenerate_reason`: too short, steering
that does not vary, a car that stands; the same runs for every model), and
a row whose score is not finite.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from benchmarks import paper_values
from benchmarks.protocol.config import BASELINES, BUILTIN_MODELS, ILLUSTRATIVE
from hasa_env.steering.loading import PAPER_STEERING_RATIO

__all__ = [
    "aggregate_estimation",
    "aggregate_steering",
    "confidence_interval",
    "summarize_seeds",
    "verdict",
]

_GROUP = ["seed", "driver", "track", "model"]


def _records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    """Rows as dicts of plain Python values (NaN -> None, numpy scalars -> Python)."""
    out = []
    for row in frame.to_dict(orient="records"):
        clean: dict[str, Any] = {}
        for key, value in row.items():
            if isinstance(value, np.generic):
                value = value.item()
            if isinstance(value, float) and not math.isfinite(value):
                value = None
            clean[str(key)] = value
        out.append(clean)
    return out


def _frame(rows: Sequence[dict[str, Any]]) -> pd.DataFrame:
    frame = pd.DataFrame(list(rows))
    if "seed" in frame:
        frame["seed"] = frame["seed"].astype(object)
    return frame


def _finite_mean(values: pd.Series) -> float:
    arr = pd.to_numeric(values, errors="coerce").to_numpy(dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    return float(arr.mean()) if arr.size else float("nan")


def _finite_std(values: pd.Series) -> float:
    arr = pd.to_numeric(values, errors="coerce").to_numpy(dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    return float(arr.std(ddof=1)) if arr.size > 1 else float("nan")


def _without_degenerate(frame: pd.DataFrame, key: str, columns: Sequence[str]) -> pd.DataFrame:
    """``frame`` with a bool ``_degenerate`` column (a ``degenerate`` reason, or a non-finite
    ``key``) and, in those rows, NaN in ``columns``: left out of every mean and count."""
    values = pd.to_numeric(frame[key], errors="coerce").to_numpy(dtype=np.float64)
    flagged = ~np.isfinite(values)
    if "degenerate" in frame:
        flagged |= frame["degenerate"].notna().to_numpy()
    frame = frame.copy()
    frame["_degenerate"] = flagged
    for column in columns:
        if column in frame:
            frame[column] = frame[column].astype(object).where(~flagged, None)
    return frame


def _kept(flags: pd.Series) -> int:
    return int((~flags.astype(bool)).sum())


def _sample_count(n: pd.Series) -> int:
    return int(pd.to_numeric(n).fillna(0).sum())


def _count(flags: pd.Series) -> int:
    return int(flags.astype(bool).sum())


def aggregate_steering(rows: Sequence[dict[str, Any]], models: Sequence[str]) -> list[dict]:
    """Per (seed, driver, model): means over runs, the RMSE decrease vs the two-point
    model, whiteness, free runs, and the paper's values in road-wheel radians."""
    if not rows:
        return []
    frame = _frame(rows)
    frame = frame[frame["model"].isin(models)]
    scored = ("n", "rmse", "r2", "r2_increments", "ljung_box_p", "free_run_rmse",
              "free_run_diverged")  # fmt: skip
    frame = _without_degenerate(frame, "rmse", scored)
    grouped = frame.groupby(_GROUP, sort=False, dropna=False)
    table = grouped.agg(
        n_runs=("_degenerate", _kept),
        n_samples=("n", _sample_count),
        rmse=("rmse", _finite_mean),
        rmse_std=("rmse", _finite_std),
        r2=("r2", _finite_mean),
        r2_increments=("r2_increments", _finite_mean),
        degenerate_runs=("_degenerate", _count),
        ljung_box_p_median=(
            "ljung_box_p",
            lambda p: (
                float(np.nanmedian(p.astype(float))) if np.isfinite(p.astype(float)).any() else None
            ),
        ),
        white_runs=("ljung_box_p", lambda p: int(np.sum(p.astype(float) > 0.05))),
        **(
            {
                "sdlp": ("sdlp", _finite_mean),
                "max_abs_lateral_offset": ("max_abs_lateral_offset", "max"),
                "left_road_runs": ("left_road", lambda v: int(v.astype(bool).sum())),
            }
            if "sdlp" in frame
            else {}
        ),
    ).reset_index()
    free = frame[frame["free_run_diverged"].notna()] if "free_run_diverged" in frame else None
    if free is not None and len(free):
        free = free.assign(
            bounded_rmse=free["free_run_rmse"].where(~free["free_run_diverged"].astype(bool))
        )
        free_table = (
            free.groupby(_GROUP, sort=False, dropna=False)
            .agg(
                free_run_rmse=("bounded_rmse", _finite_mean),
                free_run_diverged=("free_run_diverged", lambda d: int(d.astype(bool).sum())),
            )
            .reset_index()
        )
        table = table.merge(free_table, on=_GROUP, how="left")
    else:
        table["free_run_rmse"] = np.nan
        table["free_run_diverged"] = None
    base = table[table["model"] == "two_point"][["seed", "driver", "track", "rmse"]].rename(
        columns={"rmse": "two_point_rmse"}
    )
    table = table.merge(base, on=["seed", "driver", "track"], how="left")
    table["rmse_decrease_vs_two_point"] = np.where(
        table["model"] == "two_point", np.nan, 1.0 - table["rmse"] / table["two_point_rmse"]
    )
    table = table.drop(columns="two_point_rmse")
    paper = pd.DataFrame(
        [
            _paper_steering(d, m, t)
            for d, m, t in zip(table["driver"], table["model"], table["track"], strict=True)
        ]
    )
    table = pd.concat([table.reset_index(drop=True), paper], axis=1)
    table["rmse_over_paper"] = table["rmse"] / table["paper_rmse"].astype(float)
    return _records(table)


def _paper_steering(driver: str, model: str, track: str) -> dict[str, Any]:
    """The paper's values for a row: RMSE converted to road-wheel rad (/ 15) and as printed."""
    keys: dict[str, Any] = {
        "paper_rmse": None,
        "paper_rmse_steering_wheel": None,
        "paper_r2": None,
        "paper_rmse_decrease": None,
    }
    if track == "curved":
        if model in paper_values.CURVED and driver == ILLUSTRATIVE:
            r2, rmse = paper_values.CURVED[model]
            keys.update(paper_rmse_steering_wheel=rmse, paper_r2=r2)
            if model == "generalized":
                base = paper_values.CURVED["two_point"][1]
                keys["paper_rmse_decrease"] = 1.0 - rmse / base
    else:
        values = paper_values.TABLE_1.get(driver)
        if values is not None and model in BUILTIN_MODELS:
            if model == "two_point":
                keys.update(paper_rmse_steering_wheel=values[0], paper_r2=values[1])
            else:
                keys.update(
                    paper_rmse_steering_wheel=values[2],
                    paper_r2=values[3],
                    paper_rmse_decrease=values[4],
                )
    if keys["paper_rmse_steering_wheel"] is not None:
        keys["paper_rmse"] = keys["paper_rmse_steering_wheel"] / PAPER_STEERING_RATIO
    return keys


def aggregate_estimation(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (seed, driver, model): lateral RMSE mean/std/max over runs, decisions, paper values."""
    if not rows:
        return []
    frame = _frame(rows)
    frame = _without_degenerate(
        frame, "lateral_rmse",
        ("lateral_rmse", "steps_to_decide", "true_lane_final", "final_true_lane_weight"),
    )  # fmt: skip
    frame["steps"] = pd.to_numeric(frame["steps_to_decide"], errors="coerce")
    table = (
        frame.groupby(_GROUP, sort=False, dropna=False)
        .agg(
            n_runs=("_degenerate", _kept),
            lateral_rmse_mean=("lateral_rmse", _finite_mean),
            lateral_rmse_std=("lateral_rmse", _finite_std),
            lateral_rmse_max=(
                "lateral_rmse",
                lambda v: float(np.nanmax(v.astype(float))) if v.notna().any() else None,
            ),
            degenerate_runs=("_degenerate", _count),
            steps_to_decide_median=(
                "steps",
                lambda v: float(v.median()) if v.notna().any() else None,
            ),
            steps_to_decide_max=("steps", lambda v: float(v.max()) if v.notna().any() else None),
            decided_runs=("steps", lambda v: int(v.notna().sum())),
            true_lane_final_runs=("true_lane_final", lambda v: int((v == True).sum())),  # noqa: E712
            final_true_lane_weight_mean=("final_true_lane_weight", _finite_mean),
            wrong_lane_confident_runs=(
                "wrong_lane_confident",
                lambda v: int(v.astype(bool).sum()),
            ),
            wrong_lane_confident_share=("wrong_lane_confident_share", _finite_mean),
            undecided_runs=("final_decision", lambda v: int((v == "undecided").sum())),
            model_mismatch_runs=("final_decision", lambda v: int((v == "model_mismatch").sum())),
            lateral_nees=("lateral_nees", _finite_mean),
            nis_speed=("nis_speed", _finite_mean),
            nis_camera=("nis_camera", _finite_mean),
            nis_steering=("nis_steering", _finite_mean),
        )
        .reset_index()
    )
    paper_mean: list[float | None] = []
    paper_std: list[float | None] = []
    for driver, model in zip(table["driver"], table["model"], strict=True):
        paper = paper_values.TABLE_2.get(driver)
        if paper is not None and model in BUILTIN_MODELS:
            offset = 0 if model == "two_point" else 2
            paper_mean.append(paper[offset])
            paper_std.append(paper[offset + 1])
        elif model == "no_steering":
            paper_mean.append(paper_values.NO_STEERING_LATERAL_RMSE)
            paper_std.append(None)
        else:
            paper_mean.append(None)
            paper_std.append(None)
    table["paper_lateral_rmse_mean"] = paper_mean
    table["paper_lateral_rmse_std"] = paper_std
    return _records(table)


def _kind(name: str, kinds: Mapping[str, str] | None = None) -> str:
    if kinds and name in kinds:
        return kinds[name]
    if name in BUILTIN_MODELS:
        return "builtin"
    return "baseline" if name in BASELINES else "user"


_RANKED_KINDS = ("builtin", "user")
"""The kinds of models ranked against each other (not baselines, stress models, or the
models' estimators without the evidence checks)."""

_SAFETY_COUNTS = ("wrong_lane_confident_runs", "undecided_runs", "model_mismatch_runs")


def summarize_seeds(
    steering: Sequence[dict],
    estimation: Sequence[dict],
    models: Sequence[str],
    kinds: Mapping[str, str] | None = None,
    curved_estimation: Sequence[dict] = (),
) -> list[dict[str, Any]]:
    """Per (seed, model): means over drivers; the models' ranks on that seed; the
    safety counts (runs ending confidently in a wrong lane, undecided, with a model
    mismatch) and the mixture's consistency (lateral NEES, steering NIS); the lateral
    RMSE on the curved track."""
    names = list(models) + [b for b in BASELINES if b not in models]
    s = pd.DataFrame(list(steering)) if steering else pd.DataFrame(columns=["seed", "model"])
    e = pd.DataFrame(list(estimation)) if estimation else pd.DataFrame(columns=["seed", "model"])
    c = (
        pd.DataFrame(list(curved_estimation))
        if curved_estimation
        else pd.DataFrame(columns=["seed", "model"])
    )
    seeds = list(dict.fromkeys([*s.get("seed", []), *e.get("seed", [])]))
    rows = []
    for seed in seeds:
        for name in names:
            ss = s[(s["seed"].astype(object) == seed) & (s["model"] == name)] if len(s) else s
            ee = e[(e["seed"].astype(object) == seed) & (e["model"] == name)] if len(e) else e
            cc = c[(c["seed"].astype(object) == seed) & (c["model"] == name)] if len(c) else c
            if not len(ss) and not len(ee):
                continue
            row: dict[str, Any] = {
                "seed": seed,
                "model": name,
                "kind": _kind(name, kinds),
                "drivers": int((ss if len(ss) else ee)["driver"].nunique()),
                "rmse": _finite_mean(ss["rmse"]) if len(ss) else None,
                "r2_increments": _finite_mean(ss["r2_increments"]) if len(ss) else None,
                "rmse_decrease_vs_two_point": _finite_mean(ss["rmse_decrease_vs_two_point"])
                if len(ss) and name != "two_point"
                else None,
                "rmse_over_paper_median": float(np.nanmedian(ss["rmse_over_paper"].astype(float)))
                if len(ss) and ss["rmse_over_paper"].notna().any()
                else None,
                "white_runs": int(ss["white_runs"].sum()) if len(ss) else None,
                "free_run_diverged": int(pd.to_numeric(ss["free_run_diverged"]).fillna(0).sum())
                if len(ss) and ss["free_run_diverged"].notna().any()
                else None,
                "runs": int(ss["n_runs"].sum()) if len(ss) else int(ee["n_runs"].sum()),
                "lateral_rmse": _finite_mean(ee["lateral_rmse_mean"]) if len(ee) else None,
                "decided_runs": int(ee["decided_runs"].sum()) if len(ee) else None,
                "estimated_runs": int(ee["n_runs"].sum()) if len(ee) else None,
                "lateral_nees": _finite_mean(ee["lateral_nees"]) if len(ee) else None,
                "nis_steering": _finite_mean(ee["nis_steering"]) if len(ee) else None,
                "curved_lateral_rmse": _finite_mean(cc["lateral_rmse_mean"]) if len(cc) else None,
                "curved_estimated_runs": int(cc["n_runs"].sum()) if len(cc) else None,
                "degenerate_runs": int(
                    max(
                        ss["degenerate_runs"].sum() if len(ss) else 0,
                        ee["degenerate_runs"].sum() if len(ee) else 0,
                    )
                ),
            }
            for key in _SAFETY_COUNTS:
                row[key] = int(ee[key].sum()) if len(ee) else None
                row[f"curved_{key}"] = int(cc[key].sum()) if len(cc) else None
            rows.append(row)
    table = pd.DataFrame(rows)
    for key, rank_key in (("rmse", "rank_steering"), ("lateral_rmse", "rank_lateral")):
        table[rank_key] = None
        if not len(table):
            continue
        ranked = table[table["kind"].isin(_RANKED_KINDS) & table[key].notna()]
        ranks = ranked.groupby("seed")[key].rank(method="min")
        table.loc[ranks.index, rank_key] = ranks.astype(int)
    return _records(table)


def confidence_interval(values: Sequence[float], level: float = 0.95) -> tuple[float, float, float]:
    """(mean, low, high) of finite ``values``: Student's t interval over them (NaN bounds
    with fewer than two values)."""
    arr = np.asarray([v for v in values if v is not None], dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    if arr.size == 0:
        return float("nan"), float("nan"), float("nan")
    mean = float(arr.mean())
    if arr.size < 2:
        return mean, float("nan"), float("nan")
    half = float(
        stats.t.ppf(0.5 + level / 2.0, arr.size - 1) * arr.std(ddof=1) / math.sqrt(arr.size)
    )
    return mean, mean - half, mean + half


_VERDICT_KEYS = ("rmse", "r2_increments", "rmse_decrease_vs_two_point", "lateral_rmse",
                 "rmse_over_paper_median", "curved_lateral_rmse", "lateral_nees")  # fmt: skip


def verdict(
    seed_rows: Sequence[dict[str, Any]],
    models: Sequence[str],
    kinds: Mapping[str, str] | None = None,
) -> list[dict[str, Any]]:
    """Per model over seeds: means with 95 % intervals (see the module docstring), ranks,
    rank stability, decisions and free-run divergences in all."""
    frame = pd.DataFrame(list(seed_rows))
    if not len(frame):
        return []
    names = list(models) + [b for b in BASELINES if b not in models]
    rows = []
    for name in names:
        part = frame[frame["model"] == name]
        if not len(part):
            continue
        row: dict[str, Any] = {
            "model": name,
            "kind": _kind(name, kinds),
            "seeds": int(part["seed"].nunique()),
            "drivers": int(part["drivers"].max()),
            "runs": int(part["runs"].sum()),
        }
        for key in _VERDICT_KEYS:
            mean, low, high = confidence_interval(part[key].tolist())
            row[key] = mean
            row[f"{key}_ci_low"] = low
            row[f"{key}_ci_high"] = high
        counts = ("decided_runs", "estimated_runs", "white_runs", "free_run_diverged",
                  "degenerate_runs", "curved_estimated_runs", *_SAFETY_COUNTS,
                  *(f"curved_{k}" for k in _SAFETY_COUNTS))  # fmt: skip
        for key in counts:
            values = pd.to_numeric(part[key], errors="coerce")
            row[key] = int(values.sum()) if values.notna().any() else None
        rows.append(row)
    table = pd.DataFrame(rows)
    for key, rank_key in (("rmse", "rank_steering"), ("lateral_rmse", "rank_lateral")):
        table[rank_key] = None
        table[f"{rank_key}_stability"] = None
        ranked = table[table["kind"].isin(_RANKED_KINDS) & table[key].notna()]
        if not len(ranked):
            continue
        overall = ranked[key].rank(method="min").astype(int)
        table.loc[overall.index, rank_key] = overall
        for i in overall.index:
            per_seed = frame[frame["model"] == table.loc[i, "model"]][rank_key]
            per_seed = pd.to_numeric(per_seed, errors="coerce").dropna()
            if len(per_seed):
                table.loc[i, f"{rank_key}_stability"] = float(np.mean(per_seed == overall[i]))
    return _records(table)
