"""The augmented state-space model: vehicle + bias + an ARX steering model's memory.

Paper section 4.1 (eqs. 11-14), generalised to any ARX order and corrected
as in docs/design.md §8.2. Equation numbers count the equations of the
paper's source (``paper/000_27bb222d17a6bc2b.txt``): (4) discrete vehicle
model, (5)-(6) bearings, (8) generalized steering model, (10) its fitted
form, (11) augmented transition, (12) sensor model, (13) A_h, (14) C_h,
(15)-(18) EKF correction, (19) weights, (20) initial mixture.

State (SI units), for an ARX steering model with ``n`` memory states::

    x = [v_x, y, v_y, b, m_1, ..., m_n]

``v_x`` longitudinal and ``v_y`` lateral road-frame velocity (m/s), ``y``
lateral offset from the lane centre of this hypothesis (m), ``b`` camera bias
(m), ``m_i`` the memory states (rad) of the steering model in observer
canonical form. With no steering model (``arx=None``) the state is the first
four entries (paper eq. 4).

Driver's preferred offset (``preferred_offset=True``; docs/design.md §8.18). People keep
the car off the lane centre by a lateral offset p of their own (a few tenths of a metre);
a model that assumes they aim at the centre reads a sustained offset as lane evidence,
without bound. With the option the state gains p after the bias::

    x = [v_x, y, v_y, b, p, m_1, ..., m_n],     p(k+1) = p(k)  (+ a slow random walk)

and the driver's features are taken from the offset to the point they aim at, y - p, in
place of y (every ``y`` in the bearings below reads ``y - p``; d/dp = -d/dy). The camera
still measures y + b. On a straight road a hypothesis off by d then explains the steering
as well as the true one with p off by d: what tells the lanes apart is p's prior
N(0, sigma_p^2), transients and the road's curvature, so the evidence of a sustained offset
is bounded by the prior instead of growing with time.

Coloured equation error (``coloured_error_correlation=rho``; docs/design.md §8.34). A driver's
command noise that enters before the neuromuscular lag leaves a model of the steering with an
equation error that is autocorrelated and scales with the speed (the steering a given lateral
acceleration needs goes as ``1 / v^2``). With the option the equation error is
``e(k) = epsilon(k) + w(k)``, w white, and epsilon a state after the bias (and p)::

    x = [v_x, y, v_y, b, (p,) epsilon, m_1, ..., m_n],   epsilon(k+1) = rho epsilon(k) + eta(k)

``eta``'s variance is set per sample by the filter (``(v_ref / v)^4`` times its level at the
reference speed, :func:`hasa_env.steering.equation_error.speed_scale` squared). epsilon enters the steering as e does: ``h3 = m_n + beta_0 . u + epsilon``,
and each memory state receives ``a_{n-i+1} epsilon(k)`` with ``a_{n-i+1} delta(k)``.

Visual features of a state (docs/design.md §5.1 and §5.2). With the road points
``p = (dx_near, dy_near, dx_far, dy_far)`` (m) of the lane centre ahead in
the road-tangent frame at the car (:mod:`estimators.road_geometry`; a known
input per step)::

    theta = atan2(v_y, v_x)
    phi   = atan2(dy_near - y, dx_near) - theta      near-point bearing (rad)
    Omega = atan2(dy_far - y, dx_far) - theta        far-point bearing (rad)
    u     = [phi, Omega, v_y]

Without road points (``road_points=None``) the road is straight,
``p = (near, 0, far, 0)``, and the straight-road formulas are used as written::

    phi   = -(theta + atan(y / near)),    Omega = -(theta + atan(y / far))

Steering model (paper eq. 8, fitted form eq. 10; ``a_j`` multiplies delta(k-j), ``beta_j``
the vector (b_j, c_j, d_j) multiplying u(k-j), zero beyond each order)::

    delta(k) = sum_{j=1}^{n} a_j delta(k-j) + sum_{j=0}^{n} beta_j . u(k-j) + e(k)

Observer canonical form (the corrected, non-circular g_i of paper eq. 11; for the
paper's order it is the g1, g2, g3 and h3 of docs/design.md §8.3)::

    delta(k)   = m_n(k) + beta_0 . u(k) + e(k)                                 (h3)
    m_i(k+1)   = a_{n-i+1} delta(k) + beta_{n-i+1} . u(k) + m_{i-1}(k),  m_0 = 0
               = a_{n-i+1} m_n + (beta_{n-i+1} + a_{n-i+1} beta_0) . u + m_{i-1}
                 + a_{n-i+1} e(k)                                              (g_i)

Vehicle (paper eq. 4) with the IMU's road-frame accelerations as inputs::

    v_x(k+1) = v_x + Ts a_x
    y(k+1)   = y + Ts v_y + Ts^2 / 2 a_y
    v_y(k+1) = v_y + Ts a_y
    b(k+1)   = b

Measurements (paper eq. 12, with the erratum of docs/design.md §10: the speedometer
measures the speed, so h1 is the exact speed, not v_x)::

    h1 = sqrt(v_x^2 + v_y^2)      speedometer (m/s)
    h2 = y + b                    camera (m)
    h3 = m_n + beta_0 . u         steering, in the model's units (rad)

Jacobians (paper eqs. 13-14, exact: docs/design.md §10 notes the paper's A_h has
a_2 c_0 / 6.2 where / 20 belongs, and its entries are small-angle ones)::

    d theta / d v_x = -v_y / (v_x^2 + v_y^2),   d theta / d v_y = v_x / (v_x^2 + v_y^2)
    d phi / d y     = -dx_near / (dx_near^2 + (dy_near - y)^2)     (straight: -near / (near^2 + y^2))
    d Omega / d y   = -dx_far / (dx_far^2 + (dy_far - y)^2)
    d phi / d v     = d Omega / d v = -d theta / d v        (v = v_x or v_y)

The transition uses the road points at the state's own sample (k, for
x(k) -> x(k+1)), the measurement those at the measured sample.

All functions accept any leading batch shape (``x[..., n_states]``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from hasa_env.steering.arx import FAR_POINT_DISTANCE, NEAR_POINT_DISTANCE, ARXForm

__all__ = [
    "ARXStateSpace",
    "PHYSICAL_STATE_NAMES",
    "MEASUREMENT_NAMES",
    "check_road_points",
    "road_curvature_ahead",
    "road_point_rows",
]

PHYSICAL_STATE_NAMES = ("longitudinal_velocity", "lateral_offset", "lateral_velocity", "bias")
"""Names of the first four states (m/s, m, m/s, m)."""

MEASUREMENT_NAMES = ("speed", "camera_lateral", "steering")
"""Rows of the measurement vector (m/s, m, rad)."""

VX, Y, VY, BIAS = 0, 1, 2, 3
N_PHYSICAL = 4
PREFERRED_OFFSET = 4
"""Index of the driver's preferred offset p when the model has it (``preferred_offset=True``)."""
_MIN_SPEED_SQ = 1e-12  # floor of v_x^2 + v_y^2 (m^2/s^2) against division by zero


def check_road_points(road_points: np.ndarray) -> np.ndarray:
    """``road_points`` as a float64 array (..., 4), checked: finite, with dx_near, dx_far > 0.

    Raises:
        ValueError: naming the problem (wrong last axis, non-finite values, a
            point not ahead of the car).
    """
    points = np.asarray(road_points, dtype=np.float64)
    if points.ndim == 0 or points.shape[-1] != 4:
        raise ValueError(
            "road_points must have a last axis of 4 (dx_near, dy_near, dx_far, dy_far) (m), "
            f"got shape {points.shape}"
        )
    ahead = points[..., 0::2]
    if not (np.all(np.isfinite(points)) and np.all(ahead > 0)):
        raise ValueError(
            "road_points must be finite with dx_near > 0 and dx_far > 0 (points ahead of the "
            "car, m)"
        )
    return points


def road_point_rows(road_points: np.ndarray | None, n_rows: int) -> np.ndarray | None:
    """Road points as (n_rows, 4) float64, checked (a (4,) row is shared by all runs), or
    None (a straight road)."""
    if road_points is None:
        return None
    points = check_road_points(road_points)
    if points.ndim == 1:
        return np.broadcast_to(points, (n_rows, 4))
    if points.shape != (n_rows, 4):
        raise ValueError(f"road_points must have shape (4,) or ({n_rows}, 4), got {points.shape}")
    return points


def road_curvature_ahead(points: np.ndarray | None, n_rows: int) -> np.ndarray:
    """(n_rows,) the road's curvature kappa (1/m, left positive) read from road points (R, 4)
    (None or NaN: straight, 0): the circle tangent to the lane centre at the car's station
    through the near point, ``kappa = 2 dy_near / (dx_near^2 + dy_near^2)``."""
    if points is None:
        return np.zeros(n_rows)
    dx, dy = points[:, 0], points[:, 1]
    kappa = 2.0 * dy / (dx * dx + dy * dy)
    return np.where(np.isfinite(kappa), kappa, 0.0)


@dataclass(frozen=True, eq=False, init=False)
class ARXStateSpace:
    """The augmented model of a car and an ARX steering model, for any ARX orders.

    Args:
        arx: the steering model's ARX description, or None for the vehicle
            and bias only (the no-steering baseline; then h3 = 0).
        dt: sample time Ts (s); defaults to ``arx.dt`` (0.01 s without a model).
        decision_lag: samples between the state the driver saw and the
            steering measurement the model predicts. 0: the paper's eq. 10 as
            written (delta(k) uses u(k)); 1: a recording's alignment, where
            row k's steering was applied over the step ending at row k and so
            decided from row k-1 (:mod:`hasa_env.steering.features`, default
            ``decision_lag=1``). The lag shifts beta by that many samples
            (beta'_{j+lag} = beta_j), adding ``decision_lag`` memory states.
        preferred_offset: add the driver's preferred offset p as a state (after the
            bias; module docstring); the bearings are taken from y - p.
        coloured_error_correlation: rho of a coloured equation error carried as a state
            epsilon (module docstring); None: none (the equation error is white).

    Attributes:
        lagged_arx: the ARX description with the decision lag applied (the
            model the memory states realise).
        n_memory: number of memory states n = ``lagged_arx.memory_order``
            (0 without a model); the paper's order with lag 0 gives 3.
        n_physical: 4, or 5 with the preferred offset: the memory states start here.
        n_states: n_physical + n_memory (paper order: 7).
        feedback: (n_memory,) vector ``[a_n, ..., a_1]``: memory state m_i receives
            a_{n-i+1} delta(k).
        bearing_gain: (n_memory, 3) matrix; row i is ``beta_{n-i+1} + a_{n-i+1} beta_0``,
            the gain from u(k) to m_i(k+1).
        output_gain: (3,) vector ``beta_0 = (b_0, c_0, d_0)``.
        memory_matrix: (n_memory, n_memory): d m(k+1) / d m(k) (shift + feedback on m_n).
    """

    arx: ARXForm | None
    dt: float
    decision_lag: int = 0
    preferred_offset: bool = False
    coloured_error_correlation: float | None = None
    lagged_arx: ARXForm | None = field(init=False, repr=False)
    n_memory: int = field(init=False)
    feedback: np.ndarray = field(init=False, repr=False)
    bearing_gain: np.ndarray = field(init=False, repr=False)
    output_gain: np.ndarray = field(init=False, repr=False)
    memory_matrix: np.ndarray = field(init=False, repr=False)
    near_distance: float = field(init=False)
    far_distance: float = field(init=False)

    def __init__(
        self,
        arx: ARXForm | None,
        dt: float | None = None,
        decision_lag: int = 0,
        preferred_offset: bool = False,
        coloured_error_correlation: float | None = None,
    ) -> None:
        if dt is None:
            dt = arx.dt if arx is not None else 0.01
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        object.__setattr__(self, "arx", arx)
        object.__setattr__(self, "dt", float(dt))
        object.__setattr__(self, "decision_lag", decision_lag)
        object.__setattr__(self, "preferred_offset", bool(preferred_offset))
        if coloured_error_correlation is not None:
            rho = float(coloured_error_correlation)
            if arx is None or not (0.0 <= rho < 1.0):
                raise ValueError(
                    "coloured_error_correlation must be in [0, 1) and needs a steering model, "
                    f"got {coloured_error_correlation!r}"
                )
            coloured_error_correlation = rho
        object.__setattr__(self, "coloured_error_correlation", coloured_error_correlation)
        lag = decision_lag
        if isinstance(lag, bool) or not isinstance(lag, int | np.integer) or lag < 0:
            raise ValueError(f"decision_lag must be a non-negative integer, got {lag!r}")
        if arx is not None and lag:
            pad = (0.0,) * int(lag)
            arx = replace(
                arx, b=pad + arx.b, c=pad + arx.c if arx.c else (), d=pad + arx.d if arx.d else ()
            )
        if arx is None:
            n = 0
            near, far = NEAR_POINT_DISTANCE, FAR_POINT_DISTANCE
            a = np.zeros(0)
            beta = np.zeros((1, 3))
        else:
            n = arx.memory_order
            near, far = arx.near_distance, arx.far_distance
            a = np.zeros(n + 1)  # a[j] multiplies delta(k-j); a[0] unused
            a[1 : len(arx.a) + 1] = arx.a
            beta = np.zeros((n + 1, 3))  # beta[j] multiplies u(k-j)
            for column, coefficients in enumerate((arx.b, arx.c, arx.d)):
                beta[: len(coefficients), column] = coefficients
        # memory state i (1-based) is fed by lag j = n - i + 1
        lags = np.arange(n, 0, -1)
        feedback = a[lags] if n else np.zeros(0)
        bearing_gain = (beta[lags] + feedback[:, None] * beta[0]) if n else np.zeros((0, 3))
        memory_matrix = np.zeros((n, n))
        if n:
            memory_matrix[np.arange(1, n), np.arange(n - 1)] = 1.0
            memory_matrix[:, n - 1] += feedback
        for name, value in (
            ("lagged_arx", arx),
            ("n_memory", n),
            ("feedback", feedback),
            ("bearing_gain", bearing_gain),
            ("output_gain", beta[0].copy()),
            ("memory_matrix", memory_matrix),
            ("near_distance", float(near)),
            ("far_distance", float(far)),
        ):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------ structure
    @property
    def n_physical(self) -> int:
        """States before the memory: 4, plus one for the preferred offset and one for the
        coloured equation error."""
        return N_PHYSICAL + int(self.preferred_offset) + int(self.coloured_error)

    @property
    def coloured_error(self) -> bool:
        """True when the equation error has a coloured part carried as a state."""
        return self.coloured_error_correlation is not None

    @property
    def coloured_error_index(self) -> int:
        """Where epsilon lies in the state vector (the state before the memory); only with
        :attr:`coloured_error`."""
        return N_PHYSICAL + int(self.preferred_offset)

    @property
    def memory_slice(self) -> slice:
        """Where the memory states lie in the state vector: ``n_physical:n_states``."""
        return slice(self.n_physical, self.n_states)

    @property
    def n_states(self) -> int:
        """Length of the state vector, n_physical + n_memory."""
        return self.n_physical + self.n_memory

    @property
    def has_steering(self) -> bool:
        """True when the model predicts the steering measurement."""
        return self.arx is not None

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the states: the four physical ones, ``preferred_offset`` and
        ``coloured_error`` when the model has them, then ``memory_1`` .. ``memory_n``."""
        extra: tuple[str, ...] = ("preferred_offset",) if self.preferred_offset else ()
        extra += ("coloured_error",) if self.coloured_error else ()
        memory = tuple(f"memory_{i}" for i in range(1, self.n_memory + 1))
        return PHYSICAL_STATE_NAMES + extra + memory

    def steering_state_row(self) -> np.ndarray:
        """(n_states,): the states h3 reads linearly, each with coefficient 1: the last memory
        state m_n and, with the coloured equation error, epsilon (zeros without a model)."""
        row = np.zeros(self.n_states)
        if self.has_steering and self.n_memory:
            row[-1] = 1.0
        if self.coloured_error:
            row[self.coloured_error_index] = 1.0
        return row

    def transition_matrix_template(self) -> np.ndarray:
        """The state-independent part of dF/dx (paper eq. 13) as an (n, n) array."""
        n = self.n_states
        out = np.eye(n)
        out[Y, VY] = self.dt
        mem = self.memory_slice
        out[mem, mem] = self.memory_matrix
        if self.coloured_error:
            eps = self.coloured_error_index
            out[eps, eps] = self.coloured_error_correlation
            out[mem, eps] = self.feedback
        return out

    def held_memory_transition_matrix(self) -> np.ndarray:
        """dF/dx (n, n) of the transition with the memory states held (below ``min_speed``).

        The vehicle rows of :meth:`transition_matrix_template` (paper eq. 4) and
        the identity on the memory block: ``m(k+1) = m(k)``, no bearing terms.
        """
        out = self.transition_matrix_template()
        mem = self.memory_slice
        out[mem, mem] = np.eye(self.n_memory)
        if self.coloured_error:
            out[mem, self.coloured_error_index] = 0.0
        return out

    def input_matrix(self) -> np.ndarray:
        """B_D (paper eq. 4/11): (n, 2) map of (a_x, a_y) into the state."""
        dt = self.dt
        out = np.zeros((self.n_states, 2))
        out[VX, 0] = dt
        out[Y, 1] = 0.5 * dt * dt
        out[VY, 1] = dt
        return out

    # ------------------------------------------------------------- features
    def bearings(
        self,
        x: np.ndarray,
        with_jacobian: bool = False,
        road_points: np.ndarray | None = None,
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Features u = [phi, Omega, v_y] of states ``x[..., n_states]`` (at least the first 3).

        Args:
            x: states, shape (..., >= 3).
            with_jacobian: also return du/d(v_x, y, v_y).
            road_points: (..., 4) or (4,) road points (dx_near, dy_near, dx_far,
                dy_far) (m) at the states' sample; None: a straight road.

        Returns u with shape (..., 3) and, with ``with_jacobian``, du/d(v_x, y, v_y)
        with shape (..., 3, 3) (rows: phi, Omega, v_y; columns: v_x, y, v_y). With the
        preferred offset, y is read as y - p (and du/dp = -du/dy).
        """
        vx, y, vy = x[..., VX], x[..., Y], x[..., VY]
        if self.preferred_offset:
            y = y - x[..., PREFERRED_OFFSET]
        theta = np.arctan2(vy, vx)
        u = np.empty(x.shape[:-1] + (3,))
        if road_points is None:
            near, far = self.near_distance, self.far_distance
            u[..., 0] = -(theta + np.arctan(y / near))
            u[..., 1] = -(theta + np.arctan(y / far))
            across: tuple[
                tuple[float | np.ndarray, float | np.ndarray], tuple[np.ndarray, np.ndarray]
            ]
            across = (near, far), (y, y)
        else:
            points = check_road_points(road_points)
            dx_near, dx_far = points[..., 0], points[..., 2]
            off_near, off_far = y - points[..., 1], y - points[..., 3]
            # atan(off / dx), not atan2: the same arithmetic as the straight road's for
            # dy = 0 (dx > 0 is checked), so a straight run's filter is the same to the bit
            # with road points (near, 0, far, 0) as without (a batch mixing tracks)
            u[..., 0] = -(theta + np.arctan(off_near / dx_near))
            u[..., 1] = -(theta + np.arctan(off_far / dx_far))
            across = (dx_near, dx_far), (off_near, off_far)
        u[..., 2] = vy
        if not with_jacobian:
            return u
        speed_sq = np.maximum(vx * vx + vy * vy, _MIN_SPEED_SQ)
        dtheta_dvx = -vy / speed_sq
        dtheta_dvy = vx / speed_sq
        du = np.zeros(x.shape[:-1] + (3, 3))
        du[..., 0, 0] = du[..., 1, 0] = -dtheta_dvx
        du[..., 0, 2] = du[..., 1, 2] = -dtheta_dvy
        (d_near, d_far), (o_near, o_far) = across
        du[..., 0, 1] = -d_near / (d_near * d_near + o_near * o_near)
        du[..., 1, 1] = -d_far / (d_far * d_far + o_far * o_far)
        du[..., 2, 2] = 1.0
        return u, du

    # ------------------------------------------------------------ transition
    def transition(
        self,
        x: np.ndarray,
        acceleration: np.ndarray,
        road_points: np.ndarray | None = None,
    ) -> np.ndarray:
        """F(x) + B_D [a_x, a_y] (paper eq. 11 without noise): the state one sample later.

        Args:
            x: states, shape (..., n_states).
            acceleration: road-frame accelerations (a_x, a_y) (m/s^2) over the
                sample, shape broadcastable to (..., 2).
            road_points: road points at x's sample (see :meth:`bearings`); None: straight.
        """
        acceleration = np.asarray(acceleration, dtype=np.float64)
        dt = self.dt
        out = np.empty(np.broadcast_shapes(x.shape, acceleration.shape[:-1] + (1,)))
        ax, ay = acceleration[..., 0], acceleration[..., 1]
        vy = x[..., VY]
        out[..., VX] = x[..., VX] + dt * ax
        out[..., Y] = x[..., Y] + dt * vy + (0.5 * dt * dt) * ay
        out[..., VY] = vy + dt * ay
        out[..., BIAS] = x[..., BIAS]
        if self.preferred_offset:
            out[..., PREFERRED_OFFSET] = x[..., PREFERRED_OFFSET]
        if self.coloured_error:
            eps = self.coloured_error_index
            out[..., eps] = self.coloured_error_correlation * x[..., eps]
        if self.n_memory:
            u = self.bearings(x, road_points=road_points)
            mem = self.memory_slice
            out[..., mem] = x[..., mem] @ self.memory_matrix.T + u @ self.bearing_gain.T
            if self.coloured_error:
                out[..., mem] += x[..., self.coloured_error_index, None] * self.feedback
        return out

    def transition_jacobian(
        self, x: np.ndarray, road_points: np.ndarray | None = None
    ) -> np.ndarray:
        """dF/dx at ``x[..., n_states]`` (paper eq. 13, exact), shape (..., n, n).

        ``road_points``: at x's sample (see :meth:`bearings`); None: straight road.
        """
        out = np.broadcast_to(
            self.transition_matrix_template(), x.shape[:-1] + (self.n_states,) * 2
        ).copy()
        if self.n_memory:
            _, du = self.bearings(x, with_jacobian=True, road_points=road_points)
            mem = self.memory_slice
            out[..., mem, :3] = self.bearing_gain @ du
            if self.preferred_offset:
                out[..., mem, PREFERRED_OFFSET] = -out[..., mem, Y]
        return out

    # ----------------------------------------------------------- measurement
    def measurement(self, x: np.ndarray, road_points: np.ndarray | None = None) -> np.ndarray:
        """h(x) = [speed, y + b, predicted steering] (paper eq. 12), shape (..., 3).

        ``road_points``: at the measured sample (see :meth:`bearings`); None: straight road.
        """
        out = np.empty(x.shape[:-1] + (3,))
        vx, vy = x[..., VX], x[..., VY]
        out[..., 0] = np.sqrt(vx * vx + vy * vy)
        out[..., 1] = x[..., Y] + x[..., BIAS]
        out[..., 2] = self.predicted_steering(x, road_points)
        return out

    def predicted_steering(
        self, x: np.ndarray, road_points: np.ndarray | None = None
    ) -> np.ndarray:
        """h3(x) = m_n + beta_0 . u(x) (+ epsilon) (rad, model units), shape (...)."""
        if not self.has_steering:
            return np.zeros(x.shape[:-1])
        value = self.bearings(x, road_points=road_points) @ self.output_gain
        if self.n_memory:
            value = value + x[..., -1]
        if self.coloured_error:
            value = value + x[..., self.coloured_error_index]
        return value

    def measurement_jacobian(
        self, x: np.ndarray, road_points: np.ndarray | None = None
    ) -> np.ndarray:
        """dh/dx at ``x[..., n_states]`` (paper eq. 14, exact), shape (..., 3, n).

        ``road_points``: at the measured sample (see :meth:`bearings`); None: straight road.
        """
        out = np.zeros(x.shape[:-1] + (3, self.n_states))
        vx, vy = x[..., VX], x[..., VY]
        speed = np.sqrt(np.maximum(vx * vx + vy * vy, _MIN_SPEED_SQ))
        out[..., 0, VX] = vx / speed
        out[..., 0, VY] = vy / speed
        out[..., 1, Y] = 1.0
        out[..., 1, BIAS] = 1.0
        if self.has_steering:
            _, du = self.bearings(x, with_jacobian=True, road_points=road_points)
            out[..., 2, :3] = self.output_gain @ du
            if self.preferred_offset:
                out[..., 2, PREFERRED_OFFSET] = -out[..., 2, Y]
            if self.n_memory:
                out[..., 2, -1] = 1.0
            if self.coloured_error:
                out[..., 2, self.coloured_error_index] = 1.0
        return out

    # --------------------------------------------------------------- memory
    def memory_offset_sensitivity(self) -> np.ndarray:
        """d m / d p (n_memory,) of :meth:`steady_memory` on a straight road at y - p = 0: how
        the constant-past memory moves with the driver's preferred offset p::

            d u / d p = (1 / near, 1 / far, 0),   d m_i / d p = sum_{lags of m_i} beta_j . du/dp

        (zeros without the preferred offset). The filters carry the memory's covariance
        with p through it at reset and at a memory restart."""
        if not (self.preferred_offset and self.n_memory):
            return np.zeros(self.n_memory)
        beta_lagged = self.bearing_gain - self.feedback[:, None] * self.output_gain
        du_dp = np.array([1.0 / self.near_distance, 1.0 / self.far_distance, 0.0])
        return np.cumsum(beta_lagged @ du_dp)

    def steady_memory(
        self, steering: np.ndarray, x: np.ndarray, road_points: np.ndarray | None = None
    ) -> np.ndarray:
        """Memory states of a constant past: delta(k-j) = ``steering``, u(k-j) = u(x), j >= 1.

        Unrolling g_i gives ``m_i = sum_{j=n-i+1}^{n} (a_j delta + beta_j . u)``.
        Each hypothesis passes its *own* state ``x`` (its own y), so the
        memory never encodes which lane is true (docs/design.md §8.1).

        Args:
            steering: measured steering delta (rad, model units), shape (...).
            x: states whose first three entries give u, shape (..., >= 3).
            road_points: road points at x's sample (see :meth:`bearings`); None: straight.

        Returns:
            (..., n_memory) memory states.
        """
        n = self.n_memory
        if not n:
            return np.zeros(x.shape[:-1] + (0,))
        u = self.bearings(x, road_points=road_points)
        steering = np.asarray(steering, dtype=np.float64)
        # contribution of lag j = n - i + 1 for memory i: a_j delta + beta_j . u
        beta_lagged = self.bearing_gain - self.feedback[:, None] * self.output_gain
        per_lag = self.feedback * steering[..., None] + u @ beta_lagged.T
        return np.cumsum(per_lag, axis=-1)
