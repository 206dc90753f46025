"""The model and noise matrices of the mixture filter and its batched predict/update.

Shared by the fast filter (:class:`estimators.gm_ekf.GaussianMixtureEKF`) and
the filterpy reference (:mod:`estimators.filterpy_ekf`); docs/design.md §8.5-8.7 and §8.18
(the driver's preferred offset).

Why this module is long: the batched predict and update are unrolled into constant tables
(transition and measurement Jacobians as sums of per-feature maps, a 3x3 inverse by the
adjugate) for speed, and each table's docstring states the equation it tabulates; the
reference filter shares every matrix, so they stay in one place.

The two-dimensional products of the filter's own arrays (states, features, constant matrices)
are written ``a.dot(b)``, the stacked (3-D) ones ``a @ b``: on these operands ``ndarray.dot``
makes the BLAS call that ``@`` makes (dgemm, or dgemv for a single row or a vector; ``dot``
copies a non-contiguous operand first, which changes only where BLAS reads it), so the same
bits, at about a third of ``@``'s per-call cost (0.35 against 0.9 us), which is most of such a
product's time on one run's arrays of a few numbers. A caller's array (the IMU input) stays
``@``: for strides BLAS cannot read, ``matmul`` may sum in its own loop.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from estimators.arx_state_space import (
    BIAS,
    PREFERRED_OFFSET,
    VX,
    VY,
    ARXStateSpace,
    Y,
)
from estimators.settings import FilterSettings
from estimators.small_arrays import any_nan, any_true
from hasa_env.steering.equation_error import MIN_SCALE_SPEED

__all__ = ["FilterMatrices", "filter_model"]

_LOG_2PI = math.log(2.0 * math.pi)
_VARIANTS = ("full", "decorrelated", "held")  # transition tables, by code 0, 1, 2
_MIN_RUNS_SKIPPED = 8
"""The gated update is repeated on the gated runs' rows only when that skips at least this
many runs (fewer: gathering and scattering the rows costs more than it saves)."""
_MAX_ROWS_IN_FLOATS = 4
"""Up to this many filters (one run's hypotheses) the arithmetic of the bearing features and
of the 3x3 inverse is done in Python floats: the same IEEE operations in the same order as
numpy's (so the same bits), without numpy's per-call overhead, which dominates on arrays of a
few numbers (the transcendental functions stay numpy's)."""


def filter_model(
    steering_model: Any, settings: FilterSettings, dt: float | None, decision_lag: int
) -> ARXStateSpace:
    """The filters' state-space model of ``steering_model`` (an ARXForm, or None): with the
    driver's preferred offset as a state when the model steers and
    ``settings.preferred_offset_std > 0``, and the coloured equation error when it steers
    and ``settings.steering_coloured_error_std > 0``."""
    steers = steering_model is not None
    coloured = steers and settings.steering_coloured_error_std > 0
    return ARXStateSpace(
        steering_model,
        dt,
        decision_lag,
        preferred_offset=steers and settings.preferred_offset_std > 0,
        coloured_error_correlation=(
            settings.steering_coloured_error_correlation if coloured else None
        ),
    )


class FilterMatrices:
    """The model and noise matrices of the mixture filter, shared by the fast
    filter and the filterpy reference.

    The steering model's equation error e(k) drives both the steering
    measurement (h3) and the memory states (through a_j delta(k), see
    :mod:`estimators.arx_state_space`): process and measurement noise are
    correlated, ``E[w(k) v_3(k)] = s = [0, 0, 0, 0, a_n, ..., a_1] sigma_e^2``.
    The filter removes the correlation exactly (Simon, *Optimal State
    Estimation*, 2006, sec. 7.1). When the steering was measured at k::

        x(k+1) = F(x) + B_D a + J (z_3(k) - h_3(x)),      J = s / R_33
        F'     = dF/dx - J H_3,      Q' = Q - s s^T / R_33

    so the memory states follow the *measured* steering (the ARX model's
    one-step-ahead predictor). When it was not (NaN)::

        x(k+1) = F(x) + B_D a,       Q = Q_vehicle + a a^T sigma_e^2

    with ``Q_vehicle = B_D diag(sigma_imu^2) B_D^T`` and
    ``R = diag(sigma_speed^2, sigma_camera^2, sigma_e^2 + (ratio sigma_sensor)^2)``.
    Below ``min_speed`` (:class:`FilterSettings`) the memory is held::

        x(k+1) = A_held x + B_D a,   A_held = dF/dx with the memory block I and
                                     no bearing terms,   Q = Q_vehicle

    and so it is after a missing (or gated) steering reading when the model's
    autoregressive part is unstable (``unstable_memory``: the memory matrix'
    spectral radius, the largest |root| of ``z^n - a_1 z^(n-1) - ... - a_n``,
    exceeds 1, as least-squares fits on nearly noise-free drivers can give):
    such a model has no open-loop prediction (it diverges geometrically and
    overflows within a second); a stable one, like the paper's (0.94), is
    propagated open loop as above.

    Attributes:
        model: the :class:`ARXStateSpace`.
        process_noise: Q, (n, n), steering not measured at k.
        process_noise_decorrelated: Q', (n, n), steering measured at k.
        process_noise_vehicle: Q_vehicle (with the bias drift), (n, n), memory held.
        process_noise_missing_acceleration: added to Q when an IMU reading is missing.
        steering_cross_covariance: s, (n,).
        steering_gain: J = s / R_33, (n,).
        measurement_var: diagonal of R, (3,).
        initial_covariance: P_0 of every hypothesis, (n, n).
        decorrelates: True when J != 0 (a steering model with memory).
        unstable_memory: True when the memory matrix' spectral radius exceeds 1.
    """

    def __init__(self, model: ARXStateSpace, settings: FilterSettings) -> None:
        self.model = model
        self.settings = settings
        n = model.n_states
        mem = model.memory_slice
        s = settings
        input_matrix = model.input_matrix()
        input_outer = input_matrix @ input_matrix.T
        accel_var = s.acceleration_noise_std**2
        q_vehicle = accel_var * input_outer
        q_vehicle[BIAS, BIAS] += s.bias_drift_std**2
        if model.preferred_offset:
            q_vehicle[PREFERRED_OFFSET, PREFERRED_OFFSET] += s.preferred_offset_drift_std**2
        self.process_noise_missing_acceleration = (
            s.missing_acceleration_std**2 - accel_var
        ) * input_outer
        residual_var = s.steering_residual_std**2
        sensor_var = (s.steering_ratio * s.steering_sensor_std) ** 2
        steering_var = residual_var + sensor_var
        cross = np.zeros(n)
        cross[mem] = model.feedback * residual_var
        self.steering_cross_covariance = cross
        self.steering_gain = cross / steering_var
        q_full = q_vehicle.copy()
        q_full[mem, mem] += residual_var * np.outer(model.feedback, model.feedback)
        q_full[mem, mem] += s.memory_process_std**2 * np.eye(model.n_memory)
        self.process_noise = q_full
        self.process_noise_decorrelated = q_full - np.outer(cross, cross) / steering_var
        self.process_noise_vehicle = q_vehicle
        self.decorrelates = bool(np.any(self.steering_gain != 0))
        radius = np.abs(np.linalg.eigvals(model.memory_matrix)).max() if model.n_memory else 0.0
        self.unstable_memory = bool(radius > 1.0)
        self.measurement_var = np.array([s.speed_noise_std**2, s.camera_noise_std**2, steering_var])
        lateral_std = s.camera_noise_std if s.initial_lateral_std is None else s.initial_lateral_std
        p0 = np.zeros((n, n))
        p0[VX, VX] = s.initial_speed_std**2
        p0[Y, Y] = lateral_std**2 + s.bias_std**2
        p0[VY, VY] = s.initial_lateral_velocity_std**2
        p0[BIAS, BIAS] = s.bias_std**2
        p0[Y, BIAS] = p0[BIAS, Y] = -(s.bias_std**2)  # y_i = camera - b_i
        if model.preferred_offset:
            p0[PREFERRED_OFFSET, PREFERRED_OFFSET] = s.preferred_offset_std**2
        self.coloured_error_index: int | None = None
        self._coloured_step_var_at_1_mps = 0.0
        if model.coloured_error:  # stationary at the reference speed; eta's added per step
            self.coloured_error_index = model.coloured_error_index
            p0[model.coloured_error_index, model.coloured_error_index] = (
                s.steering_coloured_error_std**2
            )
            rho = s.steering_coloured_error_correlation
            self._coloured_step_var_at_1_mps = (
                s.steering_coloured_error_std**2
                * (1.0 - rho * rho)
                * s.steering_coloured_error_speed**4
            )
        self.initial_covariance = self.restart_memory_covariance(p0[None])[0]
        self._build_fast_path(input_matrix)
        for arr in (
            self.process_noise,
            self.process_noise_decorrelated,
            self.process_noise_vehicle,
            self.process_noise_missing_acceleration,
            self.steering_cross_covariance,
            self.steering_gain,
            self.measurement_var,
            self.initial_covariance,
        ):
            arr.setflags(write=False)

    def coloured_error_process_var(self, speed: np.ndarray) -> np.ndarray:
        """Var(eta) (rad^2, model units) of the coloured equation error's step at the speeds
        ``speed`` (m/s; each row's v_x): ``sigma_c^2 (1 - rho^2) (v_ref / v)^4``, v floored at
        :data:`~hasa_env.steering.equation_error.MIN_SCALE_SPEED` (the square of
        :func:`~hasa_env.steering.equation_error.speed_scale`). Zeros without it."""
        if self.coloured_error_index is None:
            return np.zeros(np.shape(speed))
        floored = np.maximum(np.abs(np.asarray(speed, dtype=np.float64)), MIN_SCALE_SPEED)
        squared = floored * floored
        return self._coloured_step_var_at_1_mps / (squared * squared)

    def restart_memory_covariance(self, cov: np.ndarray) -> np.ndarray:
        """The covariances (B, n, n) of states whose memory restarts at the constant-past
        memory of their own state (at reset and after the steering channel was off)::

            P_mm = memory_std^2 I + S S^T P_pp,   P_m,x = S P_p,x,   S = d m / d p

        with S of :meth:`ARXStateSpace.memory_offset_sensitivity` (0 without the driver's
        preferred offset p: the memory is then uncorrelated with the vehicle states). The
        memory moves with p as each hypothesis' bearings do, so a hypothesis' start memory
        is explained by its p, not read as lane evidence."""
        mem = self.model.memory_slice
        out = np.array(cov, dtype=np.float64, copy=True)
        out[:, mem, :] = 0.0
        out[:, :, mem] = 0.0
        if self.model.preferred_offset and self.model.n_memory:
            sens = self.model.memory_offset_sensitivity()
            row = out[:, PREFERRED_OFFSET, :]  # (B, n), memory columns 0
            out[:, mem, :] = sens[None, :, None] * row[:, None, :]
            out[:, :, mem] = out[:, mem, :].transpose(0, 2, 1)
            out[:, mem, mem] = np.outer(sens, sens) * row[:, PREFERRED_OFFSET, None, None]
        out[:, mem, mem] += self.settings.memory_std**2 * np.eye(self.model.n_memory)
        return out

    # --------------------------------------------------------------- prior
    def initial_state(
        self,
        measurement: np.ndarray,
        hypotheses: np.ndarray,
        road_points: np.ndarray | None = None,
    ) -> np.ndarray:
        """Prior means (R, C, n) from the first measurements (R, 3) and biases (R, C).

        ``v_x`` = speed reading (``v_y`` = 0), ``y_i`` = camera - ``b_i``,
        ``b`` = ``b_i``, memory = the constant-past memory
        (:meth:`ARXStateSpace.steady_memory`) of the measured steering and
        hypothesis i's *own* bearings (with the run's ``road_points`` (R, 4),
        None: straight road), never shared between hypotheses (a missing
        first steering reading counts as 0).
        """
        model = self.model
        speed, camera, steering = measurement[:, 0], measurement[:, 1], measurement[:, 2]
        if not (np.all(np.isfinite(speed)) and np.all(np.isfinite(camera))):
            raise ValueError("the first measurement needs a finite speed and camera reading")
        steering = np.where(np.isfinite(steering), steering, 0.0) * self.settings.steering_ratio
        x = np.zeros(hypotheses.shape + (model.n_states,))
        x[..., VX] = speed[:, None]
        x[..., Y] = camera[:, None] - hypotheses
        x[..., BIAS] = hypotheses
        if model.n_memory:
            points = None if road_points is None else road_points[:, None, :]
            x[..., model.memory_slice] = model.steady_memory(
                np.broadcast_to(steering[:, None], hypotheses.shape), x, points
            )
        return x

    # ------------------------------------------------------ fast-path tables
    def _build_fast_path(self, input_matrix: np.ndarray) -> None:
        """Constant tables of the vectorized filter.

        With ``w = [theta + atan(y/near), theta + atan(y/far), v_y]`` (so
        u = [-w_0, -w_1, w_2]; with road points ``atan((y - dy_near) / dx_near)``
        and ``atan((y - dy_far) / dx_far)``; with the driver's preferred offset p every y
        here reads y - p) the transition is ``x' = x A^T +
        w G^T + a B_D^T [+ J z_3]`` and, with ``D = [dtheta/dv_x, dtheta/dv_y,
        d atan(.)/dy (near), d atan(.)/dy (far)]``, its Jacobian is
        ``F = F_0 + sum_k D_k T_k``; likewise ``H = H_0 + sum_k D_k U_k`` plus
        the speed row. The decorrelated, plain and held-memory variants are
        tabulated.
        """
        model = self.model
        n = model.n_states
        mem = model.memory_slice
        self.input_matrix_t = np.ascontiguousarray(input_matrix.T)
        sign = np.array([-1.0, -1.0, 1.0])
        base_a = model.transition_matrix_template()
        gains = np.zeros((n, 3))
        gains[mem] = model.bearing_gain * sign
        last = model.steering_state_row()
        variants = {"full": (base_a, gains)}
        if self.decorrelates:
            variants["decorrelated"] = (
                base_a - np.outer(self.steering_gain, last),
                gains - np.outer(self.steering_gain, model.output_gain * sign),
            )
        variants["held"] = (model.held_memory_transition_matrix(), np.zeros((n, 3)))
        self._tables: dict[str, tuple[np.ndarray, ...]] = {}
        for name, (a_mat, g_mat) in variants.items():
            jac_base = a_mat.copy()
            jac_base[:, VY] += g_mat[:, 2]
            both = g_mat[:, 0] + g_mat[:, 1]
            maps = np.zeros((4, n, n))
            maps[0, :, VX] = both
            maps[1, :, VY] = both
            maps[2, :, Y] = g_mat[:, 0]
            maps[3, :, Y] = g_mat[:, 1]
            if model.preferred_offset:  # the features read y - p
                maps[2, :, PREFERRED_OFFSET] = -g_mat[:, 0]
                maps[3, :, PREFERRED_OFFSET] = -g_mat[:, 1]
            self._tables[name] = (
                np.ascontiguousarray(a_mat.T),
                np.ascontiguousarray(g_mat.T),
                jac_base.ravel().copy(),
                maps.reshape(4, n * n).copy(),
            )
        # measurement: h_1 = |v|, [h_2, h_3] = x L^T (+ beta_0' . w)
        beta0 = model.output_gain * sign
        linear = np.zeros((3, n))  # row 0 (speed) is nonlinear, filled separately
        linear[1, Y] = linear[1, BIAS] = 1.0
        h_base = np.zeros((3, n))
        h_base[1, Y] = h_base[1, BIAS] = 1.0
        h_maps = np.zeros((4, 3, n))
        if model.has_steering:
            linear[2, VY] = beta0[2]
            h_base[2, VY] = beta0[2]
            linear[2] += last
            h_base[2] += last
            both = beta0[0] + beta0[1]
            h_maps[0, 2, VX] = both
            h_maps[1, 2, VY] = both
            h_maps[2, 2, Y] = beta0[0]
            h_maps[3, 2, Y] = beta0[1]
            if model.preferred_offset:
                h_maps[2, 2, PREFERRED_OFFSET] = -beta0[0]
                h_maps[3, 2, PREFERRED_OFFSET] = -beta0[1]
        self._measurement_linear_t = np.ascontiguousarray(linear.T)
        self._steering_bearing_gain = beta0[:2].copy()
        self._steering_uses_bearings = bool(model.has_steering and np.any(beta0[:2] != 0))
        self._h_base = h_base.ravel().copy()
        self._h_base_t = np.ascontiguousarray(h_base.T).ravel().copy()
        self._h_maps = h_maps.reshape(4, 3 * n).copy()
        self._h_maps_t = np.ascontiguousarray(h_maps.transpose(0, 2, 1)).reshape(4, 3 * n)
        self._h_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._offsets_cache: dict[tuple[int, int], np.ndarray] = {}
        self._run_of_row_cache: dict[tuple[int, int], np.ndarray] = {}
        self._none_gated_cache: np.ndarray | None = None
        self._measurement_var_column = self.measurement_var[:, None].copy()
        self._inverse_distance = np.array([1.0 / model.near_distance, 1.0 / model.far_distance])
        self._theta_sign = np.array([-1.0, 1.0])
        self._process_noise_variants = np.stack(
            [self.process_noise, self.process_noise_decorrelated, self.process_noise_vehicle]
        )
        self._build_small_batch_operands()

    def _build_small_batch_operands(self) -> None:
        """Operands of the few-filter paths (one run's step): lists for the float paths, rows
        where a broadcast costs more than the operation, and the caches of :meth:`_tiled` and
        :meth:`_constant_jacobians`."""
        self._h_scratch: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._tiled_cache: dict[tuple[tuple[str, str], int], np.ndarray] = {}
        self._measurement_var_rows = np.repeat(
            self._measurement_var_column, self.model.n_states, axis=1
        )
        self._inverse_distance_list = self._inverse_distance.tolist()
        self._process_noise_by_variant = dict(
            zip(_VARIANTS, self._process_noise_variants, strict=True)
        )
        self._has_memory = self.model.n_memory > 0
        self._steering_gain_row = self.steering_gain[None, :].copy()

    def _features(
        self, x: np.ndarray, points: np.ndarray | None = None, speed: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """w = [theta + atan(y/near), theta + atan(y/far), v_y] (B, 3) and
        D = [dtheta/dv_x, dtheta/dv_y, d atan(y/near)/dy, d atan(y/far)/dy] (B, 4).

        With ``points`` (B, 4) road points: ``atan((y - dy) / dx)`` and its
        derivative ``(1 / dx) / (1 + ((y - dy) / dx)^2)`` for near and far; y reads y - p
        with the driver's preferred offset p. ``speed``: ``hypot(v_x, v_y)`` (B,) if known."""
        vx, vy = x[:, VX], x[:, VY]
        if x.shape[0] <= _MAX_ROWS_IN_FLOATS:
            rows = x.tolist()
            ratio_rows, inverse_rows = self._bearing_ratios_in_floats(rows, points)
            return _features_in_floats(vx, vy, rows, ratio_rows, inverse_rows, speed)
        lateral = x[:, Y, None]
        if self.model.preferred_offset:
            lateral = lateral - x[:, PREFERRED_OFFSET, None]
        if points is None:
            inverse = self._inverse_distance
            ratio = lateral * inverse
        else:
            inverse = 1.0 / points[:, 0::2]
            ratio = (lateral - points[:, 1::2]) * inverse
        w = np.empty((x.shape[0], 3))
        np.add(np.arctan(ratio), np.arctan2(vy, vx)[:, None], out=w[:, :2])
        w[:, 2] = vy
        deriv = np.empty((x.shape[0], 4))
        # dtheta/dv_x = -v_y / v^2, dtheta/dv_y = v_x / v^2 (x[:, 2::-2] = [v_y, v_x])
        if speed is None:
            speed_sq = np.hypot(vx, vy)
            speed_sq *= speed_sq
        else:
            speed_sq = speed * speed
        np.maximum(speed_sq, 1e-12, out=speed_sq)
        np.multiply(x[:, VY::-VY], self._theta_sign / speed_sq[:, None], out=deriv[:, :2])
        np.divide(inverse, 1.0 + ratio * ratio, out=deriv[:, 2:])
        return w, deriv

    def _bearing_ratios_in_floats(
        self, rows: list[list[float]], points: np.ndarray | None
    ) -> tuple[list[float], list[float]]:
        """:meth:`_features`' ratios ``(y - dy_near) / dx_near, (y - dy_far) / dx_far`` (as
        ``(y - dy) * (1 / dx)``; y - p with the preferred offset p; dy = 0 and dx the
        distances on a straight road) and inverses ``1 / dx`` of a few filters (``rows``:
        their states, ``x.tolist()``), flat (2 B) lists, near and far of each filter in turn,
        in Python floats: the same operations as the numpy path."""
        if self.model.preferred_offset:
            lateral = [row[Y] - row[PREFERRED_OFFSET] for row in rows]
        else:
            lateral = [row[Y] for row in rows]
        ratios: list[float] = []
        if points is None:
            i_near, i_far = self._inverse_distance_list
            for y in lateral:
                ratios += (y * i_near, y * i_far)
            return ratios, self._inverse_distance_list * len(lateral)
        inverses: list[float] = []
        for y, (dx_near, dy_near, dx_far, dy_far) in zip(lateral, points.tolist(), strict=True):
            i_near, i_far = 1.0 / dx_near, 1.0 / dx_far
            ratios += ((y - dy_near) * i_near, (y - dy_far) * i_far)
            inverses += (i_near, i_far)
        return ratios, inverses

    def _transition_variants(
        self, n_runs: int, previous_steering: np.ndarray, held: np.ndarray | None
    ) -> tuple[np.ndarray | None, str]:
        """Which transition each run's prediction uses (:data:`_VARIANTS`): ``decorrelated``
        (``full`` without a correlated steering error) with a steering reading at k;
        without one ``full`` (``held`` if the memory is unstable); ``held`` for the ``held``
        runs (R,) bool. Returns (None, the variant) when all runs share one, else the
        (R,) codes and ``"mixed"``."""
        if held is not None and not any_true(held):
            held = None
        known = None
        if self.decorrelates and any_nan(previous_steering):
            known = ~np.isnan(previous_steering)
        if held is None and known is None:
            return None, "decorrelated" if self.decorrelates else "full"
        # per run: 0 plain, 1 decorrelated, 2 memory held
        codes = np.full(n_runs, 1 if self.decorrelates else 0)
        if known is not None:
            codes[~known] = 2 if self.unstable_memory else 0
        if held is not None:
            codes[held] = 2
        if np.all(codes == codes[0]):
            return None, _VARIANTS[codes[0]]
        return codes, "mixed"

    def predict_batch(
        self,
        x: np.ndarray,
        cov: np.ndarray,
        acceleration: np.ndarray,
        previous_steering: np.ndarray,
        n_comp: int,
        *,
        road_points: np.ndarray | None = None,
        held: np.ndarray | None = None,
        missing_acceleration: bool | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """x(k+1|k) (B, n) and P(k+1|k) (B, n, n) for B = R * C flattened hypotheses.

        Args:
            x, cov: posterior means (B, n) and covariances (B, n, n) at k.
            acceleration: (R, 2) IMU input over k -> k+1 (NaN: missing).
            previous_steering: (R,) measured steering at k, model units (NaN: missing).
            n_comp: C, hypotheses per run.
            road_points: (R, 4) road points at k (None: straight road).
            held: (R,) True for runs whose memory is held (below ``min_speed``);
                None: none.
            missing_acceleration: whether some entry of ``acceleration`` is NaN, if the
                caller knows (None: tested here).
        """
        n_runs = acceleration.shape[0]
        n = x.shape[1]
        any_missing_acc = (
            any_nan(acceleration) if missing_acceleration is None else missing_acceleration
        )
        if any_missing_acc:
            missing_acc = np.isnan(acceleration)
            acceleration = np.where(missing_acc, 0.0, acceleration)
        codes, variant = self._transition_variants(n_runs, previous_steering, held)
        w: np.ndarray | None = None
        deriv: np.ndarray | None = None
        if self._has_memory and variant != "held":
            points_b = None if road_points is None else np.repeat(road_points, n_comp, axis=0)
            w, deriv = self._features(x, points_b)
        drive = acceleration @ self.input_matrix_t  # (R, n) (a caller's array: ``@``)
        if codes is not None:
            x_new, jac, q, drive = self._propagate_mixed(
                x, w, deriv, codes, n_comp, previous_steering, drive
            )
        else:
            x_new, jac = self._propagate(variant, x, w, deriv, None)
            q = self._tiled(("Q", variant), self._process_noise_by_variant[variant], x.shape[0])
            if variant == "decorrelated":
                if n_runs == 1:  # (the same products, s J_j = J_j s)
                    drive += self._steering_gain_row * previous_steering.item()
                else:
                    drive += previous_steering[:, None] * self.steering_gain
        if x.shape[0] <= _MAX_ROWS_IN_FLOATS:  # each run's row of drive for its filters
            x_new += drive.take(self._run_of_row(n_runs, n_comp), axis=0)
        elif n_comp == 1 or n_runs == 1:  # (one run: its row of drive, broadcast)
            x_new += drive
        else:
            x_new = (x_new.reshape(n_runs, n_comp, n) + drive[:, None, :]).reshape(-1, n)
        if any_missing_acc:
            extra = (
                np.repeat(missing_acc.any(axis=1), n_comp)[:, None, None]
                * self.process_noise_missing_acceleration
            )
            q = q + extra
        # F P F^T = F (F P)^T: P is exactly symmetric (symmetrized after each update)
        cov_new = jac @ (jac @ cov).transpose(0, 2, 1)
        cov_new += q
        if self.coloured_error_index is not None:
            self._add_coloured_error_noise(cov_new, x)
        return x_new, cov_new

    def _add_coloured_error_noise(self, cov: np.ndarray, x: np.ndarray) -> None:
        """``cov[:, eps, eps] += Var(eta)`` at each row's v_x (:meth:`coloured_error_process_var`;
        for a few rows in Python floats, the same IEEE operations)."""
        eps = self.coloured_error_index
        if x.shape[0] > _MAX_ROWS_IN_FLOATS:
            cov[:, eps, eps] += self.coloured_error_process_var(x[:, VX])
            return
        level = self._coloured_step_var_at_1_mps
        for row, speed in enumerate(x[:, VX].tolist()):
            floored = max(abs(speed), MIN_SCALE_SPEED)
            squared = floored * floored
            cov[row, eps, eps] += level / (squared * squared)

    def _propagate_mixed(
        self,
        x: np.ndarray,
        w: np.ndarray | None,
        deriv: np.ndarray | None,
        codes: np.ndarray,
        n_comp: int,
        previous_steering: np.ndarray,
        drive: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """x', F', Q and the drive ``B_D a [+ J z_3]`` (R, n) of runs whose transition
        variants differ (``codes`` (R,), :data:`_VARIANTS`): the most common variant on every
        row, each other one on its own rows only. Every row's arithmetic is its own, the same
        numbers as on all rows, as long as the products stay matrix products (one row would be
        a vector-matrix product, which BLAS sums in another order: then on all rows, and its
        rows taken)."""
        codes_b = np.repeat(codes, n_comp)
        counts = np.bincount(codes_b, minlength=len(_VARIANTS))
        common = int(counts.argmax())
        x_new, jac = self._propagate(_VARIANTS[common], x, w, deriv, None)
        if not jac.flags.writeable:  # the held variant's constant F, broadcast
            jac = jac.copy()
        for code in np.flatnonzero(counts):
            if code != common:
                rows = np.flatnonzero(codes_b == code)
                if rows.size > 1:
                    x_new[rows], jac[rows] = self._propagate(_VARIANTS[code], x, w, deriv, rows)
                else:
                    x_all, jac_all = self._propagate(_VARIANTS[code], x, w, deriv, None)
                    x_new[rows], jac[rows] = x_all[rows], jac_all[rows]
        q = self._process_noise_variants[codes_b]
        decorrelated = codes == 1
        if decorrelated.any():
            steering = np.where(decorrelated, previous_steering, 0.0)
            drive = drive + steering[:, None] * self.steering_gain
        return x_new, jac, q, drive

    def _propagate(
        self,
        name: str,
        x: np.ndarray,
        w: np.ndarray | None,
        deriv: np.ndarray | None,
        rows: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """x' = x A^T + w G^T and F' of the transition variant ``name`` (:data:`_VARIANTS`),
        on ``rows`` (None: all) of ``x`` and its features ``w``, ``deriv`` (None: the held
        variant, or no memory)."""
        a_t, g_t, jac_base, maps = self._tables[name]
        x_rows = x if rows is None else x[rows]
        x_new = x_rows.dot(a_t)
        n = x.shape[1]
        if w is None or deriv is None or name == "held":
            return x_new, np.broadcast_to(jac_base.reshape(n, n), (x_rows.shape[0], n, n))
        x_new += (w if rows is None else w[rows]).dot(g_t)
        jac = (deriv if rows is None else deriv[rows]).dot(maps)
        jac += self._tiled(("F", name), jac_base, jac.shape[0])
        return x_new, jac.reshape(-1, n, n)

    def _tiled(self, key: tuple[str, str], array: np.ndarray, n_rows: int) -> np.ndarray:
        """``array`` as an operand for ``n_rows`` rows: tiled to (n_rows, ...) for a few rows
        (cached, read-only; numpy's broadcasting costs more than the operation on arrays of a
        few numbers), else itself (broadcast). The same numbers either way."""
        if n_rows > _MAX_ROWS_IN_FLOATS:
            return array
        cached = self._tiled_cache.get((key, n_rows))
        if cached is None:
            cached = np.tile(array, (n_rows,) + (1,) * array.ndim)
            cached.setflags(write=False)
            self._tiled_cache[(key, n_rows)] = cached
        return cached

    def update_batch(
        self,
        x: np.ndarray,
        cov: np.ndarray,
        z: np.ndarray,
        n_comp: int,
        all_observed: bool,
        **options: Any,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joseph-form EKF update of every hypothesis and its log-likelihood.

        Args:
            x, cov: predicted means (B, n) and covariances (B, n, n).
            z: (R, 3) measurements (steering in model units); NaN = missing.
            n_comp: C.
            all_observed: True when z has no NaN.
            **options: ``road_points``, ``gate`` and ``log_weights`` of
                :meth:`gated_update_batch` (default: straight road, no gate).

        Returns:
            x(k|k) (B, n), P(k|k) (B, n, n), log N(nu; 0, S) (B,).
        """
        return self.gated_update_batch(x, cov, z, n_comp, all_observed, **options)[:3]

    def gated_update_batch(
        self,
        x: np.ndarray,
        cov: np.ndarray,
        z: np.ndarray,
        n_comp: int,
        all_observed: bool,
        *,
        road_points: np.ndarray | None = None,
        gate: float = math.inf,
        log_weights: np.ndarray | None = None,
        drop_steering: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`update_batch` with the outlier gate g of :class:`FilterSettings`.

        ``road_points``: (R, 4) road points at this sample (None: straight road).
        ``drop_steering``: (R,) True for runs whose steering innovation is scored (the
        log-likelihoods and normalized innovations returned include it) but does not update
        their states (the runs in ``model_mismatch``, ``FilterSettings.mismatch_drops_steering``):
        their x(k|k), P(k|k) are those of the update without the steering row.

        Channel c of run r is dropped for every hypothesis of that run when
        no hypothesis explains it, each weighed by its log-odds against the
        most likely one (``log_weights`` (R, C), before the update)::

            min_i [ nu_ic^2 / S_i,cc + 2 (max_j log w_j - log w_i) ] > g^2

        and the update is done without it (see ``innovation_gate``).

        Returns:
            x(k|k) (B, n), P(k|k) (B, n, n), log N(nu; 0, S) (B,), the
            (R, 3) mask of gated channels, and the normalized innovations
            ``nu_c / sqrt(S_cc)`` (B, 3) of the channels used (NaN: missing
            or gated).
        """
        points_b = None if road_points is None else np.repeat(road_points, n_comp, axis=0)
        linearized = h, jac, jac_t = self._linearize(x, points_b)
        normalized: np.ndarray | None
        x_post, cov_post, log_lik, innovation, s_diag, distance_sq, normalized = self._update(
            x, cov, z, n_comp, all_observed, points_b, linearized
        )
        n_runs = z.shape[0]
        gated = self._none_gated(n_runs)
        if not (log_weights is None or math.isinf(gate)):
            # quick exit: the most likely hypothesis explains every channel, its score having
            # no odds; nu_c^2 / S_cc <= nu^T S^-1 nu (Cauchy-Schwarz), so its distance bounds
            # them all
            # (every run's own row, also with one hypothesis per run: a run's gate never
            # depends on the other runs of its batch)
            if n_runs == 1:
                favourite_distance_sq = distance_sq.item(log_weights.argmax())
            else:
                favourite = log_weights.argmax(axis=1) + self._run_offsets(n_runs, n_comp)
                favourite_distance_sq = distance_sq[favourite].max()
            if not favourite_distance_sq <= gate * gate:  # (NaN: check the channels)
                odds = log_weights.max(axis=1, keepdims=True) - log_weights  # (R, C), >= 0
                with np.errstate(over="ignore"):  # a huge reading: an infinite score, gated
                    score = (innovation * innovation / s_diag).reshape(n_runs, n_comp, 3)
                score += 2.0 * odds[:, :, None]
                gated = score.min(axis=1) > gate * gate
                if any_true(gated):
                    z = np.where(gated, np.nan, z)
                    all_observed = False
                    runs = np.flatnonzero(gated.any(axis=1))
                    if n_runs - runs.size < _MIN_RUNS_SKIPPED:
                        x_post, cov_post, log_lik, innovation, s_diag, _, normalized = self._update(
                            x, cov, z, n_comp, False, points_b, linearized
                        )
                    else:  # the update again on the rows of the runs that gated only
                        rows, again = self._update_runs(x, cov, z[runs], runs, n_comp, linearized)
                        updated = (x_post, cov_post, log_lik, innovation, s_diag)
                        for full, part in zip(updated, again[:5], strict=True):
                            full[rows] = part
                        normalized = None
        if normalized is None:
            normalized = innovation / np.sqrt(s_diag)
        if not all_observed:
            normalized[np.repeat(np.isnan(z), n_comp, axis=0)] = np.nan
        if drop_steering is not None:
            x_post, cov_post = self._update_without_steering(
                x, cov, z, n_comp, drop_steering, linearized, (x_post, cov_post)
            )
        return x_post, cov_post, log_lik, gated, normalized

    def _update_without_steering(
        self,
        x: np.ndarray,
        cov: np.ndarray,
        z: np.ndarray,
        n_comp: int,
        drop_steering: np.ndarray,
        linearized: tuple[np.ndarray, np.ndarray, np.ndarray],
        posterior: tuple[np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray]:
        """``posterior`` (x(k|k), P(k|k)) with the rows of the ``drop_steering`` runs (R,)
        whose steering was used (``z`` after the gate) updated again without it (every row's
        arithmetic is its own, as in the gate's repeated update)."""
        runs = np.flatnonzero(drop_steering & ~np.isnan(z[:, 2]))
        if runs.size == 0:
            return posterior
        x_post, cov_post = posterior[0].copy(), posterior[1].copy()
        z_runs = z[runs].copy()
        z_runs[:, 2] = np.nan
        rows, again = self._update_runs(x, cov, z_runs, runs, n_comp, linearized)
        x_post[rows], cov_post[rows] = again[0], again[1]
        return x_post, cov_post

    def _update_runs(
        self,
        x: np.ndarray,
        cov: np.ndarray,
        z_runs: np.ndarray,
        runs: np.ndarray,
        n_comp: int,
        linearized: tuple[np.ndarray, np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, tuple[Any, ...]]:
        """The rows (B',) of the ``runs`` (R',) and :meth:`_update` of those rows alone with
        their measurements ``z_runs`` (R', 3) (some missing) and their part of ``linearized``:
        every row's arithmetic is its own, so the other rows would not change."""
        rows = (runs[:, None] * n_comp + np.arange(n_comp)).ravel()
        h, jac, jac_t = linearized
        again = self._update(x[rows], cov[rows], z_runs, n_comp, False, None,
                             (h[rows], jac[rows], jac_t[rows]))  # fmt: skip
        return rows, again

    def _linearize(
        self, x: np.ndarray, points: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """h(x) (B, 3) and the measurement Jacobians H (B, 3, n) and H^T (B, n, 3) at the
        predicted means ``x`` (B, n), with the road points (B, 4) (None: straight). Not
        changed by :meth:`_update`, so a repeated update (the gate) reuses them."""
        n = x.shape[1]
        n_b = x.shape[0]
        speed = np.hypot(x[:, VX], x[:, VY])
        h = x.dot(self._measurement_linear_t)  # [0, y + b, linear part of h_3]
        h[:, 0] = speed
        if self._steering_uses_bearings:
            jac_base, jac_base_t = self._measurement_jacobian_bases(n_b)
            w, deriv = self._features(x, points, speed)
            h[:, 2] += w[:, :2].dot(self._steering_bearing_gain)
            jac = deriv.dot(self._h_maps)
            jac += jac_base
            jac_t = deriv.dot(self._h_maps_t)
            jac_t += jac_base_t
        else:  # H is constant but for its speed row
            return h, *self._constant_jacobians(x, speed)
        # speed row: d|v|/dv_x = v_x / |v|, d|v|/dv_y = v_y / |v| (flat indices (0, VX), (0, VY))
        speed_row = jac[:, VX : VY + 1 : VY - VX]
        np.divide(x[:, VX : VY + 1 : VY - VX], np.maximum(speed, 1e-6)[:, None], out=speed_row)
        jac_t[:, 3 * VX : 3 * VY + 1 : 3 * (VY - VX)] = speed_row
        return h, jac.reshape(n_b, 3, n), jac_t.reshape(n_b, n, 3)

    def _update(
        self,
        x: np.ndarray,
        cov: np.ndarray,
        z: np.ndarray,
        n_comp: int,
        all_observed: bool,
        points: np.ndarray | None,
        linearized: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> tuple[Any, ...]:
        """The update, plus the innovations (B, 3) (0 where missing), diag(S) (B, 3),
        the squared Mahalanobis distances ``nu^T S^-1 nu`` (B,) and, for a few filters (else
        None), the normalized innovations ``nu_c / sqrt(S_cc)`` (B, 3) (before the missing
        channels are set NaN). ``linearized``: :meth:`_linearize` of ``x`` and ``points`` if
        known."""
        n_b = x.shape[0]
        h, jac, jac_t = self._linearize(x, points) if linearized is None else linearized
        if n_b <= _MAX_ROWS_IN_FLOATS:  # each run's row of z for its filters
            innovation = z.take(self._run_of_row(z.shape[0], n_comp), axis=0) - h
        elif n_comp > 1 and z.shape[0] > 1:
            innovation = (z[:, None, :] - h.reshape(-1, n_comp, 3)).reshape(n_b, 3)
        else:  # (one run: its row of z, broadcast)
            innovation = z - h
        r = self.measurement_var
        n_obs: float | np.ndarray = 3.0
        if not all_observed:
            obs_b = np.repeat(~np.isnan(z), n_comp, axis=0)  # (B, 3)
            innovation = np.where(obs_b, innovation, 0.0)
            jac = jac * obs_b[:, :, None]
            jac_t = jac_t * obs_b[:, None, :]
            r = np.where(obs_b, r, 1.0)
            n_obs = obs_b.sum(axis=1)
        hp = jac @ cov  # H P = (P H^T)^T, (B, 3, n)
        s = hp @ jac_t
        s = s.reshape(n_b, 9)
        small = None
        if n_b <= _MAX_ROWS_IN_FLOATS:
            try:
                small = _update_terms_in_floats(s, r, innovation, n_obs)
            except (ZeroDivisionError, ValueError):  # singular, or a negative variance: numpy's
                pass  # infinities and NaNs
        if small is None:
            s_diag = s[:, ::4]  # (s is not written to below)
            s_diag += r
            s_inv, det, mahalanobis_sq, normalized = _inverse_3x3(s, innovation)
        else:
            s_inv, s_diag, log_lik, mahalanobis_sq, normalized = small
        gain_t = s_inv @ hp  # K^T (B, 3, n)
        gain = gain_t.transpose(0, 2, 1)
        x_post = (innovation[:, None, :] @ gain_t)[:, 0, :]
        x_post += x
        # Joseph form (I - K H) P (I - K H)^T + K R K^T, evaluated as
        # A = (I - K H) P = P - K (H P), then A (I - K H)^T + K R K^T
        # = A + (R K^T - (A H^T)^T)^T K^T
        joseph = cov - gain @ hp
        if not all_observed:
            r_col = r[:, :, None]
        elif n_b <= _MAX_ROWS_IN_FLOATS:  # R's diagonal along every row of K^T (B, 3, n)
            r_col = self._tiled(("R", ""), self._measurement_var_rows, n_b)
        else:
            r_col = self._measurement_var_column
        correction = gain_t * r_col
        # transposed operands: for a few filters copied first (the same numbers; numpy's
        # strided loop, and its copy of an operand overlapping the output, cost more there)
        few = n_b <= _MAX_ROWS_IN_FLOATS
        correction_h = (joseph @ jac_t).transpose(0, 2, 1)
        correction -= correction_h.copy() if few else correction_h
        joseph += correction.transpose(0, 2, 1) @ gain_t
        joseph_t = joseph.transpose(0, 2, 1)
        cov_post = joseph
        cov_post += joseph_t.copy() if few else joseph_t
        cov_post *= 0.5
        if small is None:
            if mahalanobis_sq is None:
                mahalanobis_sq = np.einsum("bi,bij,bj->b", innovation, s_inv, innovation)
            log_lik = mahalanobis_sq + np.log(det)
            log_lik += n_obs * _LOG_2PI
            log_lik *= -0.5
        return x_post, cov_post, log_lik, innovation, s_diag, mahalanobis_sq, normalized

    def _run_offsets(self, n_runs: int, n_comp: int) -> np.ndarray:
        """``[0, C, 2C, ...]`` (R,): the flat index of each run's first hypothesis (cached)."""
        cached = self._offsets_cache.get((n_runs, n_comp))
        if cached is None:
            cached = np.arange(0, n_runs * n_comp, n_comp)
            cached.setflags(write=False)
            self._offsets_cache = {(n_runs, n_comp): cached}
        return cached

    def _run_of_row(self, n_runs: int, n_comp: int) -> np.ndarray:
        """``[0, .., 0, 1, .., 1, ...]`` (R C,): the run of each filter (row), to take a run's
        row of an (R, m) operand for each of its filters (cached). For a few filters this
        gather and an operation on equal shapes cost less than numpy's broadcasting of the
        (R, m) operand; the same numbers."""
        cached = self._run_of_row_cache.get((n_runs, n_comp))
        if cached is None:
            cached = np.repeat(np.arange(n_runs), n_comp)
            cached.setflags(write=False)
            self._run_of_row_cache = {(n_runs, n_comp): cached}
        return cached

    def _none_gated(self, n_runs: int) -> np.ndarray:
        """(R, 3) False, read-only (cached): no channel gated."""
        cached = self._none_gated_cache
        if cached is None or cached.shape[0] != n_runs:
            cached = np.zeros((n_runs, 3), dtype=bool)
            cached.setflags(write=False)
            self._none_gated_cache = cached
        return cached

    def _constant_jacobians(
        self, x: np.ndarray, speed: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """H (B, 3, n) and H^T (B, n, 3) at ``x`` (B, n) (``speed`` (B,) its |v|) of a model
        whose H depends on the state through its speed row only
        (``d|v|/dv_x = v_x / max(|v|, 1e-6)``, likewise v_y), written into arrays of the
        constant entries that every call reuses (its callers use them within the step and
        never store them; cached, the largest batch kept and a smaller one taking its first
        rows). For a few filters the speed row is divided in Python floats (the same
        operations; ``max`` keeping a NaN, as ``numpy.maximum``)."""
        n_b, n = x.shape
        cached = self._h_scratch
        if cached is None or cached[0].shape[0] < n_b:
            jac, jac_t = np.tile(self._h_base, (n_b, 1)), np.tile(self._h_base_t, (n_b, 1))
            cached = (jac, jac_t, jac.reshape(n_b, 3, n), jac_t.reshape(n_b, n, 3))
            self._h_scratch = cached
        jac, jac_t, jac_3d, jac_t_3d = cached
        if n_b > _MAX_ROWS_IN_FLOATS:
            speed_row = jac[:n_b, VX : VY + 1 : VY - VX]
            np.divide(x[:, VX : VY + 1 : VY - VX], np.maximum(speed, 1e-6)[:, None], out=speed_row)
            jac_t[:n_b, 3 * VX : 3 * VY + 1 : 3 * (VY - VX)] = speed_row
            return jac_3d[:n_b], jac_t_3d[:n_b]
        # H[b, 0, v] and H^T[b, v, 0] at their flat indices v and 3 v
        for b, (row, v) in enumerate(zip(x.tolist(), speed.tolist(), strict=True)):
            v = v if not v < 1e-6 else 1e-6
            jac[b, VX] = jac_t[b, 3 * VX] = row[VX] / v
            jac[b, VY] = jac_t[b, 3 * VY] = row[VY] / v
        if n_b == jac.shape[0]:
            return jac_3d, jac_t_3d
        return jac_3d[:n_b], jac_t_3d[:n_b]

    def _measurement_jacobian_bases(self, n_b: int) -> tuple[np.ndarray, np.ndarray]:
        """The constant parts of H (B, 3n) and H^T (B, 3n), tiled for B filters (cached)."""
        cached = self._h_cache
        if cached is None or cached[0].shape[0] < n_b:
            cached = (np.tile(self._h_base, (n_b, 1)), np.tile(self._h_base_t, (n_b, 1)))
            self._h_cache = cached  # keep the largest batch; a smaller one takes its first rows
        return cached[0][:n_b], cached[1][:n_b]


# adjugate of a 3x3 matrix s flattened row-major: adj[p] = s[A[p]] s[B[p]] - s[C[p]] s[D[p]]
_COF_A = np.array([4, 2, 1, 5, 0, 2, 3, 1, 0])
_COF_B = np.array([8, 7, 5, 6, 8, 3, 7, 6, 4])
_COF_C = np.array([5, 1, 2, 3, 2, 0, 4, 0, 1])
_COF_D = np.array([7, 8, 4, 8, 6, 5, 6, 7, 3])


def _features_in_floats(
    vx: np.ndarray,
    vy: np.ndarray,
    rows: list[list[float]],
    ratio: list[float],
    inverse: list[float],
    speed: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`FilterMatrices._features` of a few filters (B <= ``_MAX_ROWS_IN_FLOATS``;
    ``rows``: their states, ``x.tolist()``, whose columns ``vx`` and ``vy`` are) from its
    ratios and inverses, flat (2 B) lists (:meth:`FilterMatrices._bearing_ratios_in_floats`):
    the same numpy calls for atan (elementwise: a flat array gives each entry the bits of the
    (B, 2) one), atan2 and hypot, the same arithmetic in Python floats for the rest
    (``max(v^2, 1e-12)`` with a NaN kept, as ``numpy.maximum``)."""
    theta = np.arctan2(vy, vx).tolist()
    bearing = np.arctan(np.array(ratio)).tolist()
    speed_list = (np.hypot(vx, vy) if speed is None else speed).tolist()
    w: list[float] = []
    deriv: list[float] = []
    for b, (row, angle, v) in enumerate(zip(rows, theta, speed_list, strict=True)):
        v_x, v_y = row[VX], row[VY]
        speed_sq = v * v
        if speed_sq < 1e-12:
            speed_sq = 1e-12
        r_near, r_far = ratio[2 * b], ratio[2 * b + 1]
        w += (bearing[2 * b] + angle, bearing[2 * b + 1] + angle, v_y)
        deriv += (
            v_y * (-1.0 / speed_sq),
            v_x * (1.0 / speed_sq),
            inverse[2 * b] / (1.0 + r_near * r_near),
            inverse[2 * b + 1] / (1.0 + r_far * r_far),
        )
    n_b = len(theta)
    return np.array(w).reshape(n_b, 3), np.array(deriv).reshape(n_b, 4)


def _inverse_3x3(
    s: np.ndarray, vectors: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Inverse and determinant of 3x3 matrices given flattened, (B, 9), by the adjugate.

    Cheaper than ``numpy.linalg.inv`` on many small matrices and the same
    arithmetic whatever the batch size. A few matrices are inverted in Python floats (the
    same operations), which also give ``v^T S^-1 v`` of the ``vectors`` (B, 3) in
    ``numpy.einsum``'s order and ``v_c / sqrt(S_cc)`` (B, 3); else (and without vectors) the
    last two results are None.
    """
    if s.shape[0] <= _MAX_ROWS_IN_FLOATS:
        try:
            return _inverse_3x3_in_floats(s, vectors)
        except (ZeroDivisionError, ValueError):  # singular, or a negative variance: numpy's
            pass  # infinities and NaNs
    adjugate = s.take(_COF_A, axis=1)  # (contiguous gathers: faster on a large batch)
    adjugate *= s.take(_COF_B, axis=1)
    adjugate -= s.take(_COF_C, axis=1) * s.take(_COF_D, axis=1)
    det = s[:, 0] * adjugate[:, 0]
    det += s[:, 1] * adjugate[:, 3]
    det += s[:, 2] * adjugate[:, 6]
    adjugate /= det[:, None]
    return adjugate.reshape(-1, 3, 3), det, None, None


def _inverse_3x3_in_floats(
    s: np.ndarray, vectors: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """:func:`_inverse_3x3` in Python floats, unrolled: ``adj_p = s_A s_B - s_C s_D`` (the
    index tables), ``det = (s_0 adj_0 + s_1 adj_3) + s_2 adj_6``, ``inverse = adj / det``;
    raises ZeroDivisionError for a zero determinant. With ``vectors`` v also
    ``v^T S^-1 v`` as ``numpy.einsum("bi,bij,bj->b")`` sums it: ``(v_i S^-1_ij) v_j`` added
    to 0 in the order ij = 00, 01, 02, 10, ..., 22 (a test compares the two), and
    ``v_c / sqrt(S_cc)`` (the square root is correctly rounded in both; ValueError for a
    negative S_cc)."""
    inverses, dets = [], []
    for s0, s1, s2, s3, s4, s5, s6, s7, s8 in s.tolist():
        a0, a1, a2 = s4 * s8 - s5 * s7, s2 * s7 - s1 * s8, s1 * s5 - s2 * s4
        a3, a4, a5 = s5 * s6 - s3 * s8, s0 * s8 - s2 * s6, s2 * s3 - s0 * s5
        a6, a7, a8 = s3 * s7 - s4 * s6, s1 * s6 - s0 * s7, s0 * s4 - s1 * s3
        det = s0 * a0 + s1 * a3
        det += s2 * a6
        inverses.append([a0 / det, a1 / det, a2 / det, a3 / det, a4 / det, a5 / det,
                         a6 / det, a7 / det, a8 / det])  # fmt: skip
        dets.append(det)
    distances = normalized = None
    if vectors is not None:
        distances_list, normalized_list = [], []
        for (v0, v1, v2), (i0, i1, i2, i3, i4, i5, i6, i7, i8), diagonal in zip(
            vectors.tolist(), inverses, s[:, ::4].tolist(), strict=True
        ):
            normalized_list.append([v0 / math.sqrt(diagonal[0]), v1 / math.sqrt(diagonal[1]),
                                    v2 / math.sqrt(diagonal[2])])  # fmt: skip
            total = 0.0 + (v0 * i0) * v0
            total += (v0 * i1) * v1
            total += (v0 * i2) * v2
            total += (v1 * i3) * v0
            total += (v1 * i4) * v1
            total += (v1 * i5) * v2
            total += (v2 * i6) * v0
            total += (v2 * i7) * v1
            total += (v2 * i8) * v2
            distances_list.append(total)
        distances, normalized = np.array(distances_list), np.array(normalized_list)
    return np.array(inverses).reshape(-1, 3, 3), np.array(dets), distances, normalized


def _update_terms_in_floats(
    s: np.ndarray, r: np.ndarray, innovation: np.ndarray, n_obs: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The update's terms of a few filters in Python floats, from ``s = H P H^T`` (B, 9)
    without R: the same operations in the same order as the numpy path (``S = s + diag(R)``,
    :func:`_inverse_3x3_in_floats`, then ``-1/2 ((nu^T S^-1 nu + log det S) + m log 2 pi)``
    with numpy's ``log``), so the same bits; raises as :func:`_inverse_3x3_in_floats` does.

    Args:
        s: (B, 9) ``H P H^T`` flattened row-major.
        r: the diagonal of R, (3,) or (B, 3).
        innovation: nu, (B, 3).
        n_obs: m, the observed rows: a float, or (B,) counts.

    Returns:
        S^-1 (B, 3, 3), diag(S) (B, 3), the log-likelihoods (B,), ``nu^T S^-1 nu`` (B,) and
        ``nu_c / sqrt(S_cc)`` (B, 3).
    """
    rows = s.tolist()
    n_b = len(rows)
    r_rows = [r.tolist()] * n_b if r.ndim == 1 else r.tolist()
    inverses: list[float] = []  # flat, as diagonals and normalized
    diagonals: list[float] = []
    normalized: list[float] = []
    dets, distances = [], []
    for (s0, s1, s2, s3, s4, s5, s6, s7, s8), (r0, r1, r2), (v0, v1, v2) in zip(
        rows, r_rows, innovation.tolist(), strict=True
    ):
        s0 += r0
        s4 += r1
        s8 += r2
        a0, a1, a2 = s4 * s8 - s5 * s7, s2 * s7 - s1 * s8, s1 * s5 - s2 * s4
        a3, a4, a5 = s5 * s6 - s3 * s8, s0 * s8 - s2 * s6, s2 * s3 - s0 * s5
        a6, a7, a8 = s3 * s7 - s4 * s6, s1 * s6 - s0 * s7, s0 * s4 - s1 * s3
        det = s0 * a0 + s1 * a3
        det += s2 * a6
        i0, i1, i2 = a0 / det, a1 / det, a2 / det
        i3, i4, i5 = a3 / det, a4 / det, a5 / det
        i6, i7, i8 = a6 / det, a7 / det, a8 / det
        inverses += (i0, i1, i2, i3, i4, i5, i6, i7, i8)
        dets.append(det)
        diagonals += (s0, s4, s8)
        normalized += (v0 / math.sqrt(s0), v1 / math.sqrt(s4), v2 / math.sqrt(s8))
        # numpy.einsum's order (_inverse_3x3_in_floats), left to right
        distances.append(0.0 + (v0 * i0) * v0 + (v0 * i1) * v1 + (v0 * i2) * v2
                         + (v1 * i3) * v0 + (v1 * i4) * v1 + (v1 * i5) * v2
                         + (v2 * i6) * v0 + (v2 * i7) * v1 + (v2 * i8) * v2)  # fmt: skip
    if isinstance(n_obs, np.ndarray):
        constants = [n * _LOG_2PI for n in n_obs.tolist()]
    else:
        constants = [n_obs * _LOG_2PI] * n_b
    log_lik = [
        ((d + log_det) + c) * -0.5
        for d, log_det, c in zip(distances, np.log(dets).tolist(), constants, strict=True)
    ]
    return (
        np.fromiter(inverses, np.float64, 9 * n_b).reshape(n_b, 3, 3),
        np.array(diagonals).reshape(n_b, 3),
        np.array(log_lik),
        np.array(distances),
        np.array(normalized).reshape(n_b, 3),
    )
