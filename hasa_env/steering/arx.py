"""The ARX description of a steering model: what the estimator builds on.

A steering model that is linear in its regressors is an ARX model (paper
eq. (8), fitted form eq. (10); docs/design.md §5.4-5.6)::

    delta(k) = sum_{i=1}^{na} a_i delta(k-i)
             + sum_{i=0}^{nb-1} b_i phi(k-i)
             + sum_{i=0}^{nc-1} c_i Omega(k-i)
             + sum_{i=0}^{nd-1} d_i v_y(k-i)

with phi, Omega the near/far-point bearings (rad, positive: lane centre to
the left) at ``near_distance`` / ``far_distance`` m and v_y the lateral
velocity (m/s). Note the index convention: ``a[0]`` multiplies delta(k-1)
(the paper's "a_0 = 1.47"), ``b[0]`` multiplies phi(k).

Sample alignment (see :mod:`hasa_env.steering.features`): delta(k) is the
steering *decided* at sample k, which a recording holds in row k+1 (the
action applied over the step ending there) and the env's steering sensor
reports one step later; phi(k), Omega(k), v_y(k) are what the driver saw at
sample k. :func:`hasa_env.steering.features.steering_features` pairs them so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ARXForm", "NEAR_POINT_DISTANCE", "FAR_POINT_DISTANCE", "autoregression_roots"]

NEAR_POINT_DISTANCE = 6.2
"""Default near-point look-ahead (m), Salvucci & Gray (docs/design.md §5.1)."""
FAR_POINT_DISTANCE = 20.0
"""Default far-point look-ahead (m) (docs/design.md §5.1)."""


def autoregression_roots(coefficients: tuple[float, ...] | np.ndarray) -> np.ndarray:
    """Roots of ``z^n - c_1 z^(n-1) - ... - c_n`` for an autoregression ``x(k) = sum_i c_i
    x(k-i) + ...`` (complex, shape (n,); empty without coefficients): stable (stationary)
    when every modulus is below 1."""
    if not len(coefficients):
        return np.zeros(0, dtype=complex)
    return np.roots(np.concatenate([[1.0], -np.asarray(coefficients, dtype=np.float64)])).astype(
        complex
    )


@dataclass(frozen=True)
class ARXForm:
    """Coefficients of an ARX steering model (see module docstring).

    Attributes:
        a: coefficients of delta(k-1), ..., delta(k-na).
        b: coefficients of phi(k), ..., phi(k-nb+1).
        c: coefficients of Omega(k), ..., Omega(k-nc+1).
        d: coefficients of v_y(k), ..., v_y(k-nd+1).
        near_distance: near-point look-ahead (m), default 6.2.
        far_distance: far-point look-ahead (m), default 20.
        dt: sample time Ts (s) the coefficients belong to.
    """

    a: tuple[float, ...]
    b: tuple[float, ...]
    c: tuple[float, ...] = ()
    d: tuple[float, ...] = ()
    near_distance: float = NEAR_POINT_DISTANCE
    far_distance: float = FAR_POINT_DISTANCE
    dt: float = 0.01

    def __post_init__(self) -> None:
        for name in ("a", "b", "c", "d"):
            values = tuple(float(v) for v in getattr(self, name))
            if not all(np.isfinite(values)):
                raise ValueError(f"ARXForm.{name} must be finite, got {values}")
            object.__setattr__(self, name, values)
        if self.near_distance <= 0 or self.far_distance <= 0 or self.dt <= 0:
            raise ValueError("ARXForm distances and dt must be positive")

    @property
    def memory_order(self) -> int:
        """Number of memory states of the observer canonical form: max(na, nb-1, nc-1, nd-1)."""
        return max(len(self.a), len(self.b) - 1, len(self.c) - 1, len(self.d) - 1, 0)

    @property
    def static_lane_gain(self) -> float:
        """sum(b)/near + sum(c)/far: steady-state steering per metre of offset, times (1 - sum(a)).

        With phi ~ -y/near and Omega ~ -y/far at small angles, a steady offset y
        gives (1 - sum a) delta = -(sum(b)/near + sum(c)/far) y. The estimator can
        tell lanes apart only if this is clearly non-zero (docs/design.md §5.7).
        """
        return sum(self.b) / self.near_distance + sum(self.c) / self.far_distance

    def predict(
        self,
        delta_past: np.ndarray,
        phi: np.ndarray,
        omega: np.ndarray,
        lateral_velocity: np.ndarray,
    ) -> np.ndarray:
        """One-step-ahead predictions delta_hat(k) for every k with a full history.

        All arguments are 1-D arrays over the same samples k = 0..n-1 (delta_past
        is the measured steering). Returns an array of length n whose first
        ``max lag`` entries are NaN (not enough history).
        """
        delta = np.asarray(delta_past, dtype=np.float64)
        series = {
            "b": np.asarray(phi, dtype=np.float64),
            "c": np.asarray(omega, dtype=np.float64),
            "d": np.asarray(lateral_velocity, dtype=np.float64),
        }
        n = delta.size
        start = max(len(self.a), len(self.b) - 1, len(self.c) - 1, len(self.d) - 1, 0)
        out = np.full(n, np.nan)
        if n <= start:
            return out
        k = np.arange(start, n)
        pred = np.zeros(k.size)
        for i, coef in enumerate(self.a, start=1):
            pred += coef * delta[k - i]
        for name, x in series.items():
            for i, coef in enumerate(getattr(self, name)):
                pred += coef * x[k - i]
        out[start:] = pred
        return out
