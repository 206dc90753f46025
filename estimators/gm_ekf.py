"""The Gaussian-mixture EKF with the human as advisor (paper section 4).

Vectorized over lane hypotheses and over many runs at once: states are
(runs, components, n), covariances (runs, components, n, n). Its settings
live in :mod:`estimators.settings`, its matrices and batched predict/update
in :mod:`estimators.filter_matrices`; both names are re-exported here.

Why this module is long: the filter's docstring states its equations, its robustness rules
and every deviation from the paper (as filterpy's filters do), and one step keeps those rules
(missing inputs, the outlier gate, the evidence rule, pruning, the steering channel off at low
speed or outside the model's road curvature) in one sequence a reader can follow; the
arithmetic itself is in :mod:`estimators.filter_matrices` and :mod:`estimators.evidence`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from estimators.arx_state_space import (
    N_PHYSICAL,
    VX,
    VY,
    ARXStateSpace,
    road_point_rows,
)
from estimators.base import Estimate, reset_inputs
from estimators.evidence import (
    DECIDED,
    EVIDENCE_STATE,
    UNDECIDED,
    EvidenceRule,
    decision_names,
    initial_evidence_state,
    normalize_log_weights,
    weigh_evidence,
)
from estimators.filter_matrices import FilterMatrices
from estimators.road_geometry import straight_road_points
from estimators.settings import FilterSettings
from hasa_env.steering.arx import ARXForm

__all__ = ["FilterSettings", "GaussianMixtureEKF", "FilterMatrices"]

_STEPPED = ("_log_w", "_active", "_steering", "_slow", "_gated_count", *EVIDENCE_STATE)
"""Per-run arrays of :class:`GaussianMixtureEKF` that a step reads (and may replace)."""


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
      as curved as those it was fitted on (:class:`FilterSettings`).

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

    # Per-run state, set by reset() (and replaced by step()) through setattr;
    # shapes: R runs, C hypotheses.
    _P: np.ndarray  # (R*C, n, n) covariances
    _points: np.ndarray | None  # (R, 4) road points of the last sample; None: straight
    _log_w: np.ndarray  # (R, C) log weights
    _active: np.ndarray  # (R, C) bool: not pruned
    _hyp: np.ndarray  # (R, C) hypotheses (m)
    _steering: np.ndarray  # (R,) last steering reading (model units; NaN: none)
    _slow: np.ndarray  # (R,) bool: steering channel off (low speed)
    _gated: np.ndarray  # (R, 3) bool: channels gated at the last step
    _gated_count: np.ndarray  # (R, 3) int
    _decision: np.ndarray  # (R,) int codes of estimators.evidence
    _model_error: np.ndarray  # (R,)
    _autocorrelation: np.ndarray  # (R,)
    _evidence_scale: np.ndarray  # (R,)
    _innovation_log_w: np.ndarray  # (R, C)
    _normalized_innovation: np.ndarray  # (R, C, 3)

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
        self.model = ARXStateSpace(steering_model, dt, decision_lag)
        self.matrices = FilterMatrices(self.model, settings)
        self.state_names = self.model.state_names
        threshold = settings.prune_threshold
        ratio = settings.steering_ratio if self.model.has_steering else np.nan
        self._measurement_scale = np.array([1.0, 1.0, ratio])
        self._log_prune_threshold = math.log(threshold) if threshold > 0 else None
        self._rule = EvidenceRule.from_settings(settings, self.model.dt)
        self._min_speed = settings.min_speed if self.model.has_steering else 0.0
        self._max_speed = settings.steering_max_speed if self.model.has_steering else math.inf
        self._curvature_limit = (
            settings.steering_curvature_limit if self.model.has_steering else math.inf
        )
        self._straight_points = straight_road_points(
            self.model.near_distance, self.model.far_distance
        )
        self._x: np.ndarray | None = None
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
        return 0 if self._x is None else self._log_w.shape[0]

    @property
    def gated_counts(self) -> np.ndarray:
        """Samples gated as outliers since reset, per run and channel
        [speed, camera, steering]: (R, 3) int (a single run: (3,))."""
        return self._run_view(self._gated_count)

    @property
    def last_gated(self) -> np.ndarray:
        """Channels gated at the last step, (R, 3) bool (a single run: (3,))."""
        return self._run_view(self._gated)

    @property
    def channel_nis(self) -> np.ndarray:
        """Normalized innovation squared of each channel [speed, camera, steering] at the
        last step, averaged over the hypotheses with their weights before the update,
        ``sum_i w_i nu_ic^2 / S_i,cc``: (R, 3) (a single run: (3,); NaN: channel not used).
        A consistent filter averages 1 per channel."""
        clipped = np.minimum(np.maximum(self._normalized_innovation, -1e3), 1e3)  # (NaN stays)
        nis = np.einsum("rc,rcm->rm", np.exp(self._innovation_log_w), clipped * clipped)
        return nis[0] if self._single else nis

    @property
    def low_speed(self) -> np.ndarray:
        """Runs whose steering channel is off (speed estimate below ``min_speed``, or the
        road ahead more curved than ``steering_curvature_limit``): (R,) bool (a single run:
        one bool)."""
        return self._run_view(self._slow)

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
        if points is None:
            x = self.matrices.initial_state(z, hyp)
        else:
            x = self.matrices.initial_state(z, hyp, road_points=points)
        n = x.shape[-1]
        cov: np.ndarray = np.empty(x.shape + (n,))
        cov[:] = self.matrices.initial_covariance
        x, cov = x.reshape(-1, n), cov.reshape(-1, n, n)
        steering = z[:, 2] * self.settings.steering_ratio
        steering = np.where(np.isfinite(steering), steering, np.nan)
        state = {
            "_log_w": log_w,
            "_active": np.isfinite(log_w),
            "_hyp": hyp.copy(),
            "_steering": steering,
            "_slow": self._channel_off_at_reset(z, points),
            "_gated": np.zeros((n_runs, 3), dtype=bool),
            "_gated_count": np.zeros((n_runs, 3), dtype=np.int64),
            **initial_evidence_state(log_w),
            "_decision": np.where(
                log_w.max(axis=1) >= math.log(self.settings.decision_threshold), DECIDED, UNDECIDED
            ),
            "_model_error": np.full(n_runs, np.nan),
            "_autocorrelation": np.full(n_runs, np.nan),
            "_evidence_scale": np.ones(n_runs),
            "_innovation_log_w": log_w.copy(),
            "_normalized_innovation": np.full((n_runs, n_comp, 3), np.nan),
        }
        if runs is None:
            self._single = single
            self._n_comp = n_comp
            self._x, self._P, self._points = x, cov, points
            for name, value in state.items():
                setattr(self, name, value)
        else:
            idx = self._check_runs(runs, n_runs, n_comp)
            assert self._x is not None  # (_check_runs raises before the first reset)
            flat = self._flat_index(idx)
            self._x, self._P = self._x.copy(), self._P.copy()
            self._x[flat], self._P[flat] = x, cov
            self._store_points(idx, points)
            for name, value in state.items():
                array = getattr(self, name).copy()
                array[idx] = value
                setattr(self, name, array)
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
        if self._x is None:
            raise RuntimeError("call reset() before step()")
        z = np.asarray(measurement, dtype=np.float64)
        acc = np.asarray(acceleration, dtype=np.float64)
        if z.ndim == 1:
            z = z.reshape(1, -1)
        if acc.ndim == 1:
            acc = acc.reshape(1, -1)
        if runs is None:
            if z.shape != (self._log_w.shape[0], 3) or acc.shape != (self._log_w.shape[0], 2):
                raise ValueError(
                    f"expected measurement ({self.num_runs}, 3) and acceleration "
                    f"({self.num_runs}, 2), got {np.shape(measurement)} and "
                    f"{np.shape(acceleration)}"
                )
            points = road_point_rows(road_points, z.shape[0])
            run_state = {name: getattr(self, name) for name in _STEPPED}
            self._x, self._P, new = self._step(
                self._x, self._P, run_state, self._points, z, acc, points
            )
            for name, value in new.items():
                setattr(self, name, value)
            self._points = points
        else:
            idx = self._check_runs(runs, z.shape[0], None)
            if acc.shape != (idx.size, 2) or z.shape != (idx.size, 3):
                raise ValueError("measurement and acceleration must have one row per selected run")
            points = road_point_rows(road_points, idx.size)
            flat = self._flat_index(idx)
            run_state = {name: getattr(self, name)[idx] for name in _STEPPED}
            previous = None if self._points is None else self._points[idx]
            x, cov, new = self._step(
                self._x[flat], self._P[flat], run_state, previous, z, acc, points
            )
            self._x, self._P = self._x.copy(), self._P.copy()
            self._x[flat], self._P[flat] = x, cov
            for name, value in new.items():
                array = getattr(self, name).copy()
                array[idx] = value
                setattr(self, name, array)
            self._store_points(idx, points)
        return self.estimate()

    def estimate(self) -> Estimate:
        """The current estimate (mixture and hypotheses)."""
        if self._x is None:
            raise RuntimeError("call reset() first")
        n_runs, n_comp = self._log_w.shape
        n = self._x.shape[1]
        w = np.exp(self._log_w)
        if self._single:
            x = self._x  # (C, n) for the single run
            log_w = self._log_w[0]
            return Estimate(
                w[0] @ x,
                x,
                self._P,
                w[0],
                log_w,
                int(np.argmax(log_w)),
                self._hyp[0],
                self.state_names,
                decision_names(int(self._decision[0])),
                float(self._model_error[0]),
                float(self._autocorrelation[0]),
                float(self._evidence_scale[0]),
            )
        x = self._x.reshape(n_runs, n_comp, n)
        return Estimate(
            (w[:, None, :] @ x)[:, 0, :],
            x,
            self._P.reshape(n_runs, n_comp, n, n),
            w,
            self._log_w,
            np.argmax(self._log_w, axis=1),
            self._hyp,
            self.state_names,
            decision_names(self._decision),
            self._model_error,
            self._autocorrelation,
            self._evidence_scale,
        )

    # ------------------------------------------------------------- internals
    def _run_view(self, array: np.ndarray) -> np.ndarray:
        if self._x is None:
            raise RuntimeError("call reset() first")
        return array[0].copy() if self._single else array.copy()

    def _store_points(self, idx: np.ndarray, points: np.ndarray | None) -> None:
        """Keep the road points of runs ``idx`` (None: straight) for their next prediction."""
        if points is None and self._points is None:
            return
        stored = (
            np.tile(self._straight_points, (self.num_runs, 1))
            if self._points is None
            else self._points.copy()
        )
        stored[idx] = self._straight_points if points is None else points
        self._points = stored

    def _flat_index(self, idx: np.ndarray) -> np.ndarray:
        c = self._n_comp
        return (idx[:, None] * c + np.arange(c)).ravel()

    def _check_runs(self, runs: np.ndarray, n_rows: int, n_comp: int | None) -> np.ndarray:
        if self._x is None:
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

    def _step(
        self,
        x: np.ndarray,
        cov: np.ndarray,
        run: dict[str, np.ndarray],
        previous_points: np.ndarray | None,
        z: np.ndarray,
        acc: np.ndarray,
        points: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """One step of runs whose per-run state ``run`` holds the :data:`_STEPPED` arrays;
        returns x(k|k), P(k|k) and the new values of those that changed (and ``_gated``)."""
        mats = self.matrices
        settings = self.settings
        log_w, active, slow = run["_log_w"], run["_active"], run["_slow"]
        n_runs, n_comp = log_w.shape
        z = z * self._measurement_scale  # steering in model units (NaN without a model)
        all_observed = math.isfinite(z.sum())
        if not all_observed:  # NaN and +-inf are missing
            z = np.where(np.isfinite(z), z, np.nan)
        acc = _plausible_acceleration(acc, settings.max_acceleration)
        steering = z[:, 2]
        any_slow = bool(slow.any())
        x_pred, cov_pred = mats.predict_batch(
            x,
            cov,
            acc,
            run["_steering"],
            n_comp,
            road_points=previous_points,
            held=slow if any_slow else None,
        )
        if any_slow:  # no steering evidence at low speed
            z = z.copy()
            z[slow, 2] = np.nan
            all_observed = False
        x_post, cov_post, log_lik, gated, normalized = mats.gated_update_batch(
            x_pred,
            cov_pred,
            z,
            n_comp,
            all_observed,
            road_points=points,
            gate=settings.innovation_gate,
            log_weights=log_w,
        )
        # ---- weights (log space), through the consistency checks of estimators.evidence
        all_active = active.all()
        normalized = normalized.reshape(n_runs, n_comp, 3)
        evidence_log_w = log_w if all_active else np.where(active, log_w, -np.inf)
        new_log_w, evidence, stats = weigh_evidence(
            self._rule,
            evidence_log_w,
            log_lik.reshape(log_w.shape),
            normalized[:, :, 2],
            {name: run[name] for name in EVIDENCE_STATE},
        )
        # ---- prune
        if not all_active:
            # pruned earlier: frozen at their last posterior
            keep = active.reshape(-1)
            x_post = np.where(keep[:, None], x_post, x)
            cov_post = np.where(keep[:, None, None], cov_post, cov)
        new_active = active
        if self._log_prune_threshold is not None:
            newly = new_log_w < self._log_prune_threshold
            if not all_active:
                newly &= active
            if newly.any():
                newly[np.arange(newly.shape[0]), new_log_w.argmax(axis=1)] = False
                new_active = active & ~newly
                # renormalize only the runs that pruned: a run's weights never depend on
                # what the other runs of the batch did
                pruned = newly.any(axis=1, keepdims=True)
                new_log_w = np.where(
                    pruned,
                    normalize_log_weights(np.where(new_active, new_log_w, -np.inf), new_log_w),
                    new_log_w,
                )
        # ---- steering channel off below min_speed or on a road ahead more curved than
        # steering_curvature_limit; its memory restarts when the channel comes back
        new_slow = slow
        restart = None
        speed_check = self._min_speed > 0 and (any_slow or x_post[:, VX].min() < self._min_speed)
        if not speed_check and self._max_speed < math.inf:
            # (|v_i| <= |v_x,i| + |v_y,i| <= steering_max_speed for all i: no run is too fast)
            fastest = np.abs(x_post[:, VX]).max() + np.abs(x_post[:, VY]).max()
            speed_check = any_slow or fastest > self._max_speed
        curved = self._curved(points)
        if speed_check or curved is not None:
            if speed_check:
                # (|v_i| >= v_x,i >= min_speed for all i: no run is slow)
                speed = np.hypot(x_post[:, VX], x_post[:, VY]).reshape(log_w.shape)
                mixture_speed = np.einsum("rc,rc->r", np.exp(new_log_w), speed)
                new_slow = (mixture_speed < self._min_speed) | (mixture_speed > self._max_speed)
            else:
                new_slow = np.zeros(n_runs, dtype=bool)
            if curved is not None:
                new_slow = new_slow | curved
            if any_slow:
                # leave the mode only with a steering reading to restart from
                restart = slow & ~new_slow & ~np.isnan(steering)
                new_slow = new_slow | (slow & np.isnan(steering))
        if restart is not None and restart.any():
            self._restart_memory(x_post, cov_post, restart, new_active, steering, points)
        any_gated = bool(gated.any())
        if any_gated and gated[:, 2].any():  # an outlier must not enter the next memory update
            dropped = gated[:, 2] if restart is None else gated[:, 2] & ~restart
            steering = np.where(dropped, np.nan, steering)
        new = {
            "_log_w": new_log_w,
            "_active": new_active,
            "_steering": steering,
            "_slow": new_slow,
            "_gated": gated,
            **evidence,
            "_decision": stats["decision"],
            "_model_error": stats["model_error"],
            "_autocorrelation": stats["autocorrelation"],
            "_evidence_scale": stats["evidence_scale"],
            "_innovation_log_w": evidence_log_w,  # for channel_nis, computed when asked
            "_normalized_innovation": normalized,
        }
        if any_gated:
            new["_gated_count"] = run["_gated_count"] + gated
        return x_post, cov_post, new

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
        """In place: the memory states of the active hypotheses of ``runs`` (R,) bool
        restart as at reset (:meth:`FilterMatrices.initial_state`): the
        constant-past memory of the measured ``steering`` (R,) and each
        hypothesis' own bearings, covariance ``memory_std^2 I``, uncorrelated."""
        model = self.model
        if not model.n_memory:
            return
        rows = (runs[:, None] & active).reshape(-1)
        flat = np.flatnonzero(rows)
        if not flat.size:
            return
        run_of = flat // self._n_comp
        mem = slice(N_PHYSICAL, model.n_states)
        x[flat, mem] = model.steady_memory(
            steering[run_of], x[flat], None if points is None else points[run_of]
        )
        cov[flat, mem, :] = 0.0
        cov[flat, :, mem] = 0.0
        cov[flat, mem, mem] = self.matrices.initial_covariance[mem, mem]


def _plausible_acceleration(acc: np.ndarray, limit: float) -> np.ndarray:
    """The IMU input with non-finite entries and entries beyond +-``limit`` (m/s^2) set to NaN."""
    if math.isinf(limit):
        if math.isfinite(acc.sum()):
            return acc
        return np.where(np.isfinite(acc), acc, np.nan)
    if np.abs(acc).max() <= limit:  # False with a NaN
        return acc
    return np.where(np.abs(acc) <= limit, acc, np.nan)
