"""The protocol's tasks: score every model and estimator on a batch of runs, in any process.

Why this module is long: a task is the unit of work of the benchmark, and what it computes
once for all its models and filters (:class:`_Stacks`: stacked recordings, shared filter
passes, steering features; docs/design.md §9.5.5) sits next to the scoring that uses it, so
that the sharing and the equality it relies on are read in one place.
"""

from __future__ import annotations

import copy
import json
import math
import time
import warnings
from collections import defaultdict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.protocol.config import STEERING_BASELINE, UNCHECKED_SUFFIX
from benchmarks.protocol.models import (
    FittedModel,
    ModelError,
    describe,
    private_copy,
    run_isolated,
)
from benchmarks.protocol.plan import RunRef, load_frames
from estimators.baselines import NoSteeringEKF, OracleEKF
from estimators.calibration import (
    STEERING_CHANNEL_STATES,
    lane_calibration_bins,
    steering_channel_shares,
)
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.lane_centring import LaneCentringEKF, LaneCentringParams
from estimators.offline import (
    EstimationResult,
    StackedRecordings,
    pass_key,
    run_estimator,
    stack_recordings,
)
from estimators.settings import FilterSettings
from estimators.trust import trusted_filter
from hasa_env.steering import (
    residual_diagnostics,
    road_information,
    score_features,
    score_runs,
)
from hasa_env.steering.base import SteeringModel

__all__ = [
    "STANDSTILL_SPEED",
    "STEADY_STEERING_STD",
    "ChunkResult",
    "ChunkTask",
    "degenerate_reason",
    "model_estimator",
    "run_chunk",
]

STEADY_STEERING_STD = 1e-6
"""Steering std (rad) below which a run is degenerate: R^2 divides by the steering's
variance, so a run that hardly steers gives numbers like R^2 = -2e27 that would swamp
any mean. 1e-6 rad is far below the resolution of any steering sensor (a G29 step is
about 1.6e-5 rad at the road wheel)."""

STANDSTILL_SPEED = 1.0
"""Median speed (m/s) below which a run is degenerate: a car that stands does not keep a
lane, and the steering models' bearings describe driving (a standing synthetic run
scores R^2 of the increments near -2e4)."""

MIN_SCORED_SAMPLES = 3
"""Fewest samples a run needs to be scored (fewer: degenerate)."""


def degenerate_reason(frame: pd.DataFrame) -> str | None:
    """Why a run cannot be scored fairly (the same for every model), or None.

    Degenerate runs are reported (their rows carry the reason in ``degenerate``)
    and left out of every mean, for every model alike.
    """
    steering = frame["steering"].to_numpy(dtype=np.float64)
    speed = frame["speed"].to_numpy(dtype=np.float64)
    if len(frame) < MIN_SCORED_SAMPLES + 1:
        return f"too short to score ({len(frame) - 1} steps)"
    spread = float(np.std(steering))
    if not spread >= STEADY_STEERING_STD:
        return f"the steering barely varies (std {spread:.2g} rad < {STEADY_STEERING_STD:g} rad)"
    median = float(np.median(speed))
    if not median >= STANDSTILL_SPEED:
        return f"the car stands (median speed {median:.2g} m/s < {STANDSTILL_SPEED:g} m/s)"
    return None


@dataclass(frozen=True)
class ChunkTask:
    """The work of one task: a batch of runs of one population seed (on either track: each
    run names its own)."""

    seed: int | None
    runs: tuple[RunRef, ...]
    env_config: Mapping[str, Any]
    driver_params: Mapping[str, Any]
    models: tuple[FittedModel, ...]
    estimate: bool
    ljung_box_lags: int
    acf_lags: int
    weight_threshold: float
    error_window: float
    trace_runs: frozenset[tuple[int | None, str, str, int]]
    detail_driver: str
    compare_checks: bool = False
    filter_settings: Mapping[str, Any] = field(default_factory=dict)
    time_limit: float | None = None
    """Time limit (s) of scoring this batch with one user model, isolated (None: in-process)."""
    lane_centring: LaneCentringParams | None = None
    """The lane-centring prior fitted on the training run (None: that baseline is not run)."""


@dataclass
class ChunkResult:
    """What a task returns: per-run rows, model failures, plot data."""

    steering: list[dict[str, Any]] = field(default_factory=list)
    estimation: list[dict[str, Any]] = field(default_factory=list)
    failures: list[ModelError] = field(default_factory=list)
    traces: dict[tuple[int | None, str, str, int], dict[str, Any]] = field(default_factory=dict)
    early_errors: dict[str, list[np.ndarray]] = field(default_factory=dict)
    acf: dict[str, list[np.ndarray]] = field(default_factory=dict)
    seconds: float = 0.0


def run_chunk(task: ChunkTask) -> ChunkResult:
    """Score every model on a batch of runs (one task; runs in any process).

    Per run and model: steering scores (and, for the illustrative driver,
    residual autocorrelations); per run and estimator (main track only):
    lateral RMSE, steps to decide the lane, and the first seconds of lateral
    error. A user model scores its own copy of the runs, isolated
    (:func:`benchmarks.protocol.isolation.run_isolated`, with ``task.time_limit``);
    one that fails is reported in ``failures``.
    """
    start = time.process_time()
    frames = _task_frames(task)
    out = ChunkResult()
    predictions: dict[str, dict[int, np.ndarray]] = {}
    residuals: dict[str, list[np.ndarray]] = {}
    stacks = _Stacks(frames)  # each settings group's recordings stacked once, for every filter
    for fm in task.models:
        if fm.kind != "user":  # the project's own models run in-process
            try:
                part, traced, residuals[fm.name] = _model_part(fm, task, frames, stacks)
            except ModelError as exc:
                raise RuntimeError(str(exc)) from None
        else:
            try:
                part, traced, residuals[fm.name] = run_isolated(
                    _user_model_part, (fm, task, frames), model=fm.name, stage="score",
                    time_limit=task.time_limit,
                )  # fmt: skip
            except ModelError as exc:
                out.failures.append(exc)
                continue
        _merge(out, part)
        predictions[fm.name] = traced
    _add_road_information(out.steering, residuals, task.runs)
    for i, (ref, frame) in enumerate(zip(task.runs, frames, strict=True)):
        if ref.key in task.trace_runs:
            trace = out.traces.setdefault(ref.key, {})
            trace["time"] = frame["time"].to_numpy()
            trace["steering"] = frame["steering"].to_numpy()
            trace["predictions"] = {name: preds[i] for name, preds in predictions.items()}
    if task.estimate:
        for name, make in _baseline_estimators(task):
            _estimate_model(task, frames, name, "baseline", make, out, stacks)
    reasons = {
        ref.key: degenerate_reason(frame) for ref, frame in zip(task.runs, frames, strict=True)
    }
    for row in out.steering + out.estimation:
        row["degenerate"] = reasons[(row["seed"], row["driver"], row["track"], row["run"])]
    out.seconds = time.process_time() - start
    return out


def _task_frames(task: ChunkTask) -> list[pd.DataFrame]:
    """The recordings of the task's runs, in their order: each track's runs generated in one
    vector env (or loaded)."""
    frames: list[pd.DataFrame | None] = [None] * len(task.runs)
    tracks = dict.fromkeys(ref.track for ref in task.runs)
    for track in tracks:
        where = [i for i, ref in enumerate(task.runs) if ref.track == track]
        runs = [task.runs[i] for i in where]
        loaded = load_frames(runs, track, task.env_config, task.driver_params)
        for i, frame in zip(where, loaded, strict=True):
            frames[i] = frame
    return [f for f in frames if f is not None]


def _baseline_estimators(task: ChunkTask) -> list[tuple[str, Callable[[Any], Any]]]:
    """The baselines' names and filters (a function of the filter settings), in
    :data:`~benchmarks.protocol.config.BASELINES` order; ``lane_centring`` only with its
    fitted prior."""
    makers: list[tuple[str, Callable[[Any], Any]]] = [("no_steering", NoSteeringEKF)]
    params = task.lane_centring
    if params is not None:
        makers.append(("lane_centring", lambda s: LaneCentringEKF(params, s)))
    makers.append(("oracle", lambda s: OracleEKF(None, s)))
    return makers


def _add_road_information(
    rows: Sequence[dict[str, Any]],
    residuals: Mapping[str, Sequence[np.ndarray]],
    runs: Sequence[RunRef],
) -> None:
    """Each steering row's ``road_information`` (:func:`hasa_env.steering.road_information`:
    1 - SSE / SSE of the road-blind baseline on the run's samples both predicted; None
    without the baseline's residuals)."""
    blind = residuals.get(STEERING_BASELINE)
    index = {ref.key: i for i, ref in enumerate(runs)}
    for row in rows:
        i = index[(row["seed"], row["driver"], row["track"], row["run"])]
        mine = residuals.get(row["model"])
        value = None if blind is None or mine is None else road_information(mine[i], blind[i])
        row["road_information"] = None if value is None or not math.isfinite(value) else value


def _user_model_part(
    fm: FittedModel, task: ChunkTask, frames: Sequence[pd.DataFrame]
) -> tuple[ChunkResult, dict[int, np.ndarray], list[np.ndarray]]:
    """:func:`_model_part` on the model's own copy of the runs (whatever it does to them)."""
    return _model_part(fm, task, [private_copy(frame) for frame in frames])


def _model_part(
    fm: FittedModel,
    task: ChunkTask,
    frames: Sequence[pd.DataFrame],
    stacks: _Stacks | None = None,
) -> tuple[ChunkResult, dict[int, np.ndarray], list[np.ndarray]]:
    """One model on a batch: its steering rows and, on the main track, its estimation rows;
    plus its predictions of the runs whose traces are plotted (by run index) and its one-step
    residuals of every run (rad, aligned with the run's rows: the road information).
    ``stacks``: the batch's stacked recordings, shared with the other filters (None: its
    own)."""
    part = ChunkResult()
    preds, residuals = _score_model(fm, task, frames, part, stacks)
    residual_std = fm.residual_std
    if task.estimate and residual_std is not None:
        make = partial(model_estimator, fm, overrides=task.filter_settings)
        _estimate_model(task, frames, fm.name, fm.kind, make, part, stacks)
        if task.compare_checks:  # the same filter without the evidence checks
            _estimate_model(
                task,
                frames,
                f"{fm.name}{UNCHECKED_SUFFIX}",
                fm.kind,
                partial(make, checks=False),
                part,
                stacks,
            )
    traced = {i: preds[i] for i, ref in enumerate(task.runs) if ref.key in task.trace_runs}
    return part, traced, residuals


def model_estimator(
    fm: FittedModel,
    settings: FilterSettings,
    overrides: Mapping[str, Any] | None = None,
    checks: bool | None = None,
) -> GaussianMixtureEKF:
    """The benchmark's filter for a fitted model: :func:`estimators.trust.trusted_filter` on
    ``settings`` (the runs' config with the protocol's ``filter_settings``, the user's
    ``overrides``) with the model's residual level and training record; ``checks`` False:
    the same filter without the evidence checks and the model's limits (``--compare-checks``);
    None: the settings' own ``evidence_checks``, so a user's ``--filter
    evidence_checks=false`` is honoured (it was overruled before 2026-12-06)."""
    training = replace(fm.training, residual_std=fm.residual_std)
    return trusted_filter(
        fm.model, settings, training=training, overrides=overrides, checks=checks
    ).estimator()


def _merge(out: ChunkResult, part: ChunkResult) -> None:
    out.steering += part.steering
    out.estimation += part.estimation
    for name, values in part.acf.items():
        out.acf.setdefault(name, []).extend(values)
    for name, values in part.early_errors.items():
        out.early_errors.setdefault(name, []).extend(values)
    for key, trace in part.traces.items():
        into = out.traces.setdefault(key, {})
        into.setdefault("estimates", {}).update(trace.get("estimates", {}))
        into.update({k: v for k, v in trace.items() if k != "estimates"})


def _warm_mask(features: pd.DataFrame, model: Any, stacks: _Stacks | None = None) -> np.ndarray:
    """Rows where every feature the model uses is finite at lags 0..max_lag (``stacks``:
    the batch's shared features and their finite rows)."""
    try:
        used = sorted({r.feature for r in model.regressors} | {"delta"})
        lag = int(model.max_lag)
    except Exception:  # noqa: BLE001 - a broken regressors property
        used, lag = list(features.columns), 0
    used = [c for c in used if c in features.columns]
    finite = _finite_rows(features, used) if stacks is None else stacks.finite_rows(features, used)
    if lag > 0:
        window = np.lib.stride_tricks.sliding_window_view(
            np.concatenate([np.zeros(lag, bool), finite]), lag + 1
        )
        return np.asarray(window.all(axis=1))
    return finite


def _finite_rows(features: pd.DataFrame, columns: Sequence[str]) -> np.ndarray:
    """(T,) bool: the rows whose ``columns`` are all finite."""
    return np.all(np.isfinite(features[list(columns)].to_numpy(dtype=np.float64)), axis=1)


def _score_model(
    fm: FittedModel,
    task: ChunkTask,
    frames: Sequence[pd.DataFrame],
    out: ChunkResult,
    stacks: _Stacks | None = None,
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Score one model on every run of a batch (its steering rows go to ``out``); its
    one-step predictions and residuals (measured minus predicted steering, rad) per run.
    ``stacks``: the batch's runs with their steering features, shared with the other
    models (None: the model's own)."""
    model = fm.model
    preds = []
    residuals = []
    for i, (ref, frame) in enumerate(zip(task.runs, frames, strict=True)):
        where = f"driver {ref.driver!r} run {ref.index} ({ref.track})"
        try:
            features = model.features(frame) if stacks is None else stacks.features(model, i)
            prediction = np.asarray(model.predict_features(features), dtype=np.float64)
        except Exception as exc:  # noqa: BLE001
            raise ModelError(fm.name, "predict", f"on {where}: {describe(exc)}") from None
        if prediction.shape != (len(features),):
            raise ModelError(
                fm.name,
                "predict",
                f"on {where}: predict_features returned shape {prediction.shape}, "
                f"expected ({len(features)},)",
            )
        warm = _warm_mask(features, model, stacks)
        bad = warm & ~np.isfinite(prediction)
        if bad.any():
            raise ModelError(
                fm.name,
                "predict",
                f"predicted NaN or inf at {int(bad.sum())} of {int(warm.sum())} samples of "
                f"{where} (first at t = {float(frame['time'].iloc[int(np.argmax(bad))]):.2f} s)",
            )
        # free run (the model's own past steering) for ARX models; a non-ARX model's
        # free run is sample by sample through predict_features: too slow to score here
        free_run = fm.residual_std is not None
        try:
            row = _scores(model, features, prediction, task.ljung_box_lags, free_run)
        except Exception as exc:  # noqa: BLE001
            raise ModelError(fm.name, "predict", f"scoring {where}: {describe(exc)}") from None
        out.steering.append(
            {
                "seed": ref.seed,
                "driver": ref.driver,
                "track": ref.track,
                "run": ref.index,
                "model": fm.name,
                "rmse": float(row["rmse"]),
                "r2": float(row["r2"]),
                "r2_increments": float(row["r2_increments"]),
                "ljung_box_p": float(row["ljung_box_p"]),
                "n": int(row["n"]),
                "free_run_rmse": float(row["free_run_rmse"]) if free_run else None,
                "free_run_diverged": bool(row["free_run_diverged"]) if free_run else None,
                # how the driver drove this run (the same for every model)
                **(_driving(frame) if stacks is None else stacks.driving(i)),
            }
        )
        residual = features["delta"].to_numpy(dtype=np.float64) - prediction
        if task.estimate and ref.driver == task.detail_driver:
            diag = residual_diagnostics(residual[np.isfinite(residual)], lags=task.acf_lags)
            out.acf.setdefault(fm.name, []).append(diag.autocorrelation)
        preds.append(prediction)
        residuals.append(residual)
    return preds, residuals


def _scores(
    model: Any, features: pd.DataFrame, prediction: np.ndarray, lags: int, free_run: bool
) -> Mapping[str, Any] | pd.Series:
    """The model's scores on one run's features (:func:`~hasa_env.steering.score_runs`' row):
    a model that features and predicts as :class:`~hasa_env.steering.base.SteeringModel`
    does is scored with the one-step ``prediction`` made already
    (:func:`~hasa_env.steering.score_features`); any other one as by ``score_runs``."""
    if (
        type(model).features is SteeringModel.features
        and type(model).predict_features is SteeringModel.predict_features
    ):
        return score_features(model, features, lags, free_run, one_step=prediction)
    return score_runs(model, [features], lags=lags, free_run=free_run).iloc[0]


def _filter_key(frame: pd.DataFrame) -> str:
    config = frame.attrs.get("config") or {}
    keep = {
        "noise": config.get("noise"),
        "hypotheses": (config.get("markings") or {}).get("hypotheses"),
        "rate": (config.get("sim_frequency"), config.get("action_repeat")),
    }
    return json.dumps(keep, sort_keys=True, default=str)


def _settle_steps(true_weight: np.ndarray, valid: np.ndarray, threshold: float) -> np.ndarray:
    """(R,) first step from which the true-lane weight stays above ``threshold`` (NaN: never)."""
    above = (true_weight > threshold) | ~valid
    # last step that is below the threshold; settled from the next one on
    below = ~above
    any_below = below.any(axis=1)
    last_below = np.where(any_below, below.shape[1] - 1 - np.argmax(below[:, ::-1], axis=1), -1)
    steps = (last_below + 1).astype(np.float64)
    lengths = valid.sum(axis=1)
    steps[steps >= lengths] = np.nan
    return steps


def _decision_metrics(
    true_weight: np.ndarray,
    valid: np.ndarray,
    time: np.ndarray,
    error: np.ndarray,
    threshold: float,
) -> dict[str, np.ndarray]:
    """(R,) decision metrics of each run:

    - ``time_to_decide`` (s): ``t(k*) - t(0)`` with ``k*`` the first step at which the true
      lane's weight exceeds ``threshold`` (NaN: never);
    - ``decided_time_share``: the share of the run's steps with that weight above ``threshold``;
    - ``lateral_rmse_after_decision`` (m): ``sqrt(mean_{k >= k_s} e(k)^2)`` from the step
      ``k_s`` from which the weight stays above ``threshold`` (:func:`_settle_steps`; NaN:
      never settled).
    """
    above = (true_weight > threshold) & valid
    ever = above.any(axis=1)
    first = np.argmax(above, axis=1)
    rows = np.arange(len(valid))
    time_to_decide = np.where(ever, time[rows, first] - time[:, 0], np.nan)
    share = above.sum(axis=1) / np.maximum(valid.sum(axis=1), 1)
    settle = _settle_steps(true_weight, valid, threshold)
    after = valid & (
        np.arange(valid.shape[1])[None, :] >= np.nan_to_num(settle, nan=np.inf)[:, None]
    )
    squared = np.where(after & np.isfinite(error), error * error, 0.0)
    counts = (after & np.isfinite(error)).sum(axis=1)
    rmse_after = np.where(counts > 0, np.sqrt(squared.sum(axis=1) / np.maximum(counts, 1)), np.nan)
    return {
        "time_to_decide": time_to_decide,
        "decided_time_share": share,
        "lateral_rmse_after_decision": rmse_after,
    }


def _driving(frame: pd.DataFrame) -> dict[str, Any]:
    """How the driver drove a run (the same for every model): the standard deviation of the
    lateral position ``sdlp`` (m), its largest ``|offset|`` (m) and whether it left the road."""
    lateral = frame["lateral_offset"].to_numpy(dtype=np.float64)
    return {
        "sdlp": float(np.std(lateral)),
        "max_abs_lateral_offset": float(np.max(np.abs(lateral))),
        "left_road": bool(frame["terminated"].to_numpy(dtype=bool).any()),
    }


class _Stacks:
    """A batch's runs in groups that share the filter's settings (:func:`_filter_key`), each
    group's recordings stacked once (:func:`~estimators.offline.stack_recordings`) for every
    filter of the batch: about 0.2 s of CPU per filter pass of 97 runs (the padded arrays
    and the curved runs' road points).

    And each distinct pass done once (:meth:`run`): the filters with the same
    :func:`~estimators.offline.pass_key` on the same group give the same result to the bit
    (with ``--stress``, the no-steering filters of the three or four stress models the trust
    rule refuses and the no-steering baseline: four or five passes of about 1.6 s of CPU each
    on 97 runs, one done)."""

    def __init__(self, frames: Sequence[pd.DataFrame]) -> None:
        self.frames = frames
        self.groups: dict[str, list[int]] = defaultdict(list)
        for i, frame in enumerate(frames):
            self.groups[_filter_key(frame)].append(i)
        self._stacked: dict[tuple[int, ...], StackedRecordings] = {}
        self._results: dict[tuple[Any, ...], EstimationResult] = {}
        self._features: dict[tuple[Any, ...], pd.DataFrame] = {}
        self._held: dict[int, tuple[Any, ...]] = {}  # id of a kept features frame -> its key
        self._finite: dict[tuple[Any, ...], np.ndarray] = {}
        self._driving: dict[int, dict[str, Any]] = {}

    def stacked(self, indices: Sequence[int]) -> StackedRecordings:
        key = tuple(indices)
        if key not in self._stacked:
            self._stacked[key] = stack_recordings([self.frames[i] for i in indices])
        return self._stacked[key]

    def features(self, model: Any, index: int) -> pd.DataFrame:
        """``model.features`` of run ``index``: the steering features
        (:func:`~hasa_env.steering.features.steering_features`) computed once per run and
        feature settings (look-ahead distances, decision lag, steering signal) for every
        model that takes them as :class:`~hasa_env.steering.base.SteeringModel` does (the
        same frame, checked against the model as a frame of features is); any other model
        makes its own."""
        frame = self.frames[index]
        if type(model).features is not SteeringModel.features:
            return model.features(frame)
        key = (index, float(model.near_distance), float(model.far_distance),
               int(model.decision_lag), str(model.steering_signal))  # fmt: skip
        kept = self._features.get(key)
        if kept is None:
            kept = self._features[key] = model.features(frame)
            self._held[id(kept)] = key
            return kept
        return model.features(kept)

    def finite_rows(self, features: pd.DataFrame, columns: Sequence[str]) -> np.ndarray:
        """:func:`_finite_rows` (read-only), once per kept features frame (:meth:`features`)
        and columns; of any other frame computed each time."""
        key = self._held.get(id(features))  # a kept frame lives as long as this object
        if key is None:
            return _finite_rows(features, columns)
        key = (*key, *columns)
        if key not in self._finite:
            self._finite[key] = _finite_rows(features, columns)
            self._finite[key].setflags(write=False)
        return self._finite[key]

    def driving(self, index: int) -> dict[str, Any]:
        """:func:`_driving` of run ``index``, computed once (a copy for each row)."""
        if index not in self._driving:
            self._driving[index] = _driving(self.frames[index])
        return dict(self._driving[index])

    def run(self, estimator: Any, indices: Sequence[int]) -> EstimationResult:
        """:func:`~estimators.offline.run_estimator` of ``estimator`` on the group of runs
        ``indices``; a pass with the same key as an earlier one is that pass' result,
        copied (each caller owns its result, whatever it does to it)."""
        estimator_key = pass_key(estimator)
        if estimator_key is None:
            return run_estimator(estimator, self.stacked(indices))
        key = (tuple(indices), estimator_key)
        kept = self._results.get(key)
        if kept is None:
            result = run_estimator(estimator, self.stacked(indices))
            self._results[key] = copy.deepcopy(result)
            return result
        return copy.deepcopy(kept)


def _estimate_model(
    task: ChunkTask,
    frames: Sequence[pd.DataFrame],
    name: str,
    kind: str,
    make: Callable[[Any], Any],
    out: ChunkResult,
    stacks: _Stacks | None = None,
) -> None:
    """Run one estimator (``make(settings)``) over the batch, in groups of runs that share
    the filter's settings; its rows go to ``out``. A user model's filter that raises or
    loses its estimate is its ModelError. ``stacks``: the groups' stacked recordings, shared
    with the batch's other filters (None: stacked for this one)."""
    stacks = stacks if stacks is not None else _Stacks(frames)
    rows: list[dict[str, Any]] = []
    scratch = ChunkResult()  # its early errors and traces, kept only if the estimator works
    try:
        for indices in stacks.groups.values():
            group = [frames[i] for i in indices]
            settings = FilterSettings.from_env_config(
                group[0].attrs["config"], **task.filter_settings
            )
            estimator = make(settings)
            result = stacks.run(estimator, indices)
            refused = kind != "baseline" and isinstance(estimator, NoSteeringEKF)
            rows += _estimation_rows(task, indices, result, name, scratch, kind, refused)
    except ModelError:
        raise
    except Exception as exc:  # noqa: BLE001
        if kind not in ("user", "stress"):
            raise
        raise ModelError(name, "estimate", f"the filter raised {describe(exc)}") from None
    bad = [r for r in rows if not math.isfinite(r["lateral_rmse"])]
    if bad and kind in ("user", "stress"):
        raise ModelError(
            name,
            "estimate",
            f"the filter's lateral estimate became NaN or inf on {len(bad)} run(s), "
            f"e.g. driver {bad[0]['driver']!r} run {bad[0]['run']}",
        )
    out.estimation += rows
    _merge(out, scratch)


def _channel_diagnostics(result: Any, kind: str, refused: bool = False) -> dict[str, np.ndarray]:
    """(R,) per-run diagnostics of the steering channel, in the rows' order: the share of
    the steps it was off (NaN: no such rule), the share it was live
    (:func:`estimators.calibration.steering_live_share`; NaN for a steering-free
    baseline) and why it was not (``steering_<state>_share`` of
    :func:`estimators.calibration.steering_channel_shares`), the median model-error ratio lambda and evidence scale tau (over the steps
    it was on), and the mean NIS of each channel. ``refused``: a steering model the trust
    rule gave no lane evidence at all, filtered by the no-steering estimator under its own
    name, whose channel is off at every valid step (``steering_channel_shares``'s)."""
    n_runs = result.num_runs
    nan = np.full(n_runs, np.nan)
    shares = steering_channel_shares(result, refused=refused)
    off = result.valid if refused else result.low_speed
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a run without steering data: NaN
        model_error = np.nanmedian(result.model_error, axis=1)
        scale = result.evidence_scale
        if scale is not None and off is not None:
            scale = np.where(off, np.nan, scale)
        scale = nan if scale is None else np.nanmedian(scale, axis=1)
    nis = (
        result.mean_channel_nis()
        if result.channel_nis is not None
        else np.full((n_runs, 3), np.nan)
    )
    return {
        "steering_off_share": nan
        if off is None
        else (off & result.valid).sum(axis=1) / result.lengths,
        "steering_live_share": nan if kind == "baseline" else shares["live"],
        **{
            f"steering_{name}_share": nan if kind == "baseline" else shares[name]
            for name in STEERING_CHANNEL_STATES[2:]
        },
        "model_error_median": model_error,
        "evidence_scale_median": scale,
        "nis_speed": nis[:, 0],
        "nis_camera": nis[:, 1],
        "nis_steering": nis[:, 2],
    }


def _estimation_rows(
    task: ChunkTask,
    indices: Sequence[int],
    result: Any,
    name: str,
    out: ChunkResult,
    kind: str = "builtin",
    refused: bool = False,
) -> list[dict[str, Any]]:
    refs = [task.runs[i] for i in indices]
    error = result.lateral_error()
    rmse = np.sqrt(np.nanmean(error * error, axis=1))
    bias0 = result.truth["bias"][:, 0]
    true_weight = result.true_lane_weight()  # (R, T): weight of the hypotheses equal to the bias
    steps = _settle_steps(true_weight, result.valid, task.weight_threshold)
    decision = _decision_metrics(
        true_weight, result.valid, result.time, error, task.weight_threshold
    )
    final_true = result.picked_true_lane()
    last = result.lengths - 1
    final_weight = true_weight[np.arange(len(refs)), last]
    final_decision = result.final_decision()
    refused_by = result.refusal_reasons()
    wrong_confident = result.wrong_lane_confident(task.weight_threshold)
    wrong_share = result.wrong_lane_confident_share(task.weight_threshold)
    wrong_decision = result.wrong_decision_ever(task.weight_threshold)
    nees = result.lateral_nees()
    channel = _channel_diagnostics(result, kind, refused)
    calibration = lane_calibration_bins(result)
    n_window = int(round(task.error_window / float(np.nanmedian(np.diff(result.time[0]))))) + 1
    rows = []
    for j, ref in enumerate(refs):
        rows.append(
            {
                "seed": ref.seed,
                "driver": ref.driver,
                "track": ref.track,
                "run": ref.index,
                "model": name,
                "lateral_rmse": float(rmse[j]),
                "steps_to_decide": None if not np.isfinite(steps[j]) else int(steps[j]),
                **{key: float(values[j]) for key, values in decision.items()},
                "true_lane_final": bool(final_true[j]),
                "final_true_lane_weight": float(final_weight[j]),
                "final_decision": str(final_decision[j]),
                "refused_by": str(refused_by[j]),
                "wrong_lane_confident": bool(wrong_confident[j]),
                "wrong_lane_confident_share": float(wrong_share[j]),
                "wrong_decision_ever": bool(wrong_decision[j]),
                "lateral_nees": float(nees[j]),
                **{key: float(values[j]) for key, values in channel.items()},
                "calibration_count": calibration[j, 0].astype(int).tolist(),
                "calibration_predicted": calibration[j, 1].round(6).tolist(),
                "calibration_observed": calibration[j, 2].astype(int).tolist(),
                "bias": float(bias0[j]),
            }
        )
        if ref.driver == task.detail_driver:
            out.early_errors.setdefault(name, []).append(error[j, :n_window].copy())
        if ref.key in task.trace_runs:
            trace = out.traces.setdefault(ref.key, {})
            est = trace.setdefault("estimates", {})
            est[name] = {
                "lateral": result.mean[j, : result.lengths[j], 1].copy(),
                "true_weight": true_weight[j, : result.lengths[j]].copy(),
                "hypotheses": result.hypotheses[j].copy(),
            }
            trace["truth_lateral"] = result.truth["lateral_offset"][j, : result.lengths[j]].copy()
            trace["bias"] = float(bias0[j])
    return rows
