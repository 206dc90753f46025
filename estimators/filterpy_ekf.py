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
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from scipy.special import logsumexp

from estimators.arx_state_space import ARXStateSpace
from estimators.base import Estimate
from estimators.gm_ekf import FilterMatrices, FilterSettings
from hasa_env.steering.arx import ARXForm

__all__ = ["FilterpyGMEKF", "ARXExtendedKalmanFilter"]


class ARXExtendedKalmanFilter(ExtendedKalmanFilter):
    """filterpy's EKF with the augmented model's nonlinear prediction.

    ``predict(u)`` with ``u = (a_x, a_y, z_3)``: the IMU input and the
    steering measured at k (model units, NaN if missing). It sets ``F`` and
    ``Q`` to the (decorrelated, see :class:`estimators.gm_ekf.FilterMatrices`)
    Jacobian and process noise, then filterpy propagates ``P = F P F^T + Q``.
    """

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
        missing_acc = bool(np.isnan(acceleration).any())
        acceleration = np.where(np.isnan(acceleration), 0.0, acceleration)
        x_new = model.transition(x, acceleration)
        jac = model.transition_jacobian(x)
        q = mats.process_noise
        if mats.decorrelates and not math.isnan(steering):
            gain = mats.steering_gain
            x_new = x_new + gain * (steering - model.predicted_steering(x))
            jac = jac - np.outer(gain, model.measurement_jacobian(x)[2])
            q = mats.process_noise_decorrelated
        if missing_acc:
            q = q + mats.process_noise_missing_acceleration
        self.F = jac
        self.Q = q
        self.x = x_new[:, None]


class FilterpyGMEKF:
    """The Gaussian-mixture EKF built from filterpy EKFs (reference implementation).

    Same interface and results as :class:`estimators.gm_ekf.GaussianMixtureEKF`
    (see it for the equations; paper eq. 11-19): filterpy's
    ``ExtendedKalmanFilter.update`` uses the Joseph form and its
    ``log_likelihood`` the full multivariate normal of the innovation. Missing
    measurements drop their rows from z, H and R.

    Args:
        steering_model: the steering model's ARX description (None: no steering).
        settings: :class:`estimators.gm_ekf.FilterSettings`.
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
        self.model = ARXStateSpace(steering_model, dt, decision_lag)
        self.matrices = FilterMatrices(self.model, settings)
        self.state_names = self.model.state_names
        self._filters: list[list[ARXExtendedKalmanFilter | None]] | None = None
        self._single = False

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
    ) -> Estimate:
        """See :meth:`estimators.gm_ekf.GaussianMixtureEKF.reset`."""
        measurement = np.asarray(measurement, dtype=np.float64)
        single = measurement.ndim == 1
        z = np.atleast_2d(measurement)
        if z.ndim != 2 or z.shape[1] != 3:
            raise ValueError(f"measurement must have shape (3,) or (R, 3), got {measurement.shape}")
        n_runs = z.shape[0]
        hyp = np.asarray(hypotheses, dtype=np.float64)
        if hyp.ndim == 1:
            hyp = np.broadcast_to(hyp, (n_runs, hyp.size))
        n_comp = hyp.shape[1]
        if prior is None:
            log_w = np.full((n_runs, n_comp), -math.log(n_comp))
        else:
            p = np.broadcast_to(np.asarray(prior, dtype=np.float64), (n_runs, n_comp))
            with np.errstate(divide="ignore"):
                log_w = np.log(p / p.sum(axis=1, keepdims=True))
        x0 = self.matrices.initial_state(z, hyp)
        banks = []
        for r in range(n_runs):
            bank: list[ARXExtendedKalmanFilter | None] = []
            for c in range(n_comp):
                if not np.isfinite(log_w[r, c]):
                    bank.append(None)
                    continue
                ekf = ARXExtendedKalmanFilter(self.matrices)
                ekf.x = x0[r, c][:, None].copy()
                ekf.P = self.matrices.initial_covariance.copy()
                ekf.R = np.diag(self.matrices.measurement_var)
                bank.append(ekf)
            banks.append(bank)
        steering = z[:, 2] * self.settings.steering_ratio
        if runs is None:
            self._single = single
            self._filters, self._log_w, self._hyp, self._steering = (
                banks,
                log_w,
                hyp.copy(),
                steering,
            )
            self._last_x = x0.copy()
            self._last_P = np.broadcast_to(
                self.matrices.initial_covariance, x0.shape + (x0.shape[-1],)
            ).copy()
        else:
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
                self._last_x[r] = x0[j]
                self._last_P[r] = self.matrices.initial_covariance
        return self.estimate()

    def step(
        self,
        measurement: np.ndarray,
        acceleration: np.ndarray,
        *,
        runs: np.ndarray | None = None,
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
        for j, r in enumerate(idx):
            self._step_run(int(r), z_all[j], acc_all[j])
        return self.estimate()

    def _step_run(self, r: int, z: np.ndarray, acceleration: np.ndarray) -> None:
        model = self.model
        mats = self.matrices
        z = z.copy()
        z[2] *= self.settings.steering_ratio
        steering = z[2]
        if not model.has_steering:
            z[2] = np.nan
        rows = np.flatnonzero(~np.isnan(z))
        r_matrix = np.diag(mats.measurement_var[rows])
        log_w = self._log_w[r].copy()
        u = np.array([acceleration[0], acceleration[1], self._steering[r]])
        for c, ekf in enumerate(self._filters[r]):
            if ekf is None:
                continue
            ekf.predict(u=u)
            if rows.size:
                ekf.update(
                    z[rows][:, None],
                    lambda x: model.measurement_jacobian(x[:, 0])[rows],
                    lambda x: model.measurement(x[:, 0])[rows][:, None],
                    R=r_matrix,
                )
                log_w[c] += ekf.log_likelihood
            self._last_x[r, c] = ekf.x[:, 0]
            self._last_P[r, c] = ekf.P
        total = logsumexp(log_w)
        if np.isfinite(total):
            log_w = log_w - total
        else:
            log_w = self._log_w[r].copy()
        threshold = self.settings.prune_threshold
        if threshold > 0:
            best = int(np.argmax(log_w))
            pruned = [
                c
                for c in range(log_w.size)
                if c != best and np.isfinite(log_w[c]) and log_w[c] < math.log(threshold)
            ]
            if pruned:
                for c in pruned:
                    self._filters[r][c] = None
                    log_w[c] = -np.inf
                log_w = log_w - logsumexp(log_w)
        self._log_w[r] = log_w
        self._steering[r] = steering

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
        )
        return est.run(0) if self._single else est
