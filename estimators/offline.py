"""Run an estimator over recorded runs, many at once.

Why this module is long: :class:`EstimationResult` carries the benchmark's per-run metrics
(lateral error, lane decisions, wrong decisions reported or withheld, NEES, channel NIS) next
to the loop that fills it, so that every consumer reads one definition of each.

:func:`run_estimator` feeds one or many recordings (DataFrames with the
recording columns, :data:`hasa_env.sim.setup.RECORDING_COLUMNS`) to an
estimator as one batch: row 0 resets it, row k steps it with row k's
measurements and IMU. Runs of different lengths are padded (their padded
steps are marked invalid). Each recording's row spacing must be the
estimator's sample time (:func:`estimators.timing.check_sample_time`); on a
curved track the estimator gets the road ahead of each row's ``station``
(:func:`estimators.road_geometry.lane_points_ahead`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol, cast, runtime_checkable

import numpy as np
import pandas as pd

from estimators.arx_state_space import PHYSICAL_STATE_NAMES, check_road_points
from estimators.base import ACCELERATION_KEYS, MEASUREMENT_KEYS, Estimate, LaneEstimator
from estimators.baselines import NoSteeringEKF
from estimators.evidence import DECISIONS, refusal_reasons
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.mixture_trace import MixtureTrace
from estimators.road_geometry import lane_points_ahead, look_ahead_distances, straight_road_points
from estimators.settings import FilterSettings
from estimators.timing import check_sample_time, recording_sample_time
from estimators.trust import TrainingRecord, TrustedFilter, trusted_filter
from estimators.tuning import speed_scaled_gain, steering_residual_std, whitened_residual_std
from hasa_env.recording.format import Recording
from hasa_env.sim.road import Road
from hasa_env.steering.design import SteeringModelLike
from hasa_env.steering.features import road_of_frame

__all__ = [
    "EstimationResult",
    "EstimatorRun",
    "TRUTH_COLUMNS",
    "estimate_recording",
    "hypotheses_of",
    "recording_filter",
    "run_estimator",
    "pass_key",
    "stack_recordings",
    "StackedRecordings",
]

TRUTH_COLUMNS = ("longitudinal_velocity", "lateral_offset", "lateral_velocity", "bias")
"""Recording columns holding the true value of each physical state, in state order."""

DEFAULT_HYPOTHESES = (0.0, -1.8)


def hypotheses_of(frame: pd.DataFrame) -> tuple[float, ...]:
    """The lane hypotheses of a recording: its config's ``markings.hypotheses``
    (``frame.attrs["config"]``, set by the drivers' runner and the recording
    loader), else the env default (0, -1.8)."""
    config = frame.attrs.get("config") if hasattr(frame, "attrs") else None
    if config is None:
        return DEFAULT_HYPOTHESES
    try:
        return tuple(float(h) for h in config["markings"]["hypotheses"])
    except (TypeError, KeyError):
        return DEFAULT_HYPOTHESES


@dataclass(frozen=True, eq=False)
class EstimationResult:
    """Per-step estimates of R runs over T steps (padded runs: ``valid`` False).

    Attributes:
        state_names: names of the n states.
        hypotheses: (R, C) lane hypotheses b_i (m).
        time: (R, T) time (s) of each step (NaN where invalid).
        valid: (R, T) True for steps of the recording.
        lengths: (R,) number of rows of each recording.
        mean: (R, T, n) mixture mean.
        std: (R, T, n) mixture standard deviation (square root of the
            covariance's diagonal).
        weights: (R, T, C) hypothesis weights.
        most_likely: (R, T) index of the most probable hypothesis.
        truth: {column: (R, T)} true values from the recordings
            (``TRUTH_COLUMNS`` and ``bias_index`` where present; NaN/-1 when padded).
        component_means: (R, T, C, n) per-hypothesis means, when requested.
        gated: (R, T, 3) channels [speed, camera, steering] the estimator's
            outlier gate rejected at each step (None if it has no gate).
        low_speed: (R, T) steps with the steering channel off below the
            estimator's ``min_speed`` or on a road ahead more curved than its
            ``steering_curvature_limit`` (None if it has no such mode).
        decision: (R, T) decision state codes (:data:`estimators.evidence.DECISIONS`:
            0 undecided, 1 decided, 2 model_mismatch; -1 where invalid).
        model_error: (R, T) the statistic behind ``model_mismatch``
            (:attr:`estimators.base.Estimate.model_error`).
        evidence_scale: (R, T) the factor tau (>= 1) the steering evidence was divided by
            (:attr:`estimators.base.Estimate.evidence_scale`; 1 for estimators without one).
        channel_nis: (R, T, 3) normalized innovation squared of each channel
            [speed, camera, steering] (:attr:`GaussianMixtureEKF.channel_nis`;
            None if the estimator has none; NaN where not used).
        withheld: (R,) the hypothesis index of the decision the reversal rule withheld
            (:attr:`GaussianMixtureEKF.withheld_decisions`; -1: none; None if the
            estimator has no such rule).
        refused_by: (R,) what sent each run back to its prior for good
            (:attr:`GaussianMixtureEKF.refusal_codes`, codes of
            :data:`estimators.evidence.REFUSALS`; None if the estimator has no such rule).
    """

    state_names: tuple[str, ...]
    hypotheses: np.ndarray
    time: np.ndarray
    valid: np.ndarray
    lengths: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    weights: np.ndarray
    most_likely: np.ndarray
    truth: dict[str, np.ndarray] = field(default_factory=dict)
    component_means: np.ndarray | None = None
    gated: np.ndarray | None = None
    low_speed: np.ndarray | None = None
    decision: np.ndarray | None = None
    model_error: np.ndarray | None = None
    channel_nis: np.ndarray | None = None
    evidence_scale: np.ndarray | None = None
    withheld: np.ndarray | None = None
    refused_by: np.ndarray | None = None

    @property
    def num_runs(self) -> int:
        return self.mean.shape[0]

    def lateral_error(self) -> np.ndarray:
        """(R, T) mixture lateral-offset estimate minus the truth (m); NaN where invalid."""
        if "lateral_offset" not in self.truth:
            raise ValueError("the recordings had no lateral_offset column (no truth)")
        err = self.mean[..., 1] - self.truth["lateral_offset"]
        return np.where(self.valid, err, np.nan)

    def lateral_rmse(self, start: int = 0) -> np.ndarray:
        """(R,) root-mean-square lateral error of each run (m), over steps >= ``start``."""
        err = self.lateral_error()[:, start:]
        return np.sqrt(np.nanmean(err * err, axis=1))

    def true_lane_mask(self) -> np.ndarray:
        """(R, C) mask of the hypotheses equal to each run's true bias."""
        bias = self.truth.get("bias")
        if bias is None:
            raise ValueError("the recordings had no bias column (no truth)")
        return np.isclose(self.hypotheses, bias[:, :1], rtol=0.0, atol=1e-9)

    def true_lane_weight(self) -> np.ndarray:
        """(R, T) total weight of the hypotheses equal to the true bias."""
        return np.einsum("rtc,rc->rt", self.weights, self.true_lane_mask().astype(np.float64))

    def picked_true_lane(self, at: int = -1) -> np.ndarray:
        """(R,) whether the true lane is the most likely at step ``at`` (default: each run's
        last valid step): the weight of the hypotheses with the true bias above every other
        hypothesis' weight. A tie is not the true lane: a run refused back to a uniform prior
        (0.5 / 0.5) did not pick it, whichever index the true lane has."""
        steps = self.lengths - 1 if at == -1 else np.minimum(at, self.lengths - 1)
        rows = np.arange(self.num_runs)
        weights = self.weights[rows, steps]  # (R, C)
        truth = self.true_lane_mask()
        true_weight = np.where(truth, weights, 0.0).sum(axis=1)
        other = np.where(truth, -np.inf, weights).max(axis=1)
        return true_weight > other

    def final_decision(self) -> np.ndarray:
        """(R,) decision state name at each run's last valid step."""
        if self.decision is None:
            raise ValueError("the estimator reported no decision state")
        rows = np.arange(self.num_runs)
        return np.asarray(DECISIONS)[self.decision[rows, self.lengths - 1]]

    def refusal_reasons(self) -> np.ndarray:
        """(R,) why each run that ends in ``model_mismatch`` does: ``"path rule"`` (the car
        left every hypothesis' centre), ``"reversal rule"`` (a decision was contradicted) or
        ``"mismatch test"`` (the model does not fit the steering now; :mod:`estimators.evidence`);
        ``""`` for the runs that end otherwise."""
        return refusal_reasons(self.final_decision(), self.refused_by)

    def wrong_lane_confident(self, threshold: float = 0.95) -> np.ndarray:
        """(R,) runs that end with more than ``threshold`` weight on a single wrong lane."""
        rows = np.arange(self.num_runs)
        final = self.weights[rows, self.lengths - 1]  # (R, C)
        wrong = np.where(self.true_lane_mask(), 0.0, final)
        return wrong.max(axis=1) > threshold

    def wrong_lane_confident_share(self, threshold: float = 0.95) -> np.ndarray:
        """(R,) share of each run's valid steps with more than ``threshold`` on a wrong lane."""
        wrong = np.where(self.true_lane_mask()[:, None, :], 0.0, self.weights).max(axis=2)
        return ((wrong > threshold) & self.valid).sum(axis=1) / self.lengths

    def wrong_decision_ever(self, threshold: float = 0.95) -> np.ndarray:
        """(R,) runs that decided a wrong lane at some step: more than ``threshold`` weight
        on a wrong lane at a reported step, or a decision for a wrong lane that the reversal
        rule withheld (``withheld``; the filter's weights passed its own decision threshold
        there before going back to the prior, so the reported weights never show it)."""
        ever = self.wrong_lane_confident_share(threshold) > 0
        if self.withheld is None:
            return ever
        rows = np.arange(self.num_runs)
        index = np.maximum(self.withheld, 0)
        withheld_wrong = (self.withheld >= 0) & ~self.true_lane_mask()[rows, index]
        return ever | withheld_wrong

    def lateral_nees(self, start: int = 0) -> np.ndarray:
        """(R,) mean normalized estimation error squared of the lateral offset,
        ``mean_k (y_hat - y)^2 / sigma_y^2`` over valid steps >= ``start`` (1: the reported
        std is right on average; much more: overconfident)."""
        err = self.lateral_error()[:, start:]
        var = self.std[:, start:, 1] ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.nanmean(err * err / var, axis=1)

    def mean_channel_nis(self, start: int = 0) -> np.ndarray:
        """(R, 3) mean normalized innovation squared per channel [speed, camera,
        steering] over the steps the channel was used (NaN: never)."""
        if self.channel_nis is None:
            raise ValueError("the estimator reported no innovation statistics")
        nis = np.where(self.valid[:, start:, None], self.channel_nis[:, start:], np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a channel never used: NaN
            return np.nanmean(nis, axis=1)

    def to_frames(self) -> list[pd.DataFrame]:
        """One DataFrame per run: time, ``estimate_<state>`` and ``std_<state>`` of
        the four physical states, ``weight_<i>``, ``most_likely`` and the truth columns."""
        frames = []
        n_comp = self.weights.shape[2]
        for r in range(self.num_runs):
            length = int(self.lengths[r])
            data: dict[str, np.ndarray] = {"step": np.arange(length), "time": self.time[r, :length]}
            for j, name in enumerate(PHYSICAL_STATE_NAMES):
                data[f"estimate_{name}"] = self.mean[r, :length, j]
                data[f"std_{name}"] = self.std[r, :length, j]
            for c in range(n_comp):
                data[f"weight_{c}"] = self.weights[r, :length, c]
            data["most_likely"] = self.most_likely[r, :length]
            for key, values in self.truth.items():
                data[key] = values[r, :length]
            frames.append(pd.DataFrame(data))
        return frames


@runtime_checkable
class _Gating(Protocol):
    @property
    def last_gated(self) -> np.ndarray: ...


@runtime_checkable
class _LowSpeed(Protocol):
    @property
    def low_speed(self) -> np.ndarray: ...


@runtime_checkable
class _ChannelNIS(Protocol):
    @property
    def channel_nis(self) -> np.ndarray: ...


@dataclass(frozen=True)
class StackedRecordings:
    """Recordings stacked once (:func:`stack_recordings`), for filtering them with several
    estimators (:func:`run_estimator` takes it in place of the frames): the padded arrays
    (read-only: every result shares them) and, per look-ahead distance pair, the road
    points of the recordings' own tracks."""

    frames: tuple[pd.DataFrame, ...]
    lengths: np.ndarray
    measurements: np.ndarray
    accelerations: np.ndarray
    time: np.ndarray
    truth: dict[str, np.ndarray]
    road_points: dict[tuple[float, float], np.ndarray | None] = field(default_factory=dict)


def stack_recordings(frames: pd.DataFrame | Sequence[pd.DataFrame]) -> StackedRecordings:
    """The recordings as :func:`run_estimator` stacks them, done once (each estimator still
    checks its sample time against them).

    Raises:
        ValueError: as :func:`run_estimator` for its recordings (none, missing sensor
            columns, empty).
    """
    frames = [frames] if isinstance(frames, pd.DataFrame) else list(frames)
    _check_columns(frames)
    lengths = np.array([len(f) for f in frames])
    z, acc, time, truth = _stacked_recordings(frames, lengths, int(lengths.max()))
    for array in (lengths, z, acc, time, *truth.values()):
        array.setflags(write=False)
    return StackedRecordings(tuple(frames), lengths, z, acc, time, truth)


STEERING_ONLY_FIELDS = (
    "steering_residual_std",
    "steering_sensor_std",
    "steering_ratio",
    "min_speed",
    "steering_max_speed",
    "steering_curvature_limit",
    "aim_offset_std",
    "aim_offset_time",
)
"""The :class:`FilterSettings` fields a mixture filter without a steering model never reads:
the steering channel's noise and scale (its measurement is NaN, its row of the update
skipped), the limits that switch that channel off (:class:`GaussianMixtureEKF` keeps
``min_speed`` 0 and the others infinite without a model) and the aim cap (it bounds steering
evidence)."""


def pass_key(estimator: LaneEstimator) -> tuple[Any, ...] | None:
    """What :func:`run_estimator`'s result depends on besides the recordings, for the
    estimators whose passes can be shared; None for every other one.

    Two estimators with equal keys give the same :class:`EstimationResult` on the same
    recordings, to the bit, so a pass of one stands for a pass of the other. Keyed: a fresh
    (never reset) :class:`GaussianMixtureEKF` or :class:`~estimators.baselines.NoSteeringEKF`
    (exactly these classes: a subclass may add behaviour) without a steering model, by its
    class, sample time, decision lag and settings with the :data:`STEERING_ONLY_FIELDS` at
    their defaults: e.g. the no-steering filters of the steering models the trust rule
    refuses (:func:`estimators.trust.trusted_filter`), which differ from the no-steering
    baseline in their ``steering_residual_std`` only.
    """
    if type(estimator) not in (GaussianMixtureEKF, NoSteeringEKF):
        return None
    mixture = cast(GaussianMixtureEKF, estimator)
    if mixture.steering_model is not None or mixture.model.has_steering or mixture.num_runs:
        return None
    defaults = FilterSettings()
    settings = replace(
        mixture.settings, **{name: getattr(defaults, name) for name in STEERING_ONLY_FIELDS}
    )
    return (type(estimator).__name__, mixture.dt, mixture.decision_lag, settings)


def run_estimator(
    estimator: LaneEstimator,
    frames: pd.DataFrame | Sequence[pd.DataFrame] | StackedRecordings,
    *,
    hypotheses: Sequence[float] | np.ndarray | None = None,
    prior: np.ndarray | None = None,
    store_components: bool = False,
    roads: Road | Sequence[Road | None] | None = None,
    road_geometry: bool = True,
) -> EstimationResult:
    """Filter recordings offline, all runs in one batch.

    Args:
        estimator: any :class:`estimators.base.LaneEstimator` (batched ones
            filter all runs in one call per step).
        frames: one recording or a list (columns of
            :data:`hasa_env.sim.setup.RECORDING_COLUMNS`; at least the sensor columns), or
            the :class:`StackedRecordings` of a list (stacked once for several estimators:
            the same results).
        hypotheses: lane hypotheses (C,) or (R, C); default: each recording's
            config (:func:`hypotheses_of`).
        prior: hypothesis probabilities, (C,) or (R, C); default uniform.
        store_components: also keep the per-hypothesis means (R, T, C, n).
        roads: the road of every recording (one, or one per recording; None
            entries: straight); default: the track of each recording's
            metadata (:func:`hasa_env.steering.features.road_of_frame`).
        road_geometry: give the estimator the road ahead on curved roads
            (``road_points`` from the ``station`` column); False: the
            straight-road bearings everywhere.

    Returns:
        An :class:`EstimationResult` (a single recording gives R = 1).

    Raises:
        ValueError: a recording lacks sensor columns, is empty, is sampled at
            another rate than the estimator's (naming both rates), or is on a
            curved road without a ``station`` column.
    """
    stacked = frames if isinstance(frames, StackedRecordings) else None
    if isinstance(frames, StackedRecordings):
        frames = list(frames.frames)
    elif isinstance(frames, pd.DataFrame):
        frames = [frames]
    else:
        frames = list(frames)
    _check_recordings(estimator, frames)
    if stacked is not None:
        lengths, z, acc = stacked.lengths, stacked.measurements, stacked.accelerations
        time, truth = stacked.time, stacked.truth
    else:
        lengths = np.array([len(f) for f in frames])
        z, acc, time, truth = _stacked_recordings(frames, lengths, int(lengths.max()))
    n_runs = len(frames)
    n_steps = int(lengths.max())
    valid = np.arange(n_steps)[None, :] < lengths[:, None]
    hyp = _run_hypotheses(frames, hypotheses, n_runs)
    true_bias = None
    if getattr(estimator, "uses_true_bias", False):
        if "bias" not in truth:
            raise ValueError(
                "this estimator needs the true bias: the recordings lack a 'bias' column"
            )
        true_bias = truth["bias"][:, 0]
    points = None
    if road_geometry and stacked is not None and roads is None:  # the recordings' own tracks
        key = look_ahead_distances(estimator)
        if key not in stacked.road_points:
            computed = _road_points(estimator, frames, None, n_steps)
            if computed is not None:
                computed.setflags(write=False)
            stacked.road_points[key] = computed
        points = stacked.road_points[key]
    elif road_geometry:
        points = _road_points(estimator, frames, roads, n_steps)

    def road(k: int) -> dict[str, np.ndarray]:
        return {} if points is None else {"road_points": points[:, k]}

    est = estimator.reset(z[:, 0], hyp, prior=prior, true_bias=true_bias, **road(0))
    if isinstance(estimator, GaussianMixtureEKF):
        return _run_mixture_filter(estimator, est, z, acc, points, store_components).result(
            est, time, valid, lengths, truth
        )
    trace = _Trace(estimator, est, n_runs, n_steps, store_components)
    trace.store(0, est)
    for k in range(1, n_steps):
        est = estimator.step(z[:, k], acc[:, k], **road(k))
        trace.store(k, est)
    return trace.result(est, time, valid, lengths, truth)


def _run_mixture_filter(
    estimator: GaussianMixtureEKF,
    first: Estimate,
    z: np.ndarray,
    acc: np.ndarray,
    points: np.ndarray | None,
    store_components: bool,
) -> _Trace:
    """Steps 1 .. T-1 of the mixture filter, reset at step 0 (its estimate ``first``): the
    fast path of :func:`run_estimator`, with the results of its per-step loop to the bit.
    The road points are checked once, each step is :meth:`GaussianMixtureEKF.advance` (no
    :class:`Estimate`) and the states are recorded in blocks (:class:`MixtureTrace`)."""
    n_runs, n_steps = z.shape[:2]
    if points is not None:
        check_road_points(points)
    n_comp, n_states = first.component_means.shape[-2:]
    trace = MixtureTrace(n_runs, n_steps, n_comp, n_states, store_components)
    trace.append(estimator.mixture_state)
    for k in range(1, n_steps):
        estimator.advance(
            z[:, k], acc[:, k], None if points is None else points[:, k], checked=True
        )
        trace.append(estimator.mixture_state)
    trace.flush()
    return _Trace.of_mixture(trace, estimator)


def _check_columns(frames: list[pd.DataFrame]) -> None:
    """Raise ValueError for no recordings, a recording without the sensor columns, or an
    empty one."""
    if not frames:
        raise ValueError("no recordings given")
    for i, frame in enumerate(frames):
        missing = [c for c in (*MEASUREMENT_KEYS, *ACCELERATION_KEYS) if c not in frame.columns]
        if missing:
            raise ValueError(f"recording {i} lacks the columns {missing}")
        if len(frame) < 1:
            raise ValueError(f"recording {i} is empty")


def _check_recordings(estimator: LaneEstimator, frames: list[pd.DataFrame]) -> None:
    """Raise ValueError for no recordings, a recording without the sensor columns, an
    empty one, or one sampled at another rate than the estimator's."""
    _check_columns(frames)
    for i, frame in enumerate(frames):
        timing = recording_sample_time(frame)
        if timing is not None:
            step, frequency, repeat = timing
            source = "the recording" if len(frames) == 1 else f"recording {i}"
            check_sample_time(
                estimator, step, source=source, sim_frequency=frequency, action_repeat=repeat
            )


def _stacked_recordings(
    frames: list[pd.DataFrame], lengths: np.ndarray, n_steps: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """The recordings as padded arrays (R, T, ...): measurements (NaN after a run's end),
    accelerations (0 after), time (NaN after) and the truth columns all recordings have
    (NaN after; ``bias_index`` -1)."""
    n_runs = len(frames)
    z = np.full((n_runs, n_steps, 3), np.nan)
    acc = np.zeros((n_runs, n_steps, 2))
    time = np.full((n_runs, n_steps), np.nan)
    truth_keys = [c for c in (*TRUTH_COLUMNS, "bias_index") if all(c in f.columns for f in frames)]
    truth = {
        key: np.full((n_runs, n_steps), -1 if key == "bias_index" else np.nan) for key in truth_keys
    }
    for r, recording in enumerate(frames):
        frame = pd.DataFrame(recording, copy=False)  # no attrs (deep-copied per column read)
        length = lengths[r]
        z[r, :length] = frame[list(MEASUREMENT_KEYS)].to_numpy(dtype=np.float64)
        acc[r, :length] = frame[list(ACCELERATION_KEYS)].to_numpy(dtype=np.float64)
        if "time" in frame.columns:
            time[r, :length] = frame["time"].to_numpy(dtype=np.float64)
        for key in truth_keys:
            truth[key][r, :length] = frame[key].to_numpy()
    if "bias_index" in truth:
        truth["bias_index"] = truth["bias_index"].astype(np.int64)
    return z, acc, time, truth


def _run_hypotheses(
    frames: list[pd.DataFrame], hypotheses: Sequence[float] | np.ndarray | None, n_runs: int
) -> np.ndarray:
    """The lane hypotheses (R, C): ``hypotheses`` ((C,) or (R, C)), or each recording's."""
    if hypotheses is None:
        per_run = [hypotheses_of(f) for f in frames]
        if len({len(h) for h in per_run}) != 1:
            raise ValueError(
                "the recordings have different numbers of lane hypotheses; pass hypotheses"
            )
        return np.array(per_run)
    hyp = np.asarray(hypotheses, dtype=np.float64)
    if hyp.ndim == 1:
        hyp = np.broadcast_to(hyp, (n_runs, hyp.size))
    return hyp


class _Trace:
    """The estimates of :func:`run_estimator`, sample after sample, and the optional
    diagnostics of the estimators that have them (gating, low speed, channel NIS)."""

    def __init__(
        self,
        estimator: LaneEstimator,
        first: Estimate,
        n_runs: int,
        n_steps: int,
        store_components: bool,
    ) -> None:
        n_states = first.mean.shape[-1]
        n_comp = first.weights.shape[-1]
        self.mean = np.empty((n_runs, n_steps, n_states))
        self.std = np.empty((n_runs, n_steps, n_states))
        self.weights = np.empty((n_runs, n_steps, n_comp))
        self.most_likely = np.empty((n_runs, n_steps), dtype=np.int64)
        self.components = (
            np.empty((n_runs, n_steps, n_comp, n_states)) if store_components else None
        )
        self.gating = estimator if isinstance(estimator, _Gating) else None
        self.slowing = estimator if isinstance(estimator, _LowSpeed) else None
        self.checking = estimator if isinstance(estimator, _ChannelNIS) else None
        self.coding = estimator if hasattr(estimator, "decision_codes") else None
        self.withholding = estimator if hasattr(estimator, "withheld_decisions") else None
        self.refusing = estimator if hasattr(estimator, "refusal_codes") else None
        self.gated = np.zeros((n_runs, n_steps, 3), dtype=bool) if self.gating is not None else None
        self.low_speed = (
            np.zeros((n_runs, n_steps), dtype=bool) if self.slowing is not None else None
        )
        self.decision = np.full((n_runs, n_steps), -1, dtype=np.int8)
        self.model_error = np.full((n_runs, n_steps), np.nan)
        self.evidence_scale = np.full((n_runs, n_steps), np.nan)
        self.channel_nis = (
            np.full((n_runs, n_steps, 3), np.nan) if self.checking is not None else None
        )

    @classmethod
    def of_mixture(cls, trace: MixtureTrace, estimator: GaussianMixtureEKF) -> _Trace:
        """The record of a :class:`MixtureTrace` of ``estimator`` (its arrays, not copies)."""
        self = cls.__new__(cls)
        for name in ("mean", "std", "weights", "most_likely", "components", "gated"):
            setattr(self, name, getattr(trace, name))
        for name in ("low_speed", "decision", "model_error", "evidence_scale", "channel_nis"):
            setattr(self, name, getattr(trace, name))
        # (the filter has every optional record's attributes)
        self.gating = self.slowing = self.checking = self.coding = self.withholding = cast(
            Any, estimator
        )
        self.refusing = cast(Any, estimator)
        return self

    def store(self, k: int, e: Estimate) -> None:
        """Keep the estimate at sample k: the mixture mean, its std
        ``sqrt(sum_i w_i (P_i,nn + (x_i,n - x_n)^2))``, the weights and the diagnostics."""
        self.mean[:, k] = e.mean
        w = e.weights
        spread = (
            np.diagonal(e.component_covariances, axis1=-2, axis2=-1)
            + (e.component_means - e.mean[:, None, :]) ** 2
        )
        self.std[:, k] = np.sqrt(np.einsum("rc,rcn->rn", w, spread))
        self.weights[:, k] = w
        self.most_likely[:, k] = e.most_likely
        if self.components is not None:
            self.components[:, k] = e.component_means
        if self.gated is not None and self.gating is not None and k:
            self.gated[:, k] = self.gating.last_gated
        if self.low_speed is not None and self.slowing is not None:
            self.low_speed[:, k] = self.slowing.low_speed
        if self.coding is None:
            names = np.asarray(e.decision)
            codes = np.select([names == name for name in DECISIONS], range(len(DECISIONS)), -1)
        else:  # the filter's own codes of the names in the estimate
            codes = self.coding.decision_codes
        self.decision[:, k] = codes
        self.model_error[:, k] = e.model_error
        self.evidence_scale[:, k] = e.evidence_scale
        if self.channel_nis is not None and self.checking is not None and k:
            self.channel_nis[:, k] = self.checking.channel_nis

    def result(
        self,
        last: Estimate,
        time: np.ndarray,
        valid: np.ndarray,
        lengths: np.ndarray,
        truth: dict[str, np.ndarray],
    ) -> EstimationResult:
        """The :class:`EstimationResult` (samples after a run's end masked out)."""
        return EstimationResult(
            state_names=tuple(last.state_names),
            hypotheses=np.array(last.hypotheses, copy=True),
            time=time,
            valid=valid,
            lengths=lengths,
            mean=self.mean,
            std=self.std,
            weights=self.weights,
            most_likely=self.most_likely,
            truth=truth,
            component_means=self.components,
            gated=None if self.gated is None else self.gated & valid[:, :, None],
            low_speed=None if self.low_speed is None else self.low_speed & valid,
            decision=np.where(valid, self.decision, -1),
            model_error=np.where(valid, self.model_error, np.nan),
            evidence_scale=np.where(valid, self.evidence_scale, np.nan),
            channel_nis=None
            if self.channel_nis is None
            else np.where(valid[:, :, None], self.channel_nis, np.nan),
            withheld=None
            if self.withholding is None
            else np.atleast_1d(self.withholding.withheld_decisions),
            refused_by=None
            if self.refusing is None
            else np.atleast_1d(self.refusing.refusal_codes),
        )


@dataclass(frozen=True)
class EstimatorRun:
    """The mixture estimator over one recording.

    Attributes:
        weights: (rows, C) hypothesis weights per row.
        hypotheses: (C,) camera biases b (m).
        lateral_offset: (rows,) mixture estimate of y (m).
        lateral_rmse: RMS of estimate - true y over all rows (m).
        true_index: index of the recording's true hypothesis (-1 if it is none of them).
        final_true_weight: weight of the true hypothesis at the end (NaN if not among them).
        trusted_from: first time (s) from which the true hypothesis' weight stays above 0.9
            (NaN if never).
        final_decision: the decision state at the last row (``"undecided"``, ``"decided"``
            or ``"model_mismatch"``; :mod:`estimators.evidence`).
        refused_by: for a run that ends in ``model_mismatch``, why
            (:meth:`EstimationResult.refusal_reasons`); ``""`` otherwise.
        trust: the filter that ran (:func:`recording_filter`): its settings, the form it
            compared with the steering and its reasons (:meth:`TrustedFilter.describe`).
        result: the filter's whole output over the recording, one run
            (:class:`EstimationResult`: weights, means, stds, the evidence rule's statistics;
            e.g. :func:`estimators.calibration.steering_channel_shares` of it, and
            :meth:`EstimationResult.lateral_nees`), one run of the recording's rows.
    """

    weights: np.ndarray
    hypotheses: np.ndarray
    lateral_offset: np.ndarray
    lateral_rmse: float
    true_index: int
    final_true_weight: float
    trusted_from: float
    final_decision: str = ""
    refused_by: str = ""
    trust: TrustedFilter | None = None
    result: EstimationResult | None = None


def recording_filter(
    recording: Recording,
    steering_model: SteeringModelLike,
    steering_ratio: float = 1.0,
    residual_std: float | None = None,
    *,
    training: TrainingRecord | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> TrustedFilter:
    """The filter :func:`estimate_recording` runs over ``recording``:
    :func:`estimators.trust.trusted_filter` of the steering model on filter settings from the
    recording's config. ``steering_ratio``: model units per recorded road-wheel radian.
    ``residual_std``: the steering model's equation-error level (rad, model units;
    ``FilterSettings.steering_residual_std``); None: the training record's, else the model's
    one-step residual on this recording's true states
    (:func:`estimators.tuning.steering_residual_std`): the evidence checks
    (:mod:`estimators.evidence`) temper evidence whose residuals exceed the level they are
    given, but cannot recover evidence a level set far too high hides. The trust rule's
    prediction check is made only where ``training`` carries it (made on the data the model
    was fitted on): on a recording of another driver a model is not compared with an
    autoregression fitted to that driver (docs/design.md §8.13.1). A declared speed-scaled
    equation error is checked on this recording unless ``training`` measured it
    (:func:`estimators.tuning.speed_scaled_gain`, docs/design.md §8.34). ``training``,
    ``overrides``: as :func:`~estimators.trust.trusted_filter` takes them (the model's own
    record of its training roads and speeds limits where its steering counts).
    """
    training = training or TrainingRecord()
    arx = steering_model.arx()
    level = training.residual_std if residual_std is None else residual_std
    whitened = training.whitened_residual_std
    if arx is not None and level is None:  # both levels on this recording's true states
        level = steering_residual_std(
            arx,
            recording.data,
            decision_lag=getattr(steering_model, "decision_lag", 1),
            steering_ratio=steering_ratio,
        )
        whitened = whitened_residual_std(
            steering_model, recording.data, steering_ratio=steering_ratio
        )
    gain = training.speed_scaled_gain
    if arx is not None and gain is None:  # a declared speed-scaled error, on this recording
        gain = speed_scaled_gain(steering_model, recording.data, steering_ratio=steering_ratio)
    return trusted_filter(
        steering_model,
        FilterSettings.from_env_config(recording.config),
        steering_ratio=steering_ratio,
        training=replace(
            training, residual_std=level, whitened_residual_std=whitened, speed_scaled_gain=gain
        ),
        overrides=overrides,
    )


def estimate_recording(
    recording: Recording,
    steering_model: SteeringModelLike,
    steering_ratio: float = 1.0,
    residual_std: float | None = None,
    *,
    training: TrainingRecord | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> EstimatorRun:
    """Run the mixture EKF (:class:`estimators.gm_ekf.GaussianMixtureEKF`) over a recording.

    Through :func:`estimators.offline.run_estimator`: it sees what the car's
    sensors recorded (speed, biased camera, steering, IMU), with the
    hypotheses of the recording's config and the filter of :func:`recording_filter`
    (same arguments), which the run keeps (:attr:`EstimatorRun.trust`).
    """
    data = recording.data
    cfg = recording.config
    hypotheses = np.asarray(cfg["markings"]["hypotheses"], dtype=np.float64)
    trust = recording_filter(
        recording,
        steering_model,
        steering_ratio,
        residual_std,
        training=training,
        overrides=overrides,
    )
    estimator = trust.estimator(dt=recording.dt)
    result = run_estimator(estimator, data, hypotheses=hypotheses)
    n = len(data)
    weights = result.weights[0, :n]
    lateral = result.mean[0, :n, result.state_names.index("lateral_offset")]
    true_y = data["lateral_offset"].to_numpy(dtype=np.float64)
    rmse = float(np.sqrt(np.mean((lateral - true_y) ** 2)))
    true_index = int(data["bias_index"].iloc[0])
    outcome: dict[str, Any] = {
        "final_decision": str(result.final_decision()[0]),
        "refused_by": str(result.refusal_reasons()[0]),
        "trust": trust,
        "result": result,
    }
    if not 0 <= true_index < hypotheses.size:
        matches = np.flatnonzero(np.isclose(hypotheses, float(data["bias"].iloc[0])))
        true_index = int(matches[0]) if matches.size else -1
    if true_index < 0:
        return EstimatorRun(weights, hypotheses, lateral, rmse, -1, math.nan, math.nan, **outcome)
    w_true = weights[:, true_index]
    below = np.flatnonzero(w_true <= 0.9)
    if below.size == 0:
        trusted = 0.0
    elif below[-1] + 1 < n:
        trusted = float(data["time"].iloc[below[-1] + 1])
    else:
        trusted = math.nan
    return EstimatorRun(
        weights, hypotheses, lateral, rmse, true_index, float(w_true[-1]), trusted, **outcome
    )


def _road_points(
    estimator: LaneEstimator,
    frames: Sequence[pd.DataFrame],
    roads: Road | Sequence[Road | None] | None,
    n_steps: int,
) -> np.ndarray | None:
    """(R, T, 4) road points of the recordings' rows, or None when every road is straight.

    Rows of straight roads get ``(near, 0, far, 0)``; padded rows repeat the last row's.
    """
    if roads is None:
        per_run = [road_of_frame(f) for f in frames]
    elif isinstance(roads, Road):
        per_run = [roads] * len(frames)
    else:
        per_run = list(roads)
        if len(per_run) != len(frames):
            raise ValueError(f"got {len(per_run)} roads for {len(frames)} recordings")
    near, far = look_ahead_distances(estimator)
    points = None
    for r, (frame, road) in enumerate(zip(frames, per_run, strict=True)):
        if road is None and roads is None and _is_curved(frame):
            warnings.warn(
                f"recording {r} has a non-zero road_curvature but names no track "
                "(attrs['config']['track']): the estimator uses straight-road bearings; "
                "pass roads=...",
                stacklevel=3,
            )
        if road is None or road.is_straight:
            continue
        if "station" not in frame.columns:
            raise ValueError(
                f"recording {r} is on a curved road but lacks the 'station' column the "
                "estimator needs for the road ahead"
            )
        if points is None:
            points = np.empty((len(frames), n_steps, 4))
            points[:] = straight_road_points(near, far)
        station = frame["station"].to_numpy(dtype=np.float64)
        points[r, : station.size] = lane_points_ahead(road, station, near, far)
        points[r, station.size :] = points[r, station.size - 1]
    return points


def _is_curved(frame: pd.DataFrame) -> bool:
    if "road_curvature" not in frame.columns:
        return False
    curvature = frame["road_curvature"].to_numpy(dtype=np.float64)
    return bool(np.any(np.abs(curvature[np.isfinite(curvature)]) > 0))
