"""Aggregation of the per-run rows: per-driver tables, per-seed summaries, the verdict.

Why this module is long: the three levels below share one frame's columns and the safety
counts' definitions (a count added at the first level reaches the verdict and its exact
interval through one tuple); split, each level would restate them.

Three levels, all with pandas ``groupby``:

1. per (seed, driver, model): means over the driver's validation runs (the
   paper's tables 1 and 2, one set per population seed);
2. per (seed, model): means over drivers (:func:`summarize_seeds`), the
   ranks of the models on that seed;
3. per model, over seeds (:func:`verdict`): the mean of the per-seed values
   with a 95 % hierarchical percentile-bootstrap interval (seeds, then drivers
   within seeds; participants for recordings; :mod:`benchmarks.protocol.intervals`)::

       mean = (1/S) sum_s x_s,    x_s = mean over the seed's drivers
       [low, high] = 2.5 / 97.5 percentiles of the same mean over resampled
                     seeds and drivers (fixed generator seed)

   and exact (Clopper-Pearson) intervals of the shares of runs counted
   (decided, confidently in a wrong lane, undecided, model mismatch).
   Recordings have one "seed" (``None``): their interval is over participants.

Gain over the best steering-free baseline (``gain_over_steering_free``, m, with the same
bootstrap): :func:`benchmarks.protocol.gain.steering_free_gain`.

Ranks: every steering model and estimator of kind builtin, user or baseline
is ranked against all the others (smallest RMSE first), overall by the mean
over seeds and on each seed; stress models and the estimators without the
evidence checks are not ranked. ``rank_*_stability`` is the share of bootstrap
replicates on which a model holds its overall rank among all of them.

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
from benchmarks.protocol.calibration import lane_calibration
from benchmarks.protocol.config import BASELINES, BUILTIN_MODELS, ILLUSTRATIVE
from benchmarks.protocol.gain import steering_free_gain
from benchmarks.protocol.intervals import (
    clopper_pearson,
    hierarchical_bootstrap,
    percentile_interval,
    replicate_ranks,
)
from hasa_env.steering.loading import PAPER_STEERING_RATIO

__all__ = [
    "RANKED_KINDS",
    "aggregate_estimation",
    "aggregate_steering",
    "confidence_interval",
    "same_seed",
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
    """Per (seed, driver, model): means over runs (road information too), the RMSE decrease
    vs the two-point model, whiteness, free runs, and the paper's values in road-wheel rad."""
    if not rows:
        return []
    frame = _frame(rows)
    frame = frame[frame["model"].isin(models)]
    scored = ("n", "rmse", "r2", "r2_increments", "road_information", "ljung_box_p",
              "free_run_rmse", "free_run_diverged")  # fmt: skip
    frame = _without_degenerate(frame, "rmse", scored)
    grouped = frame.groupby(_GROUP, sort=False, dropna=False)
    table = grouped.agg(
        n_runs=("_degenerate", _kept),
        n_samples=("n", _sample_count),
        rmse=("rmse", _finite_mean),
        rmse_std=("rmse", _finite_std),
        r2=("r2", _finite_mean),
        r2_increments=("r2_increments", _finite_mean),
        road_information=("road_information", _finite_mean),
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


_DECISION_COLUMNS = ("time_to_decide", "decided_time_share", "lateral_rmse_after_decision",
                     "steering_off_share", "steering_live_share")  # fmt: skip
"""The per-run decision metrics (:func:`benchmarks.protocol.tasks._decision_metrics`)."""


def _censored_quantile(values: pd.Series | Sequence[Any], q: float) -> float | None:
    """The ``q`` quantile of times to decide, ``inf`` for a run that never decided; None
    (a run, or runs, left out: degenerate) are dropped. An observed value (inverted-CDF
    quantile); None when it is a run that never decided or there are no runs."""
    times = pd.to_numeric(pd.Series(values, dtype=object), errors="coerce").to_numpy(float)
    times = times[~np.isnan(times)]
    if not times.size:
        return None
    value = float(np.quantile(times, q, method="inverted_cdf"))
    return value if math.isfinite(value) else None


def _never(times: pd.Series) -> int:
    """Runs whose true-lane weight never passed the threshold (an infinite time to decide)."""
    return int(np.isposinf(pd.to_numeric(times, errors="coerce").to_numpy(float)).sum())


def _with_decision_columns(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with the columns rows made before them lack: the decision metrics (NaN) and
    ``wrong_decision_ever`` (before withheld decisions were counted: the reported ones)."""
    for column in _DECISION_COLUMNS:
        if column not in frame:
            frame[column] = np.nan
    if "wrong_decision_ever" not in frame:
        shares = pd.to_numeric(frame["wrong_lane_confident_share"], errors="coerce")
        frame["wrong_decision_ever"] = shares > 0
    return frame


def aggregate_estimation(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (seed, driver, model): lateral RMSE mean/std/max over runs, decisions, paper values."""
    if not rows:
        return []
    frame = _with_decision_columns(_frame(rows))
    # never decided: an infinite time (NaN is left for the degenerate runs, left out)
    frame["time_to_decide"] = pd.to_numeric(frame["time_to_decide"], errors="coerce").fillna(np.inf)
    frame = _without_degenerate(
        frame, "lateral_rmse",
        ("lateral_rmse", "steps_to_decide", "true_lane_final", "final_true_lane_weight",
         "final_decision", "wrong_lane_confident", "wrong_lane_confident_share",
         "wrong_decision_ever", *_DECISION_COLUMNS),
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
            wrong_lane_ever_runs=(
                "wrong_lane_confident_share",
                lambda v: int(np.sum(pd.to_numeric(v, errors="coerce") > 0)),
            ),
            wrong_decision_runs=(
                "wrong_decision_ever",
                lambda v: int((v == True).sum()),  # noqa: E712 (NaN: a degenerate run)
            ),
            undecided_runs=("final_decision", lambda v: int((v == "undecided").sum())),
            model_mismatch_runs=("final_decision", lambda v: int((v == "model_mismatch").sum())),
            lateral_nees=("lateral_nees", _finite_mean),
            time_to_decide_median=("time_to_decide", lambda v: _censored_quantile(v, 0.5)),
            never_decided_runs=("time_to_decide", _never),
            decided_time_share=("decided_time_share", _finite_mean),
            steering_off_share=("steering_off_share", _finite_mean),
            steering_live_share=("steering_live_share", _finite_mean),
            lateral_rmse_after_decision=("lateral_rmse_after_decision", _finite_mean),
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


RANKED_KINDS = ("builtin", "user", "baseline")
"""The kinds of models ranked against each other: every steering model and estimator but the
stress models and the estimators without the evidence checks (diagnostics, not candidates)."""


def same_seed(seeds: pd.Series, seed: Any) -> pd.Series:
    """Rows of ``seeds`` equal to ``seed``; ``None`` (recordings: no population seed) and NaN
    are one seed."""
    if seed is None or (isinstance(seed, float) and math.isnan(seed)):
        return seeds.isna()
    return seeds.astype(object) == seed


_SAFETY_COUNTS = ("wrong_lane_confident_runs", "wrong_lane_ever_runs", "wrong_decision_runs",
                  "undecided_runs", "model_mismatch_runs", "never_decided_runs")  # fmt: skip
_DECISION_MEANS = ("decided_time_share", "lateral_rmse_after_decision", "steering_off_share",
                   "steering_live_share")  # fmt: skip


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
            ss = s[same_seed(s["seed"], seed) & (s["model"] == name)] if len(s) else s
            ee = e[same_seed(e["seed"], seed) & (e["model"] == name)] if len(e) else e
            cc = c[same_seed(c["seed"], seed) & (c["model"] == name)] if len(c) else c
            if not len(ss) and not len(ee):
                continue
            row: dict[str, Any] = {
                "seed": seed,
                "model": name,
                "kind": _kind(name, kinds),
                "drivers": int((ss if len(ss) else ee)["driver"].nunique()),
                "rmse": _finite_mean(ss["rmse"]) if len(ss) else None,
                "r2_increments": _finite_mean(ss["r2_increments"]) if len(ss) else None,
                "road_information": _finite_mean(ss["road_information"]) if len(ss) else None,
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
                **{key: _finite_mean(ee[key]) if len(ee) else None for key in _DECISION_MEANS},
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
        ranked = table[table["kind"].isin(RANKED_KINDS) & table[key].notna()]
        ranks = ranked.groupby("seed", dropna=False)[key].rank(method="min")
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


_VERDICT_KEYS = {
    "rmse": ("steering", "rmse", False),
    "r2_increments": ("steering", "r2_increments", False),
    "road_information": ("steering", "road_information", False),
    "rmse_decrease_vs_two_point": ("steering", "rmse_decrease_vs_two_point", False),
    "lateral_rmse": ("estimation", "lateral_rmse_mean", False),
    "rmse_over_paper_median": ("steering", "rmse_over_paper", True),
    "curved_lateral_rmse": ("curved_estimation", "lateral_rmse_mean", False),
    "lateral_nees": ("estimation", "lateral_nees", False),
    "decided_time_share": ("estimation", "decided_time_share", False),
    "steering_off_share": ("estimation", "steering_off_share", False),
    "steering_live_share": ("estimation", "steering_live_share", False),
    "lateral_rmse_after_decision": ("estimation", "lateral_rmse_after_decision", False),
}
"""Verdict key -> (per-driver table, its column, the per-seed statistic is the median over
drivers) of the bootstrap; the point estimate is the mean of the per-seed summary's key."""

_COUNTS = ("decided_runs", "estimated_runs", "white_runs", "free_run_diverged", "degenerate_runs",
           "curved_estimated_runs", *_SAFETY_COUNTS, *(f"curved_{k}" for k in _SAFETY_COUNTS))  # fmt: skip
_SHARES = {
    "decided_runs": "estimated_runs",
    **{key: "estimated_runs" for key in _SAFETY_COUNTS},
    **{f"curved_{key}": "curved_estimated_runs" for key in _SAFETY_COUNTS},
}
"""Count -> its number of runs: ``{count}_share`` with its Clopper-Pearson interval."""


def _verdict_row(name: str, part: pd.DataFrame, kind: str) -> dict[str, Any]:
    """One model's verdict row without intervals and ranks: means over seeds, sums of counts,
    the shares of runs counted with their exact binomial intervals."""
    row: dict[str, Any] = {
        "model": name,
        "kind": kind,
        "seeds": int(part["seed"].nunique(dropna=False)),
        "drivers": int(part["drivers"].max()),
        "runs": int(part["runs"].sum()),
    }
    for key in _VERDICT_KEYS:
        row[key] = _finite_mean(part[key]) if key in part else float("nan")
    for key in _COUNTS:
        values = pd.to_numeric(part[key], errors="coerce") if key in part else pd.Series()
        row[key] = int(values.sum()) if values.notna().any() else None
    for key, total in _SHARES.items():
        count, runs = row.get(key), row.get(total)
        share, low, high = None, None, None
        if count is not None and runs:
            share = count / runs
            low, high = clopper_pearson(count, runs)
        row |= {f"{key}_share": share, f"{key}_share_ci_low": low, f"{key}_share_ci_high": high}
    return row


def _seed_groups(
    rows: Sequence[dict[str, Any]], seeds: Sequence[Any], column: str, names: Sequence[str]
) -> list[np.ndarray]:
    """Per seed, the ``(drivers, models)`` array of ``column`` (NaN where a model has no row;
    a table without drivers is one driver per seed: the per-seed summary)."""
    frame = pd.DataFrame(list(rows))
    groups = []
    for seed in seeds:
        part = frame[same_seed(frame["seed"], seed)] if len(frame) else frame
        if not len(part) or column not in part:
            groups.append(np.full((1, len(names)), np.nan))
            continue
        part = part.assign(_value=pd.to_numeric(part[column], errors="coerce"))
        if "driver" not in part:
            part = part.assign(driver="")
        wide = part.pivot_table(
            index="driver", columns="model", values="_value", aggfunc="mean", dropna=False
        )
        groups.append(wide.reindex(columns=list(names)).to_numpy(dtype=np.float64))
    return groups


def _rank_stability(table: pd.DataFrame, key: str, rank_key: str, replicates: np.ndarray) -> None:
    """``rank_key`` (the overall rank of the mean among every ranked model), ``rank_key_models``
    (how many) and ``rank_key_stability`` (the share of bootstrap replicates on which the model
    holds that rank among all of them), in ``table`` (rows in the replicates' column order)."""
    table[rank_key] = None
    table[f"{rank_key}_models"] = None
    table[f"{rank_key}_stability"] = None
    ranked = table["kind"].isin(RANKED_KINDS).to_numpy() & table[key].notna().to_numpy()
    if not ranked.any():
        return
    index = table.index[ranked]
    overall = table.loc[index, key].astype(float).rank(method="min").astype(int)
    table.loc[index, rank_key] = overall
    table.loc[index, f"{rank_key}_models"] = int(ranked.sum())
    ranks = replicate_ranks(replicates[:, ranked])
    table.loc[index, f"{rank_key}_stability"] = np.mean(
        ranks == overall.to_numpy()[None, :], axis=0
    )


def _decision_times(table: pd.DataFrame, runs: Sequence[dict[str, Any]]) -> None:
    """``time_to_decide_median`` / ``_p90`` (s) per model in ``table``: quantiles over its
    runs (degenerate ones left out), a run that never decided counting as an infinite time
    (None when the quantile is such a run; ``never_decided_runs`` counts them)."""
    frame = pd.DataFrame(list(runs))
    for q, key in ((0.5, "time_to_decide_median"), (0.9, "time_to_decide_p90")):
        table[key] = None
        if not len(frame) or "time_to_decide" not in frame:
            continue
        kept = frame["lateral_rmse"].apply(lambda v: v is not None and math.isfinite(float(v)))
        if "degenerate" in frame:
            kept &= frame["degenerate"].isna()
        times = pd.to_numeric(frame["time_to_decide"], errors="coerce").fillna(np.inf)
        for i, name in table["model"].items():
            mine = times[kept & (frame["model"] == name)]
            table.at[i, key] = _censored_quantile(mine, q) if len(mine) else None


def verdict(
    seed_rows: Sequence[dict[str, Any]],
    models: Sequence[str],
    kinds: Mapping[str, str] | None = None,
    *,
    steering: Sequence[dict[str, Any]] = (),
    estimation: Sequence[dict[str, Any]] = (),
    curved_estimation: Sequence[dict[str, Any]] = (),
    runs_estimation: Sequence[dict[str, Any]] = (),
) -> list[dict[str, Any]]:
    """Per model over seeds: means with 95 % intervals, ranks among every ranked model and
    their stability, counts, shares of runs with exact intervals (the module docstring).

    Args:
        seed_rows: :func:`summarize_seeds`' rows (the point estimates).
        models, kinds: the scored models (the baselines are added) and their kinds.
        steering, estimation, curved_estimation: the per (seed, driver, model) rows the
            bootstrap resamples; without any, it resamples the per-seed values only.
        runs_estimation: the per-run estimation rows of the main track: the quantiles of
            the time to decide (:func:`_decision_times`).
    """
    frame = pd.DataFrame(list(seed_rows))
    if not len(frame):
        return []
    names = [n for n in [*models, *(b for b in BASELINES if b not in models)]
             if (frame["model"] == n).any()]  # fmt: skip
    table = pd.DataFrame(
        [_verdict_row(n, frame[frame["model"] == n], _kind(n, kinds)) for n in names]
    )
    seeds = list(dict.fromkeys(frame["seed"]))
    by_driver = {"steering": steering, "estimation": estimation,
                 "curved_estimation": curved_estimation}  # fmt: skip
    driver_level = any(by_driver.values())
    replicates: dict[str, np.ndarray] = {}
    for key, (source, column, median) in _VERDICT_KEYS.items():
        rows, col = (by_driver[source], column) if driver_level else (seed_rows, key)
        groups = _seed_groups(rows, seeds, col, names)
        replicates[key] = hierarchical_bootstrap(groups, median=median and driver_level)
        low, high = percentile_interval(replicates[key])
        enough = sum(np.isfinite(g).sum(axis=0) for g in groups) >= 2  # something to resample
        table[f"{key}_ci_low"] = np.where(enough, low, np.nan)
        table[f"{key}_ci_high"] = np.where(enough, high, np.nan)
    for key, rank_key in (("rmse", "rank_steering"), ("lateral_rmse", "rank_lateral")):
        _rank_stability(table, key, rank_key, replicates[key])
    source, column, _ = _VERDICT_KEYS["lateral_rmse"]
    rows, col = (by_driver[source], column) if driver_level else (seed_rows, "lateral_rmse")
    table = table.assign(**steering_free_gain(_seed_groups(rows, seeds, col, names), names))
    _decision_times(table, runs_estimation)
    lane_calibration(table, runs_estimation)
    return _records(table)
