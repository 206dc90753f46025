"""Reference Gaussian-mixture EKF on filterpy's ``ExtendedKalmanFilter``.

Same model, noise, initialisation, weighting and pruning as
:class:`estimators.gm_ekf.GaussianMixtureEKF`, written the plain way: one
:class:`filterpy.kalman.ExtendedKalmanFilter` per hypothesis and per run,
fed by the model functions of :class:`estimators.arx_state_space.ARXStateSpace`
(transition, exact Jacobians, measurement). It cross-checks the fast filter
in the tests and serves users who prefer filterpy. It is much slower.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from scipy.special import logsumexp

from estimators.arx_state_space import road_curvature_ahead, road_point_rows
from estimators.base import Estimate, reset_inputs
from estimators.evidence import (
    AIM_OFFSET,
    AIM_REACH,
    DECIDED,
    EVIDENCE_STATE,
    MODEL_MISMATCH,
    UNDECIDED,
    EvidenceRule,
    aim_offset_rate,
    decision_names,
    initial_aim_offsets,
    initial_evidence_state,
    weigh_evidence,
)
from estimators.filter_matrices import FilterMatrices, filter_model
from estimators.settings import FilterSettings
from hasa_env.steering.arx import ARXForm

__all__ = ["FilterpyGMEKF", "ARXExtendedKalmanFilter"]


class ARXExtendedKalmanFilter(ExtendedKalmanFilter):
    """filterpy's EKF with the augmented model's nonlinear prediction.

    ``predict(u)`` with ``u = (a_x, a_y, z_3, held, *road_points)``: the IMU
    input, the steering measured at k (model units, NaN if missing), whether
    the memory is held (below ``min_speed``: 1, else 0) and, optionally, the
    road points at k (4 values). It sets ``F`` and ``Q`` to the (decorrelated,
    see :class:`estimators.gm_ekf.FilterMatrices`) Jacobian and process noise,
    then filterpy propagates ``P = F P F^T + Q``.
    """

    x: np.ndarray  # (n, 1) state (filterpy's attribute)

    def __init__(self, matrices: FilterMatrices) -> None:
        model = matrices.model
        super().__init__(dim_x=model.n_states, dim_z=3, dim_u=3)
        self.matrices = matrices

    def predict_x(self, u: Any = 0) -> None:
        mats = self.matrices
        model = mats.model
        x = self.x[:, 0]
        acceleration = np.asarray(u[:2], dtype=np.float64)
        steering = float(u[2])
        held = bool(u[3]) or (mats.unstable_memory and math.isnan(steering))
        points = np.asarray(u[4:8], dtype=np.float64) if len(u) > 4 else None
        missing_acc = bool(np.isnan(acceleration).any())
        acceleration = np.where(np.isnan(acceleration), 0.0, acceleration)
        if held:
            jac = model.held_memory_transition_matrix()
            x_new = jac @ x + model.input_matrix() @ acceleration
            q = mats.process_noise_vehicle
        else:
            x_new = model.transition(x, acceleration, points)
            jac = model.transition_jacobian(x, points)
            q = mats.process_noise
            if mats.decorrelates and not math.isnan(steering):
                gain = mats.steering_gain
                x_new = x_new + gain * (steering - model.predicted_steering(x, points))
                jac = jac - np.outer(gain, model.measurement_jacobian(x, points)[2])
                q = mats.process_noise_decorrelated
        if missing_acc:
            q = q + mats.process_noise_missing_acceleration
        if mats.coloured_error_index is not None:
            q = q.copy()
            eps = mats.coloured_error_index
            q[eps, eps] += float(mats.coloured_error_process_var(np.array(x[0])))
        self.F = jac
        self.Q = q
        self.x = x_new[:, None]


class FilterpyGMEKF:
    """The Gaussian-mixture EKF built from filterpy EKFs (reference implementation).

    Same interface and results as :class:`estimators.gm_ekf.GaussianMixtureEKF`
    (see it for the equations; paper eq. 11-19): filterpy's
    ``ExtendedKalmanFilter.update`` uses the Joseph form and its
    ``log_likelihood`` the full multivariate normal of the innovation. Missing
    (non-finite) measurements drop their rows from z, H and R; so do the
    channels the outlier gate rejects and, below ``min_speed``, the steering
    (the rules of :class:`estimators.settings.FilterSettings`, written out per
    run and hypothesis).

    Args:
        steering_model: the steering model's ARX description (None: no steering).
        settings: :class:`estimators.settings.FilterSettings`.
        dt: sample time (s); default ``steering_model.dt``.
        decision_lag: see :class:`estimators.gm_ekf.GaussianMixtureEKF`.
        **overrides: fields of the settings to replace.
    """

    uses_true_bias = False

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
        self.model = filter_model(steering_model, settings, dt, decision_lag)
        self.matrices = FilterMatrices(self.model, settings)
        self.state_names = self.model.state_names
        self._filters: list[list[ARXExtendedKalmanFilter | None]] | None = None
        self._single = False
        self._rule = EvidenceRule.from_settings(settings, self.model.dt)
        self._aim_rate = aim_offset_rate(settings, self.model.dt, self.model.has_steering)
        if not self._aim_rate:
            self._rule = replace(self._rule, aim_variance=0.0)

    @property
    def dt(self) -> float:
        return self.model.dt

    @property
    def num_runs(self) -> int:
        return 0 if self._filters is None else len(self._filters)

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
        """See :meth:`estimators.gm_ekf.GaussianMixtureEKF.reset`."""
        z, single, hyp, log_w = reset_inputs(measurement, hypotheses, prior)
        n_runs, n_comp = hyp.shape
        points = road_point_rows(road_points, n_runs)
        z = self._without_feedforward(z, points)
        x0 = self.matrices.initial_state(z, hyp, road_points=points)
        banks = [self._new_bank(x0[r], log_w[r]) for r in range(n_runs)]
        steering = z[:, 2] * self.settings.steering_ratio
        steering = np.where(np.isfinite(steering), steering, np.nan)
        min_speed = self.settings.min_speed if self.model.has_steering else 0.0
        slow = (z[:, 0] < min_speed) & (min_speed > 0)
        if points is None:
            points = np.full((n_runs, 4), np.nan)  # NaN: a straight road
        if runs is None:
            self._single = single
            self._filters, self._log_w, self._hyp, self._steering = (
                banks,
                log_w,
                hyp.copy(),
                steering,
            )
            self._points, self._slow = points.copy(), slow
            self._gated_count = np.zeros((n_runs, 3), dtype=np.int64)
            self._gated = np.zeros((n_runs, 3), dtype=bool)
            self._evidence = self._initial_evidence(log_w, x0)
            self._stats = {
                "decision": np.where(
                    log_w.max(axis=1) >= math.log(self.settings.decision_threshold),
                    DECIDED,
                    UNDECIDED,
                ),
                "model_error": np.full(n_runs, np.nan),
                "autocorrelation": np.full(n_runs, np.nan),
                "evidence_scale": np.ones(n_runs),
            }
            self._last_x = x0.copy()
            self._last_P = np.broadcast_to(
                self.matrices.initial_covariance, x0.shape + (x0.shape[-1],)
            ).copy()
        else:
            if self._filters is None:
                raise RuntimeError("reset the whole batch (runs=None) before resetting single runs")
            idx = (
                np.flatnonzero(runs)
                if np.asarray(runs).dtype == bool
                else np.asarray(runs, dtype=np.intp)
            )
            for j, r in enumerate(idx):
                self._filters[r] = banks[j]
                self._log_w[r] = log_w[j]
                self._hyp[r] = hyp[j]
                self._steering[r] = steering[j]
                self._points[r] = points[j]
                self._slow[r] = slow[j]
                self._gated_count[r] = 0
                self._gated[r] = False
                for name, value in self._initial_evidence(log_w[j : j + 1], x0[j : j + 1]).items():
                    self._evidence[name][r] = value[0]
                self._stats["decision"][r] = (
                    DECIDED
                    if log_w[j].max() >= math.log(self.settings.decision_threshold)
                    else UNDECIDED
                )
                self._stats["model_error"][r] = np.nan
                self._stats["autocorrelation"][r] = np.nan
                self._stats["evidence_scale"][r] = 1.0
                self._last_x[r] = x0[j]
                self._last_P[r] = self.matrices.initial_covariance
        return self.estimate()

    def _without_feedforward(self, z: np.ndarray, points: np.ndarray | None) -> np.ndarray:
        """The first measurements (R, 3) with the curvature feed-forward taken off the
        steering (measured units; docs/design.md §8.28)."""
        gain = self.settings.steering_curvature_feedforward
        if not gain or points is None:
            return z
        z = z.copy()
        z[:, 2] -= gain / self.settings.steering_ratio * road_curvature_ahead(points, len(z))
        return z

    def step(
        self,
        measurement: np.ndarray,
        acceleration: np.ndarray,
        *,
        runs: np.ndarray | None = None,
        road_points: np.ndarray | None = None,
    ) -> Estimate:
        """See :meth:`estimators.gm_ekf.GaussianMixtureEKF.step`."""
        if self._filters is None:
            raise RuntimeError("call reset() before step()")
        z_all = np.atleast_2d(np.asarray(measurement, dtype=np.float64))
        acc_all = np.atleast_2d(np.asarray(acceleration, dtype=np.float64))
        if runs is None:
            idx = np.arange(self.num_runs)
        else:
            idx = (
                np.flatnonzero(runs)
                if np.asarray(runs).dtype == bool
                else np.asarray(runs, dtype=np.intp)
            )
        points = road_point_rows(road_points, idx.size)
        for j, r in enumerate(idx):
            self._step_run(
                int(r), z_all[j], acc_all[j], None if points is None else np.array(points[j])
            )
        return self.estimate()

    @property
    def gated_counts(self) -> np.ndarray:
        """See :attr:`estimators.gm_ekf.GaussianMixtureEKF.gated_counts`."""
        return self._gated_count[0].copy() if self._single else self._gated_count.copy()

    @property
    def last_gated(self) -> np.ndarray:
        """See :attr:`estimators.gm_ekf.GaussianMixtureEKF.last_gated`."""
        return self._gated[0].copy() if self._single else self._gated.copy()

    @property
    def withheld_decisions(self) -> np.ndarray:
        """See :attr:`estimators.gm_ekf.GaussianMixtureEKF.withheld_decisions`."""
        withheld = self._evidence["_withheld"].astype(np.int64)
        return withheld[0] if self._single else withheld

    @property
    def refusal_codes(self) -> np.ndarray:
        """See :attr:`estimators.gm_ekf.GaussianMixtureEKF.refusal_codes`."""
        codes = self._evidence["_refused_by"].astype(np.int64)
        return codes[0] if self._single else codes

    @property
    def low_speed(self) -> np.ndarray:
        """See :attr:`estimators.gm_ekf.GaussianMixtureEKF.low_speed`."""
        return self._slow[0].copy() if self._single else self._slow.copy()

    def _initial_evidence(self, log_w: np.ndarray, x0: np.ndarray) -> dict[str, np.ndarray]:
        """The evidence rule's per-run arrays at reset, with the aim cap's average offsets
        (each hypothesis' y(0)) when the cap is on."""
        evidence = initial_evidence_state(log_w)
        if self._aim_rate:
            evidence.update(initial_aim_offsets(x0[..., 1]))
        return evidence

    def _new_bank(self, x0: np.ndarray, log_w: np.ndarray) -> list[ARXExtendedKalmanFilter | None]:
        """One run's filters at reset: x_i(0) = ``x0[i]`` (C, n), P_i(0) the prior
        covariance (None where the prior weight is 0)."""
        bank: list[ARXExtendedKalmanFilter | None] = []
        for c in range(log_w.size):
            if not np.isfinite(log_w[c]):
                bank.append(None)
                continue
            ekf = ARXExtendedKalmanFilter(self.matrices)
            ekf.x = x0[c][:, None].copy()
            ekf.P = self.matrices.initial_covariance.copy()
            ekf.R = np.diag(self.matrices.measurement_var)
            bank.append(ekf)
        return bank

    def _step_run(
        self, r: int, z: np.ndarray, acceleration: np.ndarray, points: np.ndarray | None
    ) -> None:
        """One step of run ``r``: predict, gate, update, evidence, prune, low speed."""
        model = self.model
        settings = self.settings
        z = z.copy()
        z[2] *= settings.steering_ratio
        if settings.steering_curvature_feedforward and points is not None:
            kappa = road_curvature_ahead(points[None, :], 1)[0]
            z[2] -= settings.steering_curvature_feedforward * kappa
        z[~np.isfinite(z)] = np.nan  # NaN and +-inf are missing
        steering = z[2]
        acceleration = np.where(
            np.abs(acceleration) <= settings.max_acceleration, acceleration, np.nan
        )
        slow = bool(self._slow[r])
        if not model.has_steering or slow:
            z[2] = np.nan
        previous = self._points[r]
        u = np.array(
            [acceleration[0], acceleration[1], self._steering[r], float(slow), *previous]
            if np.all(np.isfinite(previous))
            else [acceleration[0], acceleration[1], self._steering[r], float(slow)]
        )
        log_w = self._log_w[r].copy()
        assert self._filters is not None  # (step() checked)
        bank = self._filters[r]
        for ekf in bank:
            if ekf is not None:
                ekf.predict(u=u)
        rows = self._gate(r, bank, z, log_w, points)
        refused = (
            settings.mismatch_drops_steering
            and model.has_steering
            and int(self._stats["decision"][r]) == MODEL_MISMATCH
            and 2 in rows
        )
        # refused: scored, but no state update from the steering (FilterSettings)
        saved = [(e.x.copy(), e.P.copy()) for e in bank if e is not None] if refused else None
        log_lik, score = self._update_bank(r, bank, z, rows, points)
        if saved is not None:
            for ekf, (x, cov) in zip([e for e in bank if e is not None], saved, strict=True):
                ekf.x, ekf.P = x, cov
            self._update_bank(r, bank, z, rows[rows != 2], points)
        evidence = {name: self._evidence[name][r : r + 1] for name in EVIDENCE_STATE}
        if self._aim_rate:  # the aim cap's average offsets move toward x(k|k)'s
            aim = self._evidence[AIM_OFFSET][r].copy()
            reach = self._evidence[AIM_REACH][r].copy()
            for c, ekf in enumerate(bank):
                if ekf is not None:
                    aim[c] += self._aim_rate * (ekf.x[1, 0] - aim[c])
            if np.abs(aim).min() <= self._rule.aim_near:  # held near some centre
                reach = np.maximum(reach, np.abs(aim))
            evidence[AIM_OFFSET], evidence[AIM_REACH] = aim[None], reach[None]
        new_log_w, evidence, stats = weigh_evidence(
            self._rule, log_w[None], log_lik[None], score[None], evidence
        )
        for name, value in evidence.items():
            self._evidence[name][r] = value[0]
        for name, value in stats.items():
            self._stats[name][r] = value[0]
        log_w = self._prune(bank, new_log_w[0])
        restart = self._leave_low_speed(r, bank, log_w, slow, steering)
        if self._gated[r, 2] and not restart:
            steering = np.nan  # an outlier must not enter the memory at the next prediction
        if restart:
            self._restart_memory(r, bank, steering, points)
        self._log_w[r] = log_w
        self._steering[r] = steering
        self._points[r] = np.nan if points is None else points

    def _gate(
        self,
        r: int,
        bank: list[ARXExtendedKalmanFilter | None],
        z: np.ndarray,
        log_w: np.ndarray,
        points: np.ndarray | None,
    ) -> np.ndarray:
        """The outlier gate: the channels no hypothesis explains (weighed by its log-odds),
        ``min_i [nu_ic^2 / S_i,cc + 2 (max_j log w_j - log w_i)] > g^2``, are dropped and
        counted; returns the measurement rows kept (observed and not gated)."""
        model = self.model
        mats = self.matrices
        rows = np.flatnonzero(~np.isnan(z))
        self._gated[r] = False
        if not (rows.size and math.isfinite(self.settings.innovation_gate)):
            return rows
        score = np.full(rows.size, np.inf)
        for c, ekf in enumerate(bank):
            if ekf is None:
                continue
            xc = ekf.x[:, 0]
            hc = model.measurement_jacobian(xc, points)[rows]
            s_diag = np.diag(hc @ ekf.P @ hc.T) + mats.measurement_var[rows]
            nu = z[rows] - model.measurement(xc, points)[rows]
            odds = np.max(log_w) - log_w[c]
            with np.errstate(over="ignore"):  # a huge reading: an infinite score, gated
                score = np.minimum(score, nu * nu / s_diag + 2.0 * odds)
        gated = score > self.settings.innovation_gate**2
        self._gated_count[r, rows[gated]] += 1
        self._gated[r, rows[gated]] = True
        return rows[~gated]

    def _update_bank(
        self,
        r: int,
        bank: list[ARXExtendedKalmanFilter | None],
        z: np.ndarray,
        rows: np.ndarray,
        points: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The EKF update of each hypothesis with the measurement ``rows`` (paper eq. 15-18);
        returns log N(nu_i; 0, S_i) (C,) and the normalized steering innovations
        ``nu_i,3 / sqrt(S_i,33)`` (C,) (NaN: not used)."""
        model = self.model
        r_matrix = np.diag(self.matrices.measurement_var[rows])
        log_lik = np.zeros(len(bank))
        score = np.full(len(bank), np.nan)  # normalized steering innovations
        steering_row = np.flatnonzero(rows == 2)
        for c, ekf in enumerate(bank):
            if ekf is None:
                continue
            if rows.size:
                ekf.update(
                    z[rows][:, None],
                    lambda x: model.measurement_jacobian(x[:, 0], points)[rows],
                    lambda x: model.measurement(x[:, 0], points)[rows][:, None],
                    R=r_matrix,
                )
                log_lik[c] = ekf.log_likelihood
                if steering_row.size:
                    j = int(steering_row[0])
                    score[c] = ekf.y[j, 0] / math.sqrt(ekf.S[j, j])
            self._last_x[r, c] = ekf.x[:, 0]  # a hypothesis pruned now stays at this posterior
            self._last_P[r, c] = ekf.P
        return log_lik, score

    def _prune(self, bank: list[ARXExtendedKalmanFilter | None], log_w: np.ndarray) -> np.ndarray:
        """Hypotheses other than the most likely with ``w_i < prune_threshold`` are dropped
        (their filter removed, weight 0) and the weights normalized again."""
        threshold = self.settings.prune_threshold
        if threshold <= 0:
            return log_w
        best_index = int(np.argmax(log_w))
        pruned = [
            c
            for c in range(log_w.size)
            if c != best_index and np.isfinite(log_w[c]) and log_w[c] < math.log(threshold)
        ]
        if not pruned:
            return log_w
        for c in pruned:
            bank[c] = None
            log_w[c] = -np.inf
        return log_w - logsumexp(log_w)

    def _leave_low_speed(
        self,
        r: int,
        bank: list[ARXExtendedKalmanFilter | None],
        log_w: np.ndarray,
        slow: bool,
        steering: float,
    ) -> bool:
        """Low speed: the steering channel is off while ``sum_i w_i |v_i| < min_speed``, and
        stays off until a steering reading comes; returns whether the memory restarts now."""
        min_speed = self.settings.min_speed if self.model.has_steering else 0.0
        if min_speed <= 0:
            return False
        speed = sum(
            math.exp(log_w[c]) * math.hypot(ekf.x[0, 0], ekf.x[2, 0])
            for c, ekf in enumerate(bank)
            if ekf is not None
        )
        now_slow = speed < min_speed
        restart = False
        if slow and not now_slow:
            if math.isnan(steering):
                now_slow = True  # restart only from a steering reading
            else:
                restart = True
        self._slow[r] = now_slow
        return restart

    def _restart_memory(
        self,
        r: int,
        bank: list[ARXExtendedKalmanFilter | None],
        steering: float,
        points: np.ndarray | None,
    ) -> None:
        """The memory restart after low speed: ``m_i = steady_memory(z_3, x_i)`` and the
        covariance of :meth:`FilterMatrices.restart_memory_covariance` (``P_mm = memory_std^2
        I``, uncorrelated with the vehicle states; with the driver's preferred offset p,
        correlated through p)."""
        model = self.model
        if model.n_memory:
            mem = model.memory_slice
            for ekf in bank:
                if ekf is not None:
                    x = ekf.x[:, 0]
                    ekf.x[mem, 0] = model.steady_memory(np.array(steering), x, points)
                    ekf.P = self.matrices.restart_memory_covariance(ekf.P[None])[0]
        for c, ekf in enumerate(bank):
            if ekf is not None:
                self._last_x[r, c] = ekf.x[:, 0]
                self._last_P[r, c] = ekf.P

    def estimate(self) -> Estimate:
        """The current estimate (mixture and hypotheses)."""
        if self._filters is None:
            raise RuntimeError("call reset() first")
        x = self._last_x.copy()
        cov = self._last_P.copy()
        w = np.exp(self._log_w)
        mean = np.einsum("rc,rcn->rn", w, x)
        est = Estimate(
            mean,
            x,
            cov,
            w,
            self._log_w.copy(),
            np.argmax(self._log_w, axis=1),
            self._hyp.copy(),
            self.state_names,
            decision_names(self._stats["decision"]),
            self._stats["model_error"].copy(),
            self._stats["autocorrelation"].copy(),
            self._stats["evidence_scale"].copy(),
        )
        return est.run(0) if self._single else est
