"""The Gaussian-mixture EKF with the human as advisor (paper section 4).

Vectorized over lane hypotheses and over many runs at once: states are
(runs, components, n), covariances (runs, components, n, n). Its settings
live in :mod:`estimators.settings`, its matrices and batched predict/update
in :mod:`estimators.filter_matrices` (:class:`FilterMatrices` is re-exported
here).

The filter's per-run state is one record, :class:`MixtureState` (a subset of
runs is a slice of it: :meth:`MixtureState.take`, :meth:`MixtureState.put`),
and one step, :meth:`GaussianMixtureEKF._step`, is the list of its rules, one
method each, whose docstrings state their equations: missing inputs, predict,
update with the outlier gate, evidence, pruning, the steering channel off by
speed or curvature and its memory restart. The arithmetic itself is in
:mod:`estimators.filter_matrices` and :mod:`estimators.evidence`.

Why this module is long: the filter's docstring states its equations, its robustness rules
and every deviation from the paper (as filterpy's filters do), each rule's docstring states
its own equations, and the state record sits next to the rules that read and replace it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from estimators.arx_state_space import (
    VX,
    VY,
    road_curvature_ahead,
    road_point_rows,
)
from estimators.base import Estimate, reset_inputs
from estimators.evidence import (
    DECIDED,
    DECISIONS,
    MODEL_MISMATCH,
    UNDECIDED,
    EvidenceRule,
    aim_offset_rate,
    decision_names,
    initial_aim_offsets,
    initial_evidence_state,
    moved_aim_offsets,
    normalize_log_weights,
    weigh_evidence,
)
from estimators.filter_matrices import FilterMatrices, filter_model
from estimators.road_geometry import straight_road_points
from estimators.settings import FilterSettings
from estimators.small_arrays import (
    all_finite,
    all_true,
    all_within,
    any_equal,
    any_true,
    min_below,
)
from hasa_env.steering.arx import ARXForm

__all__ = ["GaussianMixtureEKF", "FilterMatrices", "MixtureState"]


@dataclass(slots=True)
class MixtureState:
    """The per-run state of :class:`GaussianMixtureEKF`: R runs x C hypotheses of n states.

    Rows of ``x`` and ``P`` are run-major (hypothesis i of run r is row ``r C + i``).
    A step replaces the record (or the part of it that :meth:`take` gave); arrays are
    never changed in place once stored, so an :class:`Estimate` keeps its values.

    Attributes:
        x: (R C, n) hypothesis means x_i(k|k).
        P: (R C, n, n) covariances P_i(k|k).
        log_w: (R, C) log weights log w_i (-inf: zero weight).
        active: (R, C) bool: not pruned.
        hypotheses: (R, C) lane-centre hypotheses b_i (m).
        steering: (R,) steering reading z_3(k) for the next prediction's memory
            update (model units; NaN: none, or gated).
        channel_off: (R,) bool: the steering channel is off (speed or road curvature).
        gated: (R, 3) bool: channels gated at the last step.
        gated_count: (R, 3) int: samples gated since reset.
        evidence: the evidence rule's statistics (:data:`estimators.evidence.EVIDENCE_STATE`).
        decision: (R,) int decision codes (:data:`estimators.evidence.DECISIONS`).
        model_error: (R,) lambda; autocorrelation: (R,) rho; evidence_scale: (R,) tau.
        innovation_log_w: (R, C) log weights the last update's innovations were weighed with.
        normalized_innovation: (R, C, 3) nu_c / sqrt(S_cc) of the last update (NaN: unused).
        road_points: (R, 4) road points of the last sample; None: a straight road for all.
        straight_points: (4,) the road points of a straight road (a run stepped without
            road points while others have them).
    """

    x: np.ndarray
    P: np.ndarray
    log_w: np.ndarray
    active: np.ndarray
    hypotheses: np.ndarray
    steering: np.ndarray
    channel_off: np.ndarray
    gated: np.ndarray
    gated_count: np.ndarray
    evidence: dict[str, np.ndarray]
    decision: np.ndarray
    model_error: np.ndarray
    autocorrelation: np.ndarray
    evidence_scale: np.ndarray
    innovation_log_w: np.ndarray
    normalized_innovation: np.ndarray
    road_points: np.ndarray | None
    straight_points: np.ndarray

    @property
    def num_runs(self) -> int:
        """R."""
        return self.log_w.shape[0]

    def rows(self, idx: np.ndarray) -> np.ndarray:
        """The rows of ``x`` and ``P`` of runs ``idx`` (R',): ``r C + i`` for i < C."""
        n_comp = self.log_w.shape[1]
        return (idx[:, None] * n_comp + np.arange(n_comp)).ravel()

    def take(self, idx: np.ndarray) -> MixtureState:
        """The state of runs ``idx`` (R',) (copies)."""
        rows = self.rows(idx)
        return MixtureState(
            x=self.x[rows],
            P=self.P[rows],
            road_points=None if self.road_points is None else self.road_points[idx],
            evidence={name: value[idx] for name, value in self.evidence.items()},
            straight_points=self.straight_points,
            **{name: getattr(self, name)[idx] for name in _RUN_ARRAYS},
        )

    def put(self, idx: np.ndarray, part: MixtureState) -> None:
        """Store ``part`` (from :meth:`take`, or a reset of R' runs) as runs ``idx`` (R',):
        every array is replaced by a copy with those rows set."""
        rows = self.rows(idx)
        self.x, self.P = _set_rows(self.x, rows, part.x), _set_rows(self.P, rows, part.P)
        for name in _RUN_ARRAYS:
            setattr(self, name, _set_rows(getattr(self, name), idx, getattr(part, name)))
        self.evidence = {
            name: _set_rows(value, idx, part.evidence[name])
            for name, value in self.evidence.items()
        }
        if part.road_points is None and self.road_points is None:
            return
        stored = (
            np.tile(self.straight_points, (self.num_runs, 1))
            if self.road_points is None
            else self.road_points
        )
        new = self.straight_points if part.road_points is None else part.road_points
        self.road_points = _set_rows(stored, idx, new)


_RUN_ARRAYS = (
    "log_w",
    "active",
    "hypotheses",
    "steering",
    "channel_off",
    "gated",
    "gated_count",
    "decision",
    "model_error",
    "autocorrelation",
    "evidence_scale",
    "innovation_log_w",
    "normalized_innovation",
)
"""The fields of :class:`MixtureState` with one row per run (besides ``evidence``)."""


def _set_rows(array: np.ndarray, rows: np.ndarray, value: np.ndarray) -> np.ndarray:
    """A copy of ``array`` with ``array[rows] = value``."""
    array = array.copy()
    array[rows] = value
    return array


class GaussianMixtureEKF:
    """Gaussian-mixture extended Kalman filter: one EKF per lane hypothesis.

    The human's steering, through an ARX steering model, tells the lanes
    apart (paper section 4.2; docs/design.md §8). State of hypothesis i:
    ``x_i = [v_x, y_i, v_y, b_i, m_1 .. m_n]`` (see
    :class:`estimators.arx_state_space.ARXStateSpace`); measurements
    ``z = [speed, camera y + b, steering]``; inputs the IMU accelerations a.

    Predict (paper eq. 11 and 13, noise decorrelated as in :class:`FilterMatrices`)::

        x_i(k|k-1) = F(x_i(k-1|k-1)) + B_D a(k) [+ J (z_3(k-1) - h_3(x_i(k-1|k-1)))]
        P_i(k|k-1) = F'_i P_i(k-1|k-1) F'_i^T + Q

    Update (paper eq. 15-18; eq. 12 and 14 give h and H; Joseph form)::

        nu_i = z(k) - h(x_i(k|k-1))                          innovation
        S_i  = H_i P_i H_i^T + R                             (the paper's rho_i, eq. 15)
        K_i  = P_i H_i^T S_i^-1                              (eq. 16)
        x_i  = x_i + K_i nu_i                                (eq. 17)
        P_i  = (I - K_i H_i) P_i (I - K_i H_i)^T + K_i R K_i^T   (eq. 18, Joseph form)

    Weights (paper eq. 19 with the full multivariate normal, in log space)::

        log w_i = log w_i - 1/2 (nu_i^T S_i^-1 nu_i + log det S_i + m log 2 pi)
        log w_i = log w_i - logsumexp_j(log w_j)

    Estimate: ``x = sum_i w_i x_i`` and the mixture covariance (paper
    section 5.2). A non-finite measurement (NaN, +-inf) is missing: its row of
    H, nu and R is dropped (m counts the observed rows); a non-finite IMU
    reading, or one beyond ``max_acceleration``, is 0 with the process noise
    of ``missing_acceleration_std``. Hypotheses whose weight falls below
    ``prune_threshold`` are pruned (weight 0, state frozen). Each hypothesis
    computes its bearings from its *own* y_i, and its memory states start
    from the measured steering and its own bearings
    (:meth:`FilterMatrices.initial_state`).

    Robustness rules (thresholds in :class:`FilterSettings`):

    - outlier gate: channel c is dropped for every hypothesis when
      ``min_i [nu_ic^2 / S_i,cc + 2 ln(w_max / w_i)] > innovation_gate^2``
      (for the most likely hypothesis: ``|nu_c| / sqrt(S_cc) > g``); a gated
      steering reading is also kept out of the next prediction's memory
      update. :attr:`gated_counts` counts the gated samples per run and channel;
    - low speed: while ``sum_i w_i |v_i| < min_speed`` (decided on the
      estimate at k-1; also above ``steering_max_speed``, the speeds a
      model was not fitted at) the steering row is dropped (no update, no weight)
      and the memory is held (:class:`FilterMatrices`); at the first estimate
      above it with a finite steering reading z_3(k), the memory of every
      active hypothesis restarts as at reset,
      ``m_i = steady_memory(z_3(k), x_i(k|k))``, ``P_mm = memory_std^2 I``,
      uncorrelated with the vehicle states (:attr:`low_speed`);
    - outside the model's road: while the road ahead curves more than
      ``steering_curvature_limit`` (``max(|kappa_near|, |kappa_far|)`` with
      ``kappa_d = 2 |dy_d| / (dx_d^2 + dy_d^2)`` from the road points at k,
      decided for step k+1) the steering channel is off and its memory held
      and restarted exactly as at low speed: a model is trusted only on roads
      as curved as those it was fitted on (:class:`FilterSettings`);
    - evidence (:mod:`estimators.evidence`): the weights move by the tempered evidence, and,
      with the aim cap (``aim_offset_std``, on by default), no run's log-odds grow past what a
      prior on where drivers hold the car allows for each hypothesis' lateral offset averaged
      over ``aim_offset_time`` (docs/design.md §8.19).

    Road geometry: with ``road_points`` (:mod:`estimators.road_geometry`) the
    bearings are those of the lane centre ahead on a curved road
    (:mod:`estimators.arx_state_space`); the prediction k -> k+1 uses the
    points given at k, the update at k those given at k.

    Every array holds R runs x C hypotheses; one call of :meth:`step`
    filters all of them.

    Where this differs from the paper (docs/design.md §8 and §10):

    - the speedometer measures the speed: h_1 = sqrt(v_x^2 + v_y^2), not v_x;
    - the memory recursion is the corrected, non-circular one, for any ARX
      orders, with exact Jacobians;
    - the steering model's equation error enters both the memory states and
      the steering measurement; the correlation is removed exactly
      (:class:`FilterMatrices`), so the memory follows the measured steering;
    - the memory states start from each hypothesis' own bearings, not a
      shared "human-observed" value (which would leak the true lane);
    - each hypothesis' bias starts at its lane offset with a small std
      (``bias_std``, 1 mm), not the paper's I_4 (eq. 20): a hypothesis *is* a
      known lane-centre offset, and a loose bias lets the steering model's
      mismatch drag y away from the camera (measured: 0.095 m instead of
      0.048 m lateral RMSE on the synthetic population with bias_std 0.01 m);
    - the weights use the full 3x3 innovation covariance (the paper's eq. 19
      writes a scalar sqrt(rho)).

    Args:
        steering_model: the steering model's :class:`hasa_env.steering.arx.ARXForm`;
            None gives the no-steering filter (speed and camera only).
        settings: noise levels, priors and pruning (:class:`FilterSettings`).
        dt: sample time (s); default ``steering_model.dt``.
        decision_lag: samples between the state the driver saw and the
            steering measurement (see :class:`ARXStateSpace`); default 1, the
            alignment of recordings and of
            :func:`hasa_env.steering.features.steering_features`. Use 0 for
            the paper's eq. 10 taken literally (7 states for its order).
        **overrides: fields of :class:`FilterSettings` to replace.

    Example::

        from estimators import GaussianMixtureEKF, MEASUREMENT_KEYS, ACCELERATION_KEYS
        from hasa_env.steering import GeneralizedModel
        ekf = GaussianMixtureEKF(GeneralizedModel.paper().arx(), steering_residual_std=2e-3)
        z = frame[list(MEASUREMENT_KEYS)].to_numpy()
        a = frame[list(ACCELERATION_KEYS)].to_numpy()
        est = ekf.reset(z[0], [0.0, -1.8])
        for k in range(1, len(frame)):
            est = ekf.step(z[k], a[k])
        est.lateral_offset, est.weights, est.most_likely
    """

    uses_true_bias = False

    _state: MixtureState | None
    """The per-run state (None before reset)."""

    def __init__(
        self,
        steering_model: ARXForm | None,
        settings: FilterSettings | None = None,
        *,
        dt: float | None = None,
        decision_lag: int = 1,
        **overrides: Any,
    ) -> None:
        self.settings = settings = FilterSettings.with_overrides(settings, overrides)
        self.steering_model = steering_model
        self.decision_lag = decision_lag
        self.model = filter_model(steering_model, settings, dt, decision_lag)
        self.matrices = FilterMatrices(self.model, settings)
        self.state_names = self.model.state_names
        threshold = settings.prune_threshold
        ratio = settings.steering_ratio if self.model.has_steering else np.nan
        self._measurement_scale = np.array([[1.0, 1.0, ratio]])  # (a row: cheaper for one run)
        self._feedforward = self.settings.steering_curvature_feedforward
        self._log_prune_threshold = math.log(threshold) if threshold > 0 else None
        self._rule = EvidenceRule.from_settings(settings, self.model.dt)
        # the aim cap bounds the steering's lane evidence: without a steering model it is off
        self._aim_rate = aim_offset_rate(settings, self.model.dt, self.model.has_steering)
        if not self._aim_rate:
            self._rule = replace(self._rule, aim_variance=0.0)
        self._min_speed = settings.min_speed if self.model.has_steering else 0.0
        self._drops_steering = settings.mismatch_drops_steering and self.model.has_steering
        self._max_acceleration = settings.max_acceleration
        self._max_speed = settings.steering_max_speed if self.model.has_steering else math.inf
        self._curvature_limit = (
            settings.steering_curvature_limit if self.model.has_steering else math.inf
        )
        self._straight_points = straight_road_points(
            self.model.near_distance, self.model.far_distance
        )
        self._state = None
        self._single = False
        self._n_comp = 0

    @property
    def dt(self) -> float:
        """Sample time Ts (s)."""
        return self.model.dt

    @property
    def n_states(self) -> int:
        """Length of each hypothesis' state vector."""
        return self.model.n_states

    @property
    def num_runs(self) -> int:
        """Number of runs in the current batch (0 before reset)."""
        return 0 if self._state is None else self._state.num_runs

    @property
    def gated_counts(self) -> np.ndarray:
        """Samples gated as outliers since reset, per run and channel
        [speed, camera, steering]: (R, 3) int (a single run: (3,))."""
        return self._run_view(self._checked_state().gated_count)

    @property
    def last_gated(self) -> np.ndarray:
        """Channels gated at the last step, (R, 3) bool (a single run: (3,))."""
        return self._run_view(self._checked_state().gated)

    @property
    def channel_nis(self) -> np.ndarray:
        """Normalized innovation squared of each channel [speed, camera, steering] at the
        last step, averaged over the hypotheses with their weights before the update,
        ``sum_i w_i nu_ic^2 / S_i,cc``: (R, 3) (a single run: (3,); NaN: channel not used).
        A consistent filter averages 1 per channel."""
        state = self._checked_state()
        normalized = state.normalized_innovation
        clipped = np.minimum(np.maximum(normalized, -1e3), 1e3)  # (NaN stays)
        nis = np.einsum("rc,rcm->rm", np.exp(state.innovation_log_w), clipped * clipped)
        return nis[0] if self._single else nis

    @property
    def decision_codes(self) -> np.ndarray:
        """The decision state of each run as its code, ``DECISIONS[code]`` the name in the
        estimate (:data:`estimators.evidence.DECISIONS`: 0 undecided, 1 decided, 2
        model_mismatch): (R,) int (a single run: one int). Offline runs store these codes
        without turning the names back into codes at every step."""
        return self._run_view(self._checked_state().decision)

    @property
    def withheld_decisions(self) -> np.ndarray:
        """The hypothesis the reversal rule withheld a decision for in each run, -1 where none:
        (R,) int (a single run: one int). When a run committed to hypothesis i and its weights
        later passed the decision threshold on j != i, the rule sent them back to the prior
        (``model_mismatch``) instead of reporting j (:mod:`estimators.evidence`); this is j.
        One of the two decisions was wrong, since the lane does not change within a run: the
        benchmark counts a withheld decision for a wrong lane as a wrong decision."""
        withheld = self._checked_state().evidence["_withheld"].astype(np.int64)
        return self._run_view(withheld)

    @property
    def refusal_codes(self) -> np.ndarray:
        """What sent each run back to its prior for good: (R,) int codes of
        :data:`estimators.evidence.REFUSALS` (0 nothing, 1 the reversal rule, 2 the path rule;
        a single run: one int)."""
        return self._run_view(self._checked_state().evidence["_refused_by"].astype(np.int64))

    @property
    def low_speed(self) -> np.ndarray:
        """Runs whose steering channel is off (speed estimate below ``min_speed``, or the
        road ahead more curved than ``steering_curvature_limit``): (R,) bool (a single run:
        one bool)."""
        return self._run_view(self._checked_state().channel_off)

    # ------------------------------------------------------------------ API
    def reset(
        self,
        measurement: np.ndarray,
        hypotheses: Sequence[float] | np.ndarray,
        *,
        prior: np.ndarray | None = None,
        true_bias: np.ndarray | float | None = None,
        runs: np.ndarray | None = None,
        road_points: np.ndarray | None = None,
    ) -> Estimate:
        """Start (or restart ``runs`` of) the filter from the first measurements.

        Args:
            measurement: (3,) or (R, 3) first [speed, camera, steering]; speed
                and camera must be finite (a non-finite steering counts as 0).
            hypotheses: lane-centre hypotheses, the camera bias b_i (m): (C,) or (R, C).
            prior: hypothesis probabilities, (C,) or (R, C); default uniform.
            true_bias: ignored (only the oracle uses it).
            runs: restart only these runs (indices or a boolean mask) of the
                current batch; the others are left as they are.
            road_points: (R, 4) or (4,) lane-centre points ahead
                (dx_near, dy_near, dx_far, dy_far) (m) at this sample
                (:mod:`estimators.road_geometry`); None: a straight road.

        Returns:
            The prior estimate (weights = prior).
        """
        z, single, hyp, log_w = reset_inputs(measurement, hypotheses, prior)
        n_runs, n_comp = hyp.shape
        points = road_point_rows(road_points, n_runs)
        z = self._without_feedforward(z, points)
        state = self._initial_state(z, hyp, log_w, points)
        if runs is None:
            self._single = single
            self._n_comp = n_comp
            self._state = state
        else:
            idx = self._check_runs(runs, n_runs, n_comp)
            self._checked_state().put(idx, state)
        return self.estimate()

    def step(
        self,
        measurement: np.ndarray,
        acceleration: np.ndarray,
        *,
        runs: np.ndarray | None = None,
        road_points: np.ndarray | None = None,
    ) -> Estimate:
        """Predict with the IMU input, update with the measurements, reweight, prune.

        Non-finite entries (NaN, +-inf) are missing: a measurement's row of the
        update is skipped, an IMU input is taken as 0 with the large process
        noise ``missing_acceleration_std`` (so is one beyond
        ``max_acceleration``). Outliers are gated (``innovation_gate``) and
        the steering channel is off below ``min_speed`` (:class:`FilterSettings`).

        Args:
            measurement: (3,) or (R, 3) [speed, camera, steering] at k.
            acceleration: (2,) or (R, 2) IMU (a_x, a_y) over the sample that ended at k.
            runs: step only these runs (indices or boolean mask) of the batch.
            road_points: (R, 4) or (4,) lane-centre points ahead at k (m; see
                :meth:`reset`); None: a straight road.
        """
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        state = self._state
        z = np.asarray(measurement, dtype=np.float64)
        acc = np.asarray(acceleration, dtype=np.float64)
        if z.ndim == 1:
            z = z.reshape(1, -1)
        if acc.ndim == 1:
            acc = acc.reshape(1, -1)
        if runs is None:
            self.advance(z, acc, road_points)
        else:
            idx = self._check_runs(runs, z.shape[0], None)
            if acc.shape != (idx.size, 2) or z.shape != (idx.size, 3):
                raise ValueError("measurement and acceleration must have one row per selected run")
            points = road_point_rows(road_points, idx.size)
            state.put(idx, self._step(state.take(idx), z, acc, points))
        return self.estimate()

    def advance(
        self,
        measurement: np.ndarray,
        acceleration: np.ndarray,
        road_points: np.ndarray | None = None,
        *,
        checked: bool = False,
    ) -> None:
        """:meth:`step` of the whole batch without building the :class:`Estimate`: the same
        rules on the same arrays, for loops that read :attr:`mixture_state` instead (the
        offline runner, :func:`estimators.offline.run_estimator`).

        Args:
            measurement: (R, 3) float64 [speed, camera, steering] at k.
            acceleration: (R, 2) float64 IMU (a_x, a_y).
            road_points: (R, 4) or (4,) road points at k (None: a straight road).
            checked: the caller checked the shapes and the road points already
                (:func:`estimators.arx_state_space.check_road_points` of the (R, 4) rows,
                e.g. once for a whole recording): they are used as given.
        """
        state = self._checked_state()
        if checked:
            self._state = self._step(state, measurement, acceleration, road_points)
            return
        z, acc = measurement, acceleration
        n_runs = state.log_w.shape[0]
        if z.shape != (n_runs, 3) or acc.shape != (n_runs, 2):
            raise ValueError(
                f"expected measurement ({self.num_runs}, 3) and acceleration "
                f"({self.num_runs}, 2), got {np.shape(measurement)} and "
                f"{np.shape(acceleration)}"
            )
        points = road_point_rows(road_points, z.shape[0])
        self._state = self._step(state, z, acc, points)

    @property
    def mixture_state(self) -> MixtureState:
        """The per-run state after the last reset or step, (R, ...) even for a single run
        (:class:`MixtureState`). Read only: a step replaces the record and never changes
        its arrays, so a reference taken now keeps this step's values."""
        return self._checked_state()

    def estimate(self) -> Estimate:
        """The current estimate (mixture and hypotheses)."""
        if self._state is None:
            raise RuntimeError("call reset() first")
        state = self._state
        if self._single:
            x = state.x  # (C, n) for the single run
            log_w = state.log_w[0]
            w = np.exp(log_w)
            return Estimate.of_fields(
                mean=w.dot(x),
                component_means=x,
                component_covariances=state.P,
                weights=w,
                log_weights=log_w,
                most_likely=int(log_w.argmax()),
                hypotheses=state.hypotheses[0],
                state_names=self.state_names,
                decision=DECISIONS[state.decision.item()],
                model_error=state.model_error.item(),
                innovation_autocorrelation=state.autocorrelation.item(),
                evidence_scale=state.evidence_scale.item(),
            )
        n_runs, n_comp = state.log_w.shape
        n = state.x.shape[1]
        w = np.exp(state.log_w)
        x = state.x.reshape(n_runs, n_comp, n)
        return Estimate(
            (w[:, None, :] @ x)[:, 0, :],
            x,
            state.P.reshape(n_runs, n_comp, n, n),
            w,
            state.log_w,
            np.argmax(state.log_w, axis=1),
            state.hypotheses,
            self.state_names,
            decision_names(state.decision),
            state.model_error,
            state.autocorrelation,
            state.evidence_scale,
        )

    # ------------------------------------------------------------- internals
    def _checked_state(self) -> MixtureState:
        if self._state is None:
            raise RuntimeError("call reset() first")
        return self._state

    def _run_view(self, array: np.ndarray) -> np.ndarray:
        return array[0].copy() if self._single else array.copy()

    def _check_runs(self, runs: np.ndarray, n_rows: int, n_comp: int | None) -> np.ndarray:
        if self._state is None:
            raise RuntimeError("reset the whole batch (runs=None) before resetting single runs")
        idx = np.asarray(runs)
        if idx.dtype == bool:
            if idx.shape != (self.num_runs,):
                raise ValueError(f"a boolean runs mask must have shape ({self.num_runs},)")
            idx = np.flatnonzero(idx)
        idx = idx.astype(np.intp).ravel()
        if idx.size != n_rows:
            raise ValueError(f"got {n_rows} measurement rows for {idx.size} selected runs")
        if idx.size and (idx.min() < 0 or idx.max() >= self.num_runs):
            raise IndexError(f"runs must index the batch of {self.num_runs} runs")
        if n_comp is not None and n_comp != self._n_comp:
            raise ValueError(f"the batch has {self._n_comp} hypotheses per run; got {n_comp}")
        return idx

    def _initial_state(
        self, z: np.ndarray, hyp: np.ndarray, log_w: np.ndarray, points: np.ndarray | None
    ) -> MixtureState:
        """The state at reset: x_i(0) from :meth:`FilterMatrices.initial_state` (each
        hypothesis' own bearings), ``P_i(0)`` the prior covariance, ``w_i`` the prior, the
        steering channel off when ``z_1 < min_speed``, ``z_1 > steering_max_speed`` or the
        road ahead too curved, and the decision ``decided`` when ``max_i w_i`` reaches
        ``decision_threshold``."""
        n_runs, n_comp = hyp.shape
        if points is None:
            x = self.matrices.initial_state(z, hyp)
        else:
            x = self.matrices.initial_state(z, hyp, road_points=points)
        n = x.shape[-1]
        cov: np.ndarray = np.empty(x.shape + (n,))
        cov[:] = self.matrices.initial_covariance
        steering = z[:, 2] * self.settings.steering_ratio
        log_decision_threshold = math.log(self.settings.decision_threshold)
        state = MixtureState(
            x=x.reshape(-1, n),
            P=cov.reshape(-1, n, n),
            log_w=log_w,
            active=np.isfinite(log_w),
            hypotheses=hyp.copy(),
            steering=np.where(np.isfinite(steering), steering, np.nan),
            channel_off=self._channel_off_at_reset(z, points),
            gated=np.zeros((n_runs, 3), dtype=bool),
            gated_count=np.zeros((n_runs, 3), dtype=np.int64),
            evidence=initial_evidence_state(log_w),
            decision=np.where(log_w.max(axis=1) >= log_decision_threshold, DECIDED, UNDECIDED),
            model_error=np.full(n_runs, np.nan),
            autocorrelation=np.full(n_runs, np.nan),
            evidence_scale=np.ones(n_runs),
            innovation_log_w=log_w.copy(),
            normalized_innovation=np.full((n_runs, n_comp, 3), np.nan),
            road_points=points,
            straight_points=self._straight_points,
        )
        if self._aim_rate:
            state.evidence.update(initial_aim_offsets(x[..., 1].reshape(n_runs, n_comp)))
        return state

    # ------------------------------------------------------------ the rules
    def _step(
        self,
        state: MixtureState,
        z: np.ndarray,
        acc: np.ndarray,
        points: np.ndarray | None,
    ) -> MixtureState:
        """One step k-1 -> k of the runs of ``state``: the rules in order (class docstring);
        ``points`` are the road points at k (None: straight)."""
        if self._feedforward and points is not None:
            z = self._without_feedforward(z, points)
        z, all_observed = self._observed(z)
        acc, missing_acc = _plausible_acceleration(acc, self._max_acceleration)
        steering = z[:, 2]
        off = state.channel_off
        any_off = any_true(off)
        x_pred, cov_pred = self._predict(state, acc, off if any_off else None, missing_acc)
        if any_off:
            z, all_observed = _without_steering(z, off), False
        x_post, cov_post, log_lik, gated, normalized = self._update(
            x_pred, cov_pred, z, all_observed, state.log_w, points, self._refused_steering(state)
        )
        normalized = normalized.reshape(*state.log_w.shape, 3)
        all_active = all_true(state.active)
        innovation_log_w, log_w, evidence, stats = self._weigh(
            state,
            all_active,
            log_lik,
            normalized,
            moved_aim_offsets(state.evidence, x_post[:, 1], self._aim_rate, self._rule.aim_near)
            if self._aim_rate
            else None,
        )
        if not all_active:
            x_post, cov_post = _freeze_pruned(state, x_post, cov_post)
        active, log_w = self._prune(state.active, all_active, log_w)
        channel_off, restart = self._switch_channel(off, any_off, x_post, log_w, steering, points)
        if restart is not None and any_true(restart):
            self._restart_memory(x_post, cov_post, restart, active, steering, points)
        any_gated = any_true(gated)
        if any_gated:
            steering = _memory_steering(steering, gated, restart)
        return MixtureState(
            x=x_post,
            P=cov_post,
            log_w=log_w,
            active=active,
            hypotheses=state.hypotheses,
            steering=steering,
            channel_off=channel_off,
            gated=gated,
            gated_count=state.gated_count + gated if any_gated else state.gated_count,
            evidence=evidence,
            decision=stats["decision"],
            model_error=stats["model_error"],
            autocorrelation=stats["autocorrelation"],
            evidence_scale=stats["evidence_scale"],
            innovation_log_w=innovation_log_w,  # for channel_nis, computed when asked
            normalized_innovation=normalized,
            road_points=points,
            straight_points=state.straight_points,
        )

    def _without_feedforward(self, z: np.ndarray, points: np.ndarray | None) -> np.ndarray:
        """The measurements (R, 3) with the curvature feed-forward taken off the steering
        (measured units): ``delta - G kappa / steering_ratio``, kappa of the road points
        (``FilterSettings.steering_curvature_feedforward`` G; docs/design.md §8.28); ``z``
        itself without it or on a straight road."""
        if self._feedforward == 0.0 or points is None:
            return z
        z = np.array(z, dtype=np.float64, copy=True)
        kappa = road_curvature_ahead(points, z.shape[0])
        z[:, 2] -= (self._feedforward / self.settings.steering_ratio) * kappa
        return z

    def _observed(self, z: np.ndarray) -> tuple[np.ndarray, bool]:
        """Missing measurements: ``z`` (R, 3) with the steering in model units
        (``z_3 steering_ratio``; NaN without a model) and every non-finite entry NaN
        (missing: its row of H, nu and R is dropped), and whether none is missing."""
        z = z * self._measurement_scale
        all_observed = all_finite(z)
        if not all_observed:  # NaN and +-inf are missing
            z = np.where(np.isfinite(z), z, np.nan)
        return z, all_observed

    def _predict(
        self,
        state: MixtureState,
        acc: np.ndarray,
        held: np.ndarray | None,
        missing_acceleration: bool | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Predict (paper eq. 11 and 13, :meth:`FilterMatrices.predict_batch`)::

            x_i(k|k-1) = F(x_i(k-1|k-1)) + B_D a(k) [+ J (z_3(k-1) - h_3(x_i(k-1|k-1)))]
            P_i(k|k-1) = F'_i P_i(k-1|k-1) F'_i^T + Q

        with the road points of k-1; the memory of the ``held`` runs (R,) bool (steering
        channel off) is held, and a NaN ``a`` (missing) is 0 with its large process noise
        (``missing_acceleration``: whether ``acc`` has a NaN, if known)."""
        return self.matrices.predict_batch(
            state.x,
            state.P,
            acc,
            state.steering,
            state.log_w.shape[1],
            road_points=state.road_points,
            held=held,
            missing_acceleration=missing_acceleration,
        )

    def _update(
        self,
        x_pred: np.ndarray,
        cov_pred: np.ndarray,
        z: np.ndarray,
        all_observed: bool,
        log_w: np.ndarray,
        points: np.ndarray | None,
        drop_steering: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Update with the outlier gate (paper eq. 15-18, Joseph form;
        :meth:`FilterMatrices.gated_update_batch`; the states of the ``drop_steering`` runs
        (R,) updated without their steering, which is still scored)::

            nu_i = z(k) - h(x_i(k|k-1)),  S_i = H_i P_i H_i^T + R,  K_i = P_i H_i^T S_i^-1
            x_i  = x_i + K_i nu_i,  P_i = (I - K_i H_i) P_i (I - K_i H_i)^T + K_i R K_i^T

        Gate: channel c of a run is dropped for all its hypotheses when
        ``min_i [nu_ic^2 / S_i,cc + 2 ln(w_max / w_i)] > innovation_gate^2``.

        Returns:
            x(k|k), P(k|k), log N(nu_i; 0, S_i), the (R, 3) gated channels and the
            normalized innovations ``nu_c / sqrt(S_cc)`` (R C, 3).
        """
        return self.matrices.gated_update_batch(
            x_pred,
            cov_pred,
            z,
            log_w.shape[1],
            all_observed,
            road_points=points,
            gate=self.settings.innovation_gate,
            log_weights=log_w,
            drop_steering=drop_steering,
        )

    def _refused_steering(self, state: MixtureState) -> np.ndarray | None:
        """(R,) the runs in ``model_mismatch`` after the last step, whose steering updates no
        state (``FilterSettings.mismatch_drops_steering``; None: none, or the setting off)."""
        if not self._drops_steering or not any_equal(state.decision, MODEL_MISMATCH):
            return None
        return state.decision == MODEL_MISMATCH

    def _weigh(
        self,
        state: MixtureState,
        all_active: bool,
        log_lik: np.ndarray,
        normalized: np.ndarray,
        evidence: dict[str, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Evidence (paper eq. 19, tempered by the consistency checks of
        :func:`estimators.evidence.weigh_evidence`; pruned hypotheses have weight 0)::

            log w_i = log w_i + l_i / tau,   l_i = -1/2 (nu_i^T S_i^-1 nu_i + log det S_i + m log 2 pi)
            log w_i = log w_i - logsumexp_j(log w_j)

        ``evidence``: the rule's per-run arrays to weigh with (default the state's; the step
        passes them with the aim cap's offsets moved). Returns the log weights before the
        update (pruned: -inf), the new log weights (R, C),
        the rule's new statistics and its per-run ``decision``, ``model_error``,
        ``autocorrelation`` and ``evidence_scale``."""
        log_w = state.log_w if all_active else np.where(state.active, state.log_w, -np.inf)
        new_log_w, evidence, stats = weigh_evidence(
            self._rule,
            log_w,
            log_lik.reshape(log_w.shape),
            normalized[:, :, 2],
            state.evidence if evidence is None else evidence,
        )
        return log_w, new_log_w, evidence, stats

    def _prune(
        self, active: np.ndarray, all_active: bool, log_w: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pruning: an active hypothesis other than its run's most likely one with
        ``w_i < prune_threshold`` is pruned (inactive; weight 0 from now on), and the
        weights of a run that pruned are normalized again,
        ``log w_i = log w_i - logsumexp_{j active} log w_j``. Returns (active, log_w)."""
        if self._log_prune_threshold is None:
            return active, log_w
        newly = log_w < self._log_prune_threshold
        if not all_active:
            newly &= active
        if not any_true(newly):
            return active, log_w
        newly[np.arange(newly.shape[0]), log_w.argmax(axis=1)] = False
        new_active = active & ~newly
        # renormalize only the runs that pruned: a run's weights never depend on
        # what the other runs of the batch did
        pruned = newly.any(axis=1, keepdims=True)
        renormalized = normalize_log_weights(np.where(new_active, log_w, -np.inf), log_w)
        return new_active, np.where(pruned, renormalized, log_w)

    def _switch_channel(
        self,
        off: np.ndarray,
        any_off: bool,
        x: np.ndarray,
        log_w: np.ndarray,
        steering: np.ndarray,
        points: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """The steering channel off by speed or curvature, for step k+1::

            v     = sum_i w_i sqrt(v_x,i^2 + v_y,i^2)                   (x(k|k), w(k))
            off   = v < min_speed  or  v > steering_max_speed  or  curved(k)
            off   = off  or  (off(k-1) and z_3(k) missing)    (leave only with a reading)

        where ``curved`` is :meth:`_curved`. Returns the new ``off`` (R,) and the runs
        whose memory restarts, ``off(k-1) and not off and z_3(k) finite`` (None: none can).
        The speed test is skipped when bounds on every hypothesis' speed already decide
        it (``|v_i| >= v_x,i``; ``|v_i| <= |v_x,i| + |v_y,i|``)."""
        speed_check = self._min_speed > 0 and (any_off or min_below(x[:, VX], self._min_speed))
        if not speed_check and self._max_speed < math.inf:
            fastest = np.abs(x[:, VX]).max() + np.abs(x[:, VY]).max()
            speed_check = any_off or fastest > self._max_speed
        curved = self._curved(points)
        if not speed_check and curved is None:
            return off, None
        if speed_check:
            speed = np.hypot(x[:, VX], x[:, VY]).reshape(log_w.shape)
            mixture_speed = np.einsum("rc,rc->r", np.exp(log_w), speed)
            new_off = (mixture_speed < self._min_speed) | (mixture_speed > self._max_speed)
        else:
            new_off = np.zeros(log_w.shape[0], dtype=bool)
        if curved is not None:
            new_off = new_off | curved
        if not any_off:
            return new_off, None
        restart = off & ~new_off & ~np.isnan(steering)
        return new_off | (off & np.isnan(steering)), restart

    def _curved(self, points: np.ndarray | None) -> np.ndarray | None:
        """(R,) bool: the road ahead curves more than ``steering_curvature_limit`` (None when
        no run can: a straight road or no limit). ``kappa = 2 |dy| / (dx^2 + dy^2)`` is the
        curvature of the arc from the car's station to the near and the far point."""
        if points is None or not math.isfinite(self._curvature_limit):
            return None
        dx, dy = points[:, 0::2], points[:, 1::2]
        kappa = 2.0 * np.abs(dy) / (dx * dx + dy * dy)
        return kappa.max(axis=1) > self._curvature_limit

    def _channel_off_at_reset(self, z: np.ndarray, points: np.ndarray | None) -> np.ndarray:
        """(R,) bool: runs that start with the steering channel off (slow or curved)."""
        off = ((z[:, 0] < self._min_speed) & (self._min_speed > 0)) | (z[:, 0] > self._max_speed)
        curved = self._curved(points)
        return off if curved is None else off | curved

    def _restart_memory(
        self,
        x: np.ndarray,
        cov: np.ndarray,
        runs: np.ndarray,
        active: np.ndarray,
        steering: np.ndarray,
        points: np.ndarray | None,
    ) -> None:
        """Memory restart, in place: the memory states of the active hypotheses of ``runs``
        (R,) bool restart as at reset (:meth:`FilterMatrices.initial_state`)::

            m_i = steady_memory(z_3(k), x_i(k|k)),  P_mm = memory_std^2 I,  P_m,phys = 0

        the constant-past memory of the measured ``steering`` (R,) and each hypothesis'
        own bearings, uncorrelated with the vehicle states (with the driver's preferred
        offset p: correlated through p, :meth:`FilterMatrices.restart_memory_covariance`)."""
        model = self.model
        if not model.n_memory:
            return
        rows = (runs[:, None] & active).reshape(-1)
        flat = np.flatnonzero(rows)
        if not flat.size:
            return
        run_of = flat // active.shape[1]
        mem = model.memory_slice
        x[flat, mem] = model.steady_memory(
            steering[run_of], x[flat], None if points is None else points[run_of]
        )
        cov[flat] = self.matrices.restart_memory_covariance(cov[flat])


def _without_steering(z: np.ndarray, off: np.ndarray) -> np.ndarray:
    """No steering evidence while the channel is off: a copy of ``z`` (R, 3) with
    ``z_3`` missing (NaN) in the ``off`` runs (R,) bool."""
    z = z.copy()
    z[off, 2] = np.nan
    return z


def _freeze_pruned(
    state: MixtureState, x: np.ndarray, cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pruned hypotheses stay frozen at their last posterior: ``x_i(k|k) = x_i(k-1|k-1)``,
    ``P_i(k|k) = P_i(k-1|k-1)`` where ``state.active`` is False."""
    keep = state.active.reshape(-1)
    return (
        np.where(keep[:, None], x, state.x),
        np.where(keep[:, None, None], cov, state.P),
    )


def _memory_steering(
    steering: np.ndarray, gated: np.ndarray, restart: np.ndarray | None
) -> np.ndarray:
    """The steering reading z_3(k) for the next prediction's memory update: NaN (none) where
    the steering channel was gated as an outlier (but kept where the memory just restarted
    from it)."""
    if not any_true(gated[:, 2]):
        return steering
    dropped = gated[:, 2] if restart is None else gated[:, 2] & ~restart
    return np.where(dropped, np.nan, steering)


def _plausible_acceleration(acc: np.ndarray, limit: float) -> tuple[np.ndarray, bool | None]:
    """The IMU input with non-finite entries and entries beyond +-``limit`` (m/s^2) set to NaN,
    and False when it has no NaN (None: it may have)."""
    if math.isinf(limit):
        if all_finite(acc):
            return acc, False
        return np.where(np.isfinite(acc), acc, np.nan), None
    if all_within(acc, limit):  # False with a NaN
        return acc, False
    return np.where(np.abs(acc) <= limit, acc, np.nan), None
