"""The Gaussian-mixture EKF with the human as advisor (paper section 5).

Vectorized over lane hypotheses and over many runs at once: states are
(runs, components, n), covariances (runs, components, n, n).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import KW_ONLY, dataclass, fields, replace
from typing import Any

import numpy as np

from estimators.arx_state_space import (
    BIAS,
    N_PHYSICAL,
    VX,
    VY,
    ARXStateSpace,
    Y,
    check_road_points,
)
from estimators.base import Estimate
from estimators.road_geometry import straight_road_points
from hasa_env.steering.arx import ARXForm

__all__ = ["FilterSettings", "GaussianMixtureEKF", "FilterMatrices"]

_LOG_2PI = math.log(2.0 * math.pi)
_VARIANTS = ("full", "decorrelated", "held")  # transition tables, by code 0, 1, 2
_STEPPED = ("_log_w", "_active", "_steering", "_slow", "_gated_count")
"""Per-run arrays of :class:`GaussianMixtureEKF` that a step reads (and may replace)."""


@dataclass(frozen=True)
class FilterSettings:
    """Noise levels, priors and pruning of the mixture filter (SI units; rad in model units).

    Attributes:
        speed_noise_std: speedometer noise (m/s), R_11 = std^2.
        camera_noise_std: camera lateral-offset noise (m), R_22.
        acceleration_noise_std: IMU noise (m/s^2) on each axis; process noise
            Q = B_D diag(std^2) B_D^T on the vehicle states.
        steering_residual_std: std of the steering model's equation error e(k)
            (rad, model units): the model residual level, which dominates the
            steering channel. R_33 = residual^2 + (ratio * sensor)^2.
        steering_sensor_std: steering-sensor noise (rad, measured units).
        steering_ratio: model units per measured unit: the filter compares
            ``steering_ratio * delta_measured`` with the model (1: the model
            predicts the road-wheel angle the sensor measures).
        initial_speed_std: prior std of v_x around the first speed reading (m/s).
        initial_lateral_std: prior std of y_i around ``camera - b_i`` (m);
            None: camera_noise_std.
        initial_lateral_velocity_std: prior std of v_y around 0 (m/s).
        bias_std: prior std of each hypothesis' bias around b_i (m).
        memory_std: prior std of each memory state around its constant-past
            value (rad, model units).
        bias_drift_std: random-walk std of b per sample (m); 0: constant bias.
        memory_process_std: extra process noise on each memory state per
            sample (rad), for model mismatch beyond the equation error.
        missing_acceleration_std: process noise (m/s^2) used in place of the
            IMU noise when an IMU reading is NaN (the input is then taken as 0).
        prune_threshold: hypotheses whose weight falls below this are pruned
            (weight 0, state frozen); the most likely one is never pruned.
        innovation_gate: outlier gate g on each measurement channel c (speed,
            camera, steering). The channel is missing at this step for every
            hypothesis (never gated per hypothesis: a wrong hypothesis' large
            steering innovations *are* the lane evidence) when no hypothesis
            explains it, each weighed by its log-odds against the most likely
            one (weights w_i before the update)::

                min_i [ nu_ic^2 / S_i,cc + 2 ln(w_max / w_i) ] > g^2

            For the most likely hypothesis the term is its normalized
            innovation, ``|nu_c| / sqrt(S_cc) > g``; a less likely hypothesis
            keeps the channel only if it explains it better by its log-odds,
            so once a lane is decided (``w_max / w_i > exp(g^2 / 2)``, 7e7 for
            g = 6) the test is the most likely hypothesis' alone, while a
            wrong favourite cannot veto the evidence against itself (with the
            favourite's test alone, a 0.99 prior on the wrong lane kept 2 of
            9 synthetic-population runs on it for all 30 s, their steering
            gated at 2997 of 3000 steps). Default 6: a Gaussian channel
            exceeds it with probability 2e-9 per sample; a camera reading
            30 m off is about 600 sigma. ``math.inf`` turns gating off.
        min_speed: below this speed (m/s) the steering channel is off: no
            update from it and no weight from it (the run's mixture speed
            estimate ``sum_i w_i |v_i|`` at k-1 decides, the same for every
            hypothesis), and the memory states are held (``m(k+1) = m(k)``,
            no bearing terms: ``theta = atan2(v_y, v_x)`` and its Jacobian
            ``1 / |v|`` degenerate as v -> 0). When the estimate rises above it
            again the memory states restart from the measured steering and
            each hypothesis' own bearings, as at reset. Default 3 m/s (11
            km/h): the filter's lateral-velocity error is about 0.03 m/s rms
            on the synthetic population (0.005 m/s with a matched model),
            which at 3 m/s tilts theta by 10 mrad, the near-point bearing of
            a 6 cm offset (at 15 m/s: 2 mrad), so the bearings stop carrying
            lane information; and the steering models describe lane keeping
            at road speeds (the paper fits 15-45 m/s), not manoeuvring. 0
            turns it off.
        max_acceleration: IMU readings with |a| above this (m/s^2) are
            implausible and treated as missing, like NaN (input 0 with
            ``missing_acceleration_std``). Default 50 m/s^2 (about 5 g):
            several times what tyres can transmit (about 10 m/s^2), so it
            only catches sensor faults. ``math.inf`` turns it off.
    """

    speed_noise_std: float = 0.05
    camera_noise_std: float = 0.05
    acceleration_noise_std: float = 0.05
    steering_residual_std: float = 2e-3
    steering_sensor_std: float = 1e-4
    steering_ratio: float = 1.0
    initial_speed_std: float = 0.1
    initial_lateral_std: float | None = None
    initial_lateral_velocity_std: float = 0.3
    bias_std: float = 1e-3
    memory_std: float = 0.01
    bias_drift_std: float = 0.0
    memory_process_std: float = 0.0
    missing_acceleration_std: float = 3.0
    prune_threshold: float = 1e-10
    _: KW_ONLY  # the fields below are keyword-only
    innovation_gate: float = 6.0
    min_speed: float = 3.0
    max_acceleration: float = 50.0

    def __post_init__(self) -> None:
        may_be_infinite = ("innovation_gate", "max_acceleration")
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None and f.name == "initial_lateral_std":
                continue
            if not (isinstance(value, int | float) and not math.isnan(value) and value >= 0):
                raise ValueError(f"FilterSettings.{f.name} must be a number >= 0, got {value!r}")
            if math.isinf(value) and f.name not in may_be_infinite:
                raise ValueError(f"FilterSettings.{f.name} must be finite, got {value!r}")
        positive = (
            "speed_noise_std",
            "camera_noise_std",
            "steering_ratio",
            "initial_speed_std",
            *may_be_infinite,
        )
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"FilterSettings.{name} must be > 0, got {getattr(self, name)!r}")
        if self.steering_residual_std == 0 and self.steering_sensor_std == 0:
            raise ValueError("steering_residual_std and steering_sensor_std cannot both be 0")
        if not self.prune_threshold < 1:
            raise ValueError(f"prune_threshold must be < 1, got {self.prune_threshold!r}")

    @classmethod
    def with_overrides(
        cls, settings: FilterSettings | None, overrides: Mapping[str, Any]
    ) -> FilterSettings:
        """``settings`` (default: the defaults) with the named fields replaced."""
        settings = settings or cls()
        return replace(settings, **overrides) if overrides else settings

    @classmethod
    def from_env_config(cls, config: Mapping[str, Any], **overrides: Any) -> FilterSettings:
        """Settings with the sensor noise levels of an env config (``env.unwrapped.config``)."""
        noise = config["noise"]
        values = {
            "speed_noise_std": float(noise["speed"]),
            "camera_noise_std": float(noise["camera"]),
            "acceleration_noise_std": float(noise["imu"]),
            "steering_sensor_std": float(noise["steering"]),
        }
        # a noise-free env would make R singular: keep a floor
        values = {k: max(v, 1e-6) for k, v in values.items()}
        values.update(overrides)
        return cls(**values)


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
        mem = slice(N_PHYSICAL, n)
        s = settings
        input_matrix = model.input_matrix()
        input_outer = input_matrix @ input_matrix.T
        accel_var = s.acceleration_noise_std**2
        q_vehicle = accel_var * input_outer
        q_vehicle[BIAS, BIAS] += s.bias_drift_std**2
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
        p0[mem, mem] = s.memory_std**2 * np.eye(model.n_memory)
        self.initial_covariance = p0
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
            x[..., N_PHYSICAL:] = model.steady_memory(
                np.broadcast_to(steering[:, None], hypotheses.shape), x, points
            )
        return x

    # ------------------------------------------------------ fast-path tables
    def _build_fast_path(self, input_matrix: np.ndarray) -> None:
        """Constant tables of the vectorized filter.

        With ``w = [theta + atan(y/near), theta + atan(y/far), v_y]`` (so
        u = [-w_0, -w_1, w_2]; with road points ``atan((y - dy_near) / dx_near)``
        and ``atan((y - dy_far) / dx_far)``) the transition is ``x' = x A^T +
        w G^T + a B_D^T [+ J z_3]`` and, with ``D = [dtheta/dv_x, dtheta/dv_y,
        d atan(.)/dy (near), d atan(.)/dy (far)]``, its Jacobian is
        ``F = F_0 + sum_k D_k T_k``; likewise ``H = H_0 + sum_k D_k U_k`` plus
        the speed row. The decorrelated, plain and held-memory variants are
        tabulated.
        """
        model = self.model
        n = model.n_states
        mem = slice(N_PHYSICAL, n)
        self.input_matrix_t = np.ascontiguousarray(input_matrix.T)
        sign = np.array([-1.0, -1.0, 1.0])
        base_a = model.transition_matrix_template()
        gains = np.zeros((n, 3))
        gains[mem] = model.bearing_gain * sign
        last = np.zeros(n)
        if model.n_memory:
            last[-1] = 1.0
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
            if model.n_memory:
                linear[2, -1] = 1.0
                h_base[2, -1] = 1.0
            both = beta0[0] + beta0[1]
            h_maps[0, 2, VX] = both
            h_maps[1, 2, VY] = both
            h_maps[2, 2, Y] = beta0[0]
            h_maps[3, 2, Y] = beta0[1]
        self._measurement_linear_t = np.ascontiguousarray(linear.T)
        self._steering_bearing_gain = beta0[:2].copy()
        self._steering_uses_bearings = bool(model.has_steering and np.any(beta0[:2] != 0))
        self._h_base = h_base.ravel().copy()
        self._h_base_t = np.ascontiguousarray(h_base.T).ravel().copy()
        self._h_maps = h_maps.reshape(4, 3 * n).copy()
        self._h_maps_t = np.ascontiguousarray(h_maps.transpose(0, 2, 1)).reshape(4, 3 * n)
        self._h_cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._offsets_cache: dict[tuple[int, int], np.ndarray] = {}
        self._measurement_var_column = self.measurement_var[:, None].copy()
        self._inverse_distance = np.array([1.0 / model.near_distance, 1.0 / model.far_distance])
        self._theta_sign = np.array([-1.0, 1.0])
        self._process_noise_variants = np.stack(
            [self.process_noise, self.process_noise_decorrelated, self.process_noise_vehicle]
        )

    def _features(
        self, x: np.ndarray, points: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """w = [theta + atan(y/near), theta + atan(y/far), v_y] (B, 3) and
        D = [dtheta/dv_x, dtheta/dv_y, d atan(y/near)/dy, d atan(y/far)/dy] (B, 4).

        With ``points`` (B, 4) road points: ``atan((y - dy) / dx)`` and its
        derivative ``(1 / dx) / (1 + ((y - dy) / dx)^2)`` for near and far."""
        vx, vy = x[:, VX], x[:, VY]
        if points is None:
            inverse = self._inverse_distance
            ratio = x[:, Y, None] * inverse
        else:
            inverse = 1.0 / points[:, 0::2]
            ratio = (x[:, Y, None] - points[:, 1::2]) * inverse
        w = np.empty((x.shape[0], 3))
        np.add(np.arctan(ratio), np.arctan2(vy, vx)[:, None], out=w[:, :2])
        w[:, 2] = vy
        deriv = np.empty((x.shape[0], 4))
        # dtheta/dv_x = -v_y / v^2, dtheta/dv_y = v_x / v^2 (x[:, 2::-2] = [v_y, v_x])
        speed_sq = np.hypot(vx, vy)
        speed_sq *= speed_sq
        np.maximum(speed_sq, 1e-12, out=speed_sq)
        np.multiply(x[:, VY::-VY], self._theta_sign / speed_sq[:, None], out=deriv[:, :2])
        np.divide(inverse, 1.0 + ratio * ratio, out=deriv[:, 2:])
        return w, deriv

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
        """
        n_runs = acceleration.shape[0]
        n = x.shape[1]
        any_missing_acc = math.isnan(acceleration.sum())
        if any_missing_acc:
            missing_acc = np.isnan(acceleration)
            acceleration = np.where(missing_acc, 0.0, acceleration)
        if held is not None and not held.any():
            held = None
        known = None
        if self.decorrelates and math.isnan(previous_steering.sum()):
            known = ~np.isnan(previous_steering)
        if held is None and known is None:
            codes = None
            variant = "decorrelated" if self.decorrelates else "full"
        else:
            # per run: 0 plain, 1 decorrelated, 2 memory held
            codes = np.full(n_runs, 1 if self.decorrelates else 0)
            if known is not None:
                codes[~known] = 2 if self.unstable_memory else 0
            if held is not None:
                codes[held] = 2
            variant = _VARIANTS[codes[0]] if np.all(codes == codes[0]) else "mixed"
            if variant != "mixed":
                codes = None
        has_memory = self.model.n_memory > 0
        if has_memory and variant != "held":
            points_b = None if road_points is None else np.repeat(road_points, n_comp, axis=0)
            w, deriv = self._features(x, points_b)

        def propagate(name: str) -> tuple[np.ndarray, np.ndarray]:
            a_t, g_t, jac_base, maps = self._tables[name]
            x_new = x @ a_t
            if not has_memory or name == "held":
                return x_new, np.broadcast_to(jac_base.reshape(n, n), (x.shape[0], n, n))
            x_new += w @ g_t
            jac = deriv @ maps
            jac += jac_base
            return x_new, jac.reshape(-1, n, n)

        drive = acceleration @ self.input_matrix_t  # (R, n)
        if codes is not None:
            codes_b = np.repeat(codes, n_comp)
            x_new = np.empty_like(x)
            jac = np.empty((x.shape[0], n, n))
            for code in np.unique(codes):
                rows = codes_b == code
                x_c, jac_c = propagate(_VARIANTS[code])
                x_new[rows], jac[rows] = x_c[rows], jac_c[rows]
            q = self._process_noise_variants[codes_b]
            decorrelated = codes == 1
            if decorrelated.any():
                steering = np.where(decorrelated, previous_steering, 0.0)
                drive = drive + steering[:, None] * self.steering_gain
        else:
            x_new, jac = propagate(variant)
            q = self._process_noise_variants[_VARIANTS.index(variant)]
            if variant == "decorrelated":
                drive += previous_steering[:, None] * self.steering_gain
        if n_comp == 1:
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
        return x_new, cov_new

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
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`update_batch` with the outlier gate g of :class:`FilterSettings`.

        ``road_points``: (R, 4) road points at this sample (None: straight road).

        Channel c of run r is dropped for every hypothesis of that run when
        no hypothesis explains it, each weighed by its log-odds against the
        most likely one (``log_weights`` (R, C), before the update)::

            min_i [ nu_ic^2 / S_i,cc + 2 (max_j log w_j - log w_i) ] > g^2

        and the update is done without it (see ``innovation_gate``).

        Returns:
            x(k|k) (B, n), P(k|k) (B, n, n), log N(nu; 0, S) (B,) and the
            (R, 3) mask of gated channels.
        """
        points_b = None if road_points is None else np.repeat(road_points, n_comp, axis=0)
        x_post, cov_post, log_lik, innovation, s_diag, distance_sq = self._update(
            x, cov, z, n_comp, all_observed, points_b
        )
        n_runs = z.shape[0]
        if log_weights is None or math.isinf(gate):
            return x_post, cov_post, log_lik, np.zeros((n_runs, 3), dtype=bool)
        # quick exit: the most likely hypothesis explains every channel, its score having no
        # odds; nu_c^2 / S_cc <= nu^T S^-1 nu (Cauchy-Schwarz), so its distance bounds them all
        favourite = log_weights.argmax(axis=1)
        if n_comp > 1:
            favourite += self._run_offsets(n_runs, n_comp)
        if distance_sq[favourite].max() <= gate * gate:
            return x_post, cov_post, log_lik, np.zeros((n_runs, 3), dtype=bool)
        odds = log_weights.max(axis=1, keepdims=True) - log_weights  # (R, C), >= 0 (inf: pruned)
        with np.errstate(over="ignore"):  # a huge reading: an infinite score, gated
            score = (innovation * innovation / s_diag).reshape(n_runs, n_comp, 3)
        score += 2.0 * odds[:, :, None]
        gated = score.min(axis=1) > gate * gate
        if gated.any():
            z = np.where(gated, np.nan, z)
            x_post, cov_post, log_lik, *_ = self._update(x, cov, z, n_comp, False, points_b)
        return x_post, cov_post, log_lik, gated

    def _update(
        self,
        x: np.ndarray,
        cov: np.ndarray,
        z: np.ndarray,
        n_comp: int,
        all_observed: bool,
        points: np.ndarray | None,
    ) -> tuple[np.ndarray, ...]:
        """The update, plus the innovations (B, 3) (0 where missing), diag(S) (B, 3) and
        the squared Mahalanobis distances ``nu^T S^-1 nu`` (B,)."""
        n = x.shape[1]
        n_b = x.shape[0]
        speed = np.hypot(x[:, VX], x[:, VY])
        h = x @ self._measurement_linear_t  # [0, y + b, linear part of h_3]
        h[:, 0] = speed
        jac_base, jac_base_t = self._measurement_jacobian_bases(n_b)
        if self._steering_uses_bearings:
            w, deriv = self._features(x, points)
            h[:, 2] += w[:, :2] @ self._steering_bearing_gain
            jac = deriv @ self._h_maps
            jac += jac_base
            jac_t = deriv @ self._h_maps_t
            jac_t += jac_base_t
        else:
            jac = jac_base.copy()
            jac_t = jac_base_t.copy()
        # speed row: d|v|/dv_x = v_x / |v|, d|v|/dv_y = v_y / |v| (flat indices (0, VX), (0, VY))
        speed_row = x[:, VX : VY + 1 : VY - VX] / np.maximum(speed, 1e-6)[:, None]
        jac[:, VX : VY + 1 : VY - VX] = speed_row
        jac_t[:, 3 * VX : 3 * VY + 1 : 3 * (VY - VX)] = speed_row
        jac = jac.reshape(n_b, 3, n)
        jac_t = jac_t.reshape(n_b, n, 3)
        if n_comp > 1:
            innovation = (z[:, None, :] - h.reshape(-1, n_comp, 3)).reshape(n_b, 3)
        else:
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
        s[:, ::4] += r
        s_diag = s[:, ::4]  # (s is not written to below)
        s_inv, det = _inverse_3x3(s)
        gain_t = s_inv @ hp  # K^T (B, 3, n)
        gain = gain_t.transpose(0, 2, 1)
        x_post = (innovation[:, None, :] @ gain_t)[:, 0, :]
        x_post += x
        # Joseph form (I - K H) P (I - K H)^T + K R K^T, evaluated as
        # A = (I - K H) P = P - K (H P), then A (I - K H)^T + K R K^T
        # = A + (R K^T - (A H^T)^T)^T K^T
        joseph = cov - gain @ hp
        r_col = self._measurement_var_column if np.ndim(r) == 1 else r[:, :, None]
        correction = gain_t * r_col
        correction -= (joseph @ jac_t).transpose(0, 2, 1)
        joseph += correction.transpose(0, 2, 1) @ gain_t
        cov_post = joseph
        cov_post += joseph.transpose(0, 2, 1)
        cov_post *= 0.5
        mahalanobis_sq = np.einsum("bi,bij,bj->b", innovation, s_inv, innovation)
        log_lik = mahalanobis_sq + np.log(det)
        log_lik += n_obs * _LOG_2PI
        log_lik *= -0.5
        return x_post, cov_post, log_lik, innovation, s_diag, mahalanobis_sq

    def _run_offsets(self, n_runs: int, n_comp: int) -> np.ndarray:
        """``[0, C, 2C, ...]`` (R,): the flat index of each run's first hypothesis (cached)."""
        cached = self._offsets_cache.get((n_runs, n_comp))
        if cached is None:
            cached = np.arange(0, n_runs * n_comp, n_comp)
            cached.setflags(write=False)
            self._offsets_cache = {(n_runs, n_comp): cached}
        return cached

    def _measurement_jacobian_bases(self, n_b: int) -> tuple[np.ndarray, np.ndarray]:
        """The constant parts of H (B, 3n) and H^T (B, 3n), tiled for B filters (cached)."""
        cached = self._h_cache.get(n_b)
        if cached is None:
            cached = (np.tile(self._h_base, (n_b, 1)), np.tile(self._h_base_t, (n_b, 1)))
            self._h_cache = {n_b: cached}  # keep only the latest batch size
        return cached


# adjugate of a 3x3 matrix s flattened row-major: adj[p] = s[A[p]] s[B[p]] - s[C[p]] s[D[p]]
_COF_A = np.array([4, 2, 1, 5, 0, 2, 3, 1, 0])
_COF_B = np.array([8, 7, 5, 6, 8, 3, 7, 6, 4])
_COF_C = np.array([5, 1, 2, 3, 2, 0, 4, 0, 1])
_COF_D = np.array([7, 8, 4, 8, 6, 5, 6, 7, 3])


def _inverse_3x3(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of 3x3 matrices given flattened, (B, 9), by the adjugate.

    Cheaper than ``numpy.linalg.inv`` on many small matrices and the same
    arithmetic whatever the batch size.
    """
    adjugate = s.take(_COF_A, axis=1)
    adjugate *= s.take(_COF_B, axis=1)
    adjugate -= s.take(_COF_C, axis=1) * s.take(_COF_D, axis=1)
    det = s[:, 0] * adjugate[:, 0]
    det += s[:, 1] * adjugate[:, 3]
    det += s[:, 2] * adjugate[:, 6]
    adjugate /= det[:, None]
    return adjugate.reshape(-1, 3, 3), det


class GaussianMixtureEKF:
    """Gaussian-mixture extended Kalman filter: one EKF per lane hypothesis.

    The human's steering, through an ARX steering model, tells the lanes
    apart (paper section 5; DESIGN.md section 5). State of hypothesis i:
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
      estimate at k-1) the steering row is dropped (no update, no weight)
      and the memory is held (:class:`FilterMatrices`); at the first estimate
      above it with a finite steering reading z_3(k), the memory of every
      active hypothesis restarts as at reset,
      ``m_i = steady_memory(z_3(k), x_i(k|k))``, ``P_mm = memory_std^2 I``,
      uncorrelated with the vehicle states (:attr:`low_speed`).

    Road geometry: with ``road_points`` (:mod:`estimators.road_geometry`) the
    bearings are those of the lane centre ahead on a curved road
    (:mod:`estimators.arx_state_space`); the prediction k -> k+1 uses the
    points given at k, the update at k those given at k.

    Every array holds R runs x C hypotheses; one call of :meth:`step`
    filters all of them.

    Where this differs from the paper (DESIGN.md sections 5 and 7):

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
        self._min_speed = settings.min_speed if self.model.has_steering else 0.0
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
    def low_speed(self) -> np.ndarray:
        """Runs whose steering channel is off (speed estimate below ``min_speed``):
        (R,) bool (a single run: one bool)."""
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
        measurement = np.asarray(measurement, dtype=np.float64)
        single = measurement.ndim == 1
        z = measurement.reshape(1, -1) if single else measurement
        if z.ndim != 2 or z.shape[1] != 3:
            raise ValueError(f"measurement must have shape (3,) or (R, 3), got {measurement.shape}")
        n_runs = z.shape[0]
        hyp = np.asarray(hypotheses, dtype=np.float64)
        if hyp.ndim == 1:
            hyp = np.broadcast_to(hyp, (n_runs, hyp.size))
        if hyp.ndim != 2 or hyp.shape[0] != n_runs or hyp.shape[1] < 1:
            raise ValueError(
                f"hypotheses must have shape (C,) or ({n_runs}, C), got {np.shape(hypotheses)}"
            )
        if not np.all(np.isfinite(hyp)):
            raise ValueError("hypotheses must be finite")
        n_comp = hyp.shape[1]
        if prior is None:
            log_w = np.full((n_runs, n_comp), -math.log(n_comp))
        else:
            p = np.broadcast_to(np.asarray(prior, dtype=np.float64), (n_runs, n_comp))
            if np.any(~np.isfinite(p)) or np.any(p < 0) or not np.allclose(p.sum(axis=1), 1.0):
                raise ValueError("prior must be non-negative and sum to 1 over the hypotheses")
            with np.errstate(divide="ignore"):
                log_w = np.log(p / p.sum(axis=1, keepdims=True))
        points = _as_points(road_points, n_runs)
        if points is None:
            x = self.matrices.initial_state(z, hyp)
        else:
            x = self.matrices.initial_state(z, hyp, road_points=points)
        n = x.shape[-1]
        cov = np.empty(x.shape + (n,))
        cov[:] = self.matrices.initial_covariance
        x, cov = x.reshape(-1, n), cov.reshape(-1, n, n)
        steering = z[:, 2] * self.settings.steering_ratio
        steering = np.where(np.isfinite(steering), steering, np.nan)
        state = {
            "_log_w": log_w,
            "_active": np.isfinite(log_w),
            "_hyp": hyp.copy(),
            "_steering": steering,
            "_slow": (z[:, 0] < self._min_speed) & (self._min_speed > 0),
            "_gated": np.zeros((n_runs, 3), dtype=bool),
            "_gated_count": np.zeros((n_runs, 3), dtype=np.int64),
        }
        if runs is None:
            self._single = single
            self._n_comp = n_comp
            self._x, self._P, self._points = x, cov, points
            for name, value in state.items():
                setattr(self, name, value)
        else:
            idx = self._check_runs(runs, n_runs, n_comp)
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
            points = _as_points(road_points, z.shape[0])
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
            points = _as_points(road_points, idx.size)
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
        n_comp = log_w.shape[1]
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
        x_post, cov_post, log_lik, gated = mats.gated_update_batch(
            x_pred,
            cov_pred,
            z,
            n_comp,
            all_observed,
            road_points=points,
            gate=settings.innovation_gate,
            log_weights=log_w,
        )
        # ---- weights (log space)
        new_log_w = log_w + log_lik.reshape(log_w.shape)
        all_active = active.all()
        if not all_active:
            new_log_w = np.where(active, new_log_w, -np.inf)
        new_log_w = _normalize_log_weights(new_log_w, log_w)
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
                new_log_w = _normalize_log_weights(
                    np.where(new_active, new_log_w, -np.inf), new_log_w
                )
        # ---- low speed: steering off below min_speed, memory restarted above it
        new_slow = slow
        restart = None
        if self._min_speed > 0 and (any_slow or x_post[:, VX].min() < self._min_speed):
            # (|v_i| >= v_x,i >= min_speed for all i: no run is slow)
            speed = np.hypot(x_post[:, VX], x_post[:, VY]).reshape(log_w.shape)
            new_slow = np.einsum("rc,rc->r", np.exp(new_log_w), speed) < self._min_speed
            if any_slow:
                # leave the low-speed mode only with a steering reading to restart from
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
        }
        if any_gated:
            new["_gated_count"] = run["_gated_count"] + gated
        return x_post, cov_post, new

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


def _as_points(road_points: np.ndarray | None, n_rows: int) -> np.ndarray | None:
    """Road points as (n_rows, 4) float64 (a (4,) row is shared by all runs), or None."""
    if road_points is None:
        return None
    points = check_road_points(road_points)
    if points.ndim == 1:
        return np.broadcast_to(points, (n_rows, 4))
    if points.shape != (n_rows, 4):
        raise ValueError(f"road_points must have shape (4,) or ({n_rows}, 4), got {points.shape}")
    return points


def _plausible_acceleration(acc: np.ndarray, limit: float) -> np.ndarray:
    """The IMU input with non-finite entries and entries beyond +-``limit`` (m/s^2) set to NaN."""
    if math.isinf(limit):
        if math.isfinite(acc.sum()):
            return acc
        return np.where(np.isfinite(acc), acc, np.nan)
    if np.abs(acc).max() <= limit:  # False with a NaN
        return acc
    return np.where(np.abs(acc) <= limit, acc, np.nan)


def _normalize_log_weights(log_w: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """``log_w - logsumexp(log_w)`` per run; a run whose weights all vanished keeps ``fallback``."""
    total = np.logaddexp.reduce(log_w, axis=1, keepdims=True)  # logsumexp, stable
    if math.isfinite(total.sum()):
        return log_w - total
    ok = np.isfinite(total)
    with np.errstate(invalid="ignore"):
        return np.where(ok, log_w - total, fallback)
