"""The preview LQR design shared by the preview and the intermittent drivers.

After Sharp, Casanova & Symonds (2000), "A mathematical model for driver
steering control, with design, tuning and performance results" (Vehicle
System Dynamics 33): a linear-quadratic regulator on the car's lateral
kinematics whose state is augmented with a shift register of the road
curvature previewed ahead, so the feed-forward gains on the previewed
curvatures come out of the same Riccati equation as the feedback gains.

Plant (Frenet coordinates, small angles): y' = v theta,
theta' = v delta / L - v kappa; the steering delta is a state and its rate
the input. In the speed-normalised coordinates

    lateral velocity  y_v = v theta,   lateral acceleration  a = v^2 delta / L,
    road's demand     w_j = v^2 kappa_j,   lateral jerk  j = v^2 delta' / L,

the plant is a triple integrator y'' = a - w_0, a' = j that is the same at
every speed, and so is the cost (:class:`PreviewCost`: lateral error,
heading as lateral velocity, steering rate as lateral jerk)::

    J = sum_k T [q_y y(k)^2 + q_h y_v(k)^2 + r j(k)^2]

Design (:func:`preview_gains`, once per cost, cached): discretise the
triple integrator exactly (zero-order hold, sample time T =
``preview_step``), augment it with the shift register z = (w_0, ..., w_P)
of the road's demand at the preview times t_j = j T (z(k+1) = (w_1, ...,
w_P, rho w_P), rho = exp(-T / tau_P): beyond the horizon the driver expects
the curvature it sees last to fade with the time constant ``persistence``;
rho = 0 is the plain shift register of Sharp et al.), and solve the discrete
algebraic Riccati equation (:func:`scipy.linalg.solve_discrete_are`)::

    X = [y, y_v, a, w_0 ... w_P],   X(k+1) = A X(k) + B j(k)
    S = A' S A - A' S B (R + B' S B)^-1 B' S A + Q
    K = (R + B' S B)^-1 B' S A = [k_y, k_v, k_a, k_0 ... k_P]

so that j = -(f + k_a a) with the feedback-plus-preview term
(:class:`PreviewFeedback`)::

    f = k_y y + k_v v theta + sum_j k_j v^2 kappa(s + v t_j)

In steering units the gains depend on speed exactly as L k_y / v^2 (on y),
L k_v / v (on theta), k_a (on delta) and L k_j (on the previewed
curvatures): the closed loop has the same time response at every speed, so
a delay and a lag that it tolerates at 15 m/s it tolerates at 45 m/s too.
:meth:`PreviewCost.from_bandwidth` sets the weights from a loop bandwidth.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from scipy.linalg import solve_discrete_are

from hasa_env.drivers.human import check_range, sum_from
from hasa_env.sim.road import Road

__all__ = ["PreviewCost", "PreviewFeedback", "preview_gains"]


@dataclass(frozen=True)
class PreviewCost:
    """Cost weights and preview of the LQR design (see the module docstring).

    Attributes:
        lateral_weight: q_y (1/m^2) on the lateral offset, in [1e-6, 1e6].
        heading_weight: q_h (s^2/m^2) on the lateral velocity v theta, in [0, 1e6].
        steering_rate_weight: r (s^6/m^2) on the lateral jerk v^2 delta' / L, in [1e-9, 1e9].
        preview_time: horizon (s) of the previewed curvature, in [0, 5].
        preview_step: T (s), spacing of the preview points and sample time of the
            design, in [0.02, 0.5].
        persistence: tau_P (s), in [0, 60]: the driver expects the curvature at the
            horizon to fade beyond it as exp(-t / tau_P) (0: to vanish at once).
    """

    lateral_weight: float = 1.0
    heading_weight: float = 0.7
    steering_rate_weight: float = 0.35
    preview_time: float = 1.2
    preview_step: float = 0.1
    persistence: float = 3.0

    def __post_init__(self) -> None:
        owner = "PreviewCost"
        check_range(owner, "lateral_weight", self.lateral_weight, 1e-6, 1e6)
        check_range(owner, "heading_weight", self.heading_weight, 0.0, 1e6)
        check_range(owner, "steering_rate_weight", self.steering_rate_weight, 1e-9, 1e9)
        check_range(owner, "preview_time", self.preview_time, 0.0, 5.0)
        check_range(owner, "preview_step", self.preview_step, 0.02, 0.5)
        check_range(owner, "persistence", self.persistence, 0.0, 60.0)

    @property
    def preview_points(self) -> int:
        """P: the preview register holds the road's demand at t_j = j T, j = 0..P."""
        return round(self.preview_time / self.preview_step)

    @classmethod
    def from_bandwidth(
        cls, bandwidth: float, velocity_weight: float = 1.0, **kwargs: Any
    ) -> PreviewCost:
        """Weights for a lateral loop of natural frequency ``bandwidth`` (rad/s).

        With q_y = 1, r = bandwidth^-6 and q_h = velocity_weight / bandwidth^2 the
        optimal closed loop of the triple integrator (without delay, lag or
        preview) has its poles at ``bandwidth`` times the left-half-plane roots
        of ``p^6 + velocity_weight p^2 - 1 = 0`` (velocity_weight 0: the
        third-order Butterworth pattern, damping 0.5; larger: better damped).
        """
        check_range("PreviewCost.from_bandwidth", "bandwidth", bandwidth, 0.05, 20.0)
        check_range("PreviewCost.from_bandwidth", "velocity_weight", velocity_weight, 0.0, 100.0)
        return cls(
            lateral_weight=1.0,
            heading_weight=velocity_weight / bandwidth**2,
            steering_rate_weight=bandwidth**-6,
            **kwargs,
        )

    def to_dict(self) -> dict[str, float]:
        """A JSON-able dict of the parameters."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PreviewCost:
        """Inverse of :meth:`to_dict`."""
        return cls(**data)


@lru_cache(maxsize=256)
def preview_gains(cost: PreviewCost) -> np.ndarray:
    """K = [k_y, k_v, k_a, k_0 ... k_P] of the speed-normalised design (module docstring).

    Read-only array of 3 + P + 1 gains; raises ValueError if the design does
    not stabilise the sampled plant.
    """
    t = cost.preview_step
    p = cost.preview_points
    n = 3 + p + 1
    a = np.zeros((n, n))
    a[:3, :3] = [[1.0, t, t * t / 2.0], [0.0, 1.0, t], [0.0, 0.0, 1.0]]
    a[:3, 3] = [-t * t / 2.0, -t, 0.0]  # the road's demand w_0, held over the sample
    for j in range(p):
        a[3 + j, 4 + j] = 1.0  # shift register: w_j(k+1) = w_{j+1}(k)
    if cost.persistence > 0:  # w_P(k+1) = rho w_P(k): the curvature beyond the horizon fades
        a[3 + p, 3 + p] = math.exp(-t / cost.persistence)
    b = np.zeros((n, 1))
    b[:3, 0] = [t**3 / 6.0, t * t / 2.0, t]
    q = np.zeros((n, n))
    q[0, 0] = t * cost.lateral_weight
    q[1, 1] = t * cost.heading_weight
    r = np.array([[t * cost.steering_rate_weight]])
    s = solve_discrete_are(a, b, q, r)
    gain = np.linalg.solve(r + b.T @ s @ b, b.T @ s @ a)[0]
    radius = np.abs(np.linalg.eigvals(a - b @ gain[None, :])).max()
    if not radius < 1.0:
        raise ValueError(f"preview design {cost} does not stabilise the plant (|z| = {radius})")
    gain.setflags(write=False)
    return gain


class PreviewFeedback:
    """The feedback-plus-preview term f and the gain k_a of N drivers' designs.

    Gains are zero-padded to the longest preview in the batch (extra points
    weigh nothing), and the sum over the preview runs in a fixed order, so a
    driver gets the same bits alone or in any batch.
    """

    def __init__(self, costs: Sequence[PreviewCost]) -> None:
        gains = [preview_gains(c) for c in costs]
        width = max(g.size for g in gains)
        self.gains = np.zeros((len(gains), width))
        for i, g in enumerate(gains):
            self.gains[i, : g.size] = g
        steps = np.array([c.preview_step for c in costs])
        self.preview_times = steps[:, None] * np.arange(width - 3)[None, :]
        self.acceleration_gain = self.gains[:, 2]

    def __call__(
        self,
        y: np.ndarray,
        theta: np.ndarray,
        station: np.ndarray,
        v: np.ndarray,
        road: Road,
        bias: np.ndarray | None = None,
    ) -> np.ndarray:
        """f = k_y y + k_v v theta + sum_j k_j v^2 kappa(s + v t_j) (m/s^3), arrays of N cars.

        kappa is the driven lane's curvature: the road's plus that of its lane shifts
        (:meth:`~hasa_env.sim.road.Road.driven_curvature`; y and theta are then relative
        to the driven lane, :meth:`~hasa_env.drivers.human.HumanBatch.perceived`); ``bias``
        is each car's episode bias (m), needed by a shift toward the other hypothesis.
        """
        k = self.gains
        out = k[:, 0] * y + k[:, 1] * (v * theta)
        if not road.is_straight or road.lane_shifts:
            v2 = v * v
            stations = station[:, None] + v[:, None] * self.preview_times
            kappa = road.curvature_lookup(stations)
            if road.lane_shifts:
                kappa = kappa + road.driven_curvature(stations, bias)
            # out + term_0 + term_1 + ..., left to right: the same bits alone or in a batch
            out = sum_from(out, k[:, 3 : 3 + kappa.shape[1]] * (v2[:, None] * kappa))
        return out
