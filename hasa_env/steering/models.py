"""The paper's steering models: the two-point model and the generalized ARX model.

Both are linear in their parameters and ARX models (paper eq. (8)), so they
fit by least squares, score, save, and serve the estimator through
:meth:`~hasa_env.steering.base.SteeringModel.arx`. Sample alignment and sign
conventions: :mod:`hasa_env.steering.features` and docs/design.md §5.3-5.6.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from hasa_env.steering.arx import ARXForm
from hasa_env.steering.base import SteeringModel
from hasa_env.steering.design import Design, Regressor, lagged
from hasa_env.steering.equation_error import MAX_EQUATION_ERROR_ORDER

__all__ = [
    "TwoPointModel",
    "GeneralizedModel",
    "RoadBlindModel",
    "PAPER_ORDERS",
    "ROAD_BLIND_ORDER",
]

PAPER_ORDERS = {"na": 2, "nb": 4, "nc": 1, "nd": 2}
"""Orders of the paper's generalized model (eq. (10)): 2 past steering values,
phi(k..k-3), Omega(k), v_y(k..k-1)."""

ROAD_BLIND_ORDER = 2
"""Order of the road-blind baseline: the generalized model's na (2 past steering values)."""

_MAX_ORDER = 50


def _check_order(name: str, value: object, high: int = _MAX_ORDER) -> int:
    """``value`` as an order in [0, ``high``]; ValueError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not 0 <= value <= high:
        raise ValueError(f"{name} must be an integer in [0, {high}], got {value!r}")
    return int(value)


class TwoPointModel(SteeringModel):
    """Salvucci & Gray's two-point model in corrected backward-Euler form (paper eqs. (7)/(9)).

    ``delta(k) = delta(k-1) + k_n [phi(k) - phi(k-1)]
    + k_f [Omega(k) - Omega(k-1)] + k_I Ts phi(k)``

    (docs/design.md §5.3: the paper's sums without alternating signs are a
    typo). Parameters: ``near_gain`` k_n (rad/rad), ``far_gain`` k_f (rad/rad),
    ``integral_gain`` k_I (1/s). As an ARX model:
    a = (1,), b = (k_n + k_I Ts, -k_n), c = (k_f, -k_f).

    Args:
        near_gain, far_gain, integral_gain: the gains (all three or none; or
            give ``parameters``).
        **kwargs: :class:`~hasa_env.steering.base.SteeringModel` options
            (distances, dt, name, parameters, standard_errors).
    """

    model_type = "two_point"

    def __init__(
        self,
        near_gain: float | None = None,
        far_gain: float | None = None,
        integral_gain: float | None = None,
        **kwargs: Any,
    ) -> None:
        gains = (near_gain, far_gain, integral_gain)
        if any(g is not None for g in gains):
            if any(g is None for g in gains):
                raise ValueError(
                    "give all three gains near_gain, far_gain, integral_gain (or none)"
                )
            if kwargs.get("parameters") is not None:
                raise ValueError("give the gains either as keywords or as parameters, not both")
            kwargs["parameters"] = gains
        kwargs.setdefault("name", "two-point")
        super().__init__(**kwargs)

    @classmethod
    def paper(cls, dt: float = 0.01, **kwargs: Any) -> TwoPointModel:
        """The paper's fit on the illustrative driver (eq. (9)): k_n=-0.2, k_f=0.7, k_I=0.087.

        ``kwargs``: other :class:`~hasa_env.steering.base.SteeringModel` options
        (e.g. ``steering_signal``).
        """
        kwargs.setdefault("name", "two-point (paper)")
        model = cls(-0.2, 0.7, 0.087, dt=dt, **kwargs)
        model.training_curvature = 0.0  # fitted on the paper's straight track
        return model

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return ("near_gain", "far_gain", "integral_gain")

    @property
    def regressors(self) -> tuple[Regressor, ...]:
        return (
            Regressor("delta", 1),
            Regressor("phi", 0),
            Regressor("phi", 1),
            Regressor("omega", 0),
            Regressor("omega", 1),
        )

    def design(self, features: pd.DataFrame) -> Design:
        delta = features["delta"].to_numpy(dtype=np.float64)
        phi = features["phi"].to_numpy(dtype=np.float64)
        omega = features["omega"].to_numpy(dtype=np.float64)
        matrix = np.column_stack([phi - lagged(phi, 1), omega - lagged(omega, 1), self.dt * phi])
        return Design(target=delta, offset=lagged(delta, 1), matrix=matrix)

    def arx(self) -> ARXForm | None:
        if not self.is_fitted:
            return None
        k_n, k_f, k_i = self.parameter_vector.tolist()
        return ARXForm(
            a=(1.0,),
            b=(k_n + k_i * self.dt, -k_n),
            c=(k_f, -k_f),
            d=(),
            near_distance=self.near_distance,
            far_distance=self.far_distance,
            dt=self.dt,
        )


class GeneralizedModel(SteeringModel):
    """The generalized two-point model: an ARX model of any orders (paper eqs. (8)/(10)).

    ``delta(k) = sum_{i=1}^{na} a_i delta(k-i) + sum_{i=0}^{nb-1} b_i phi(k-i)
    + sum_{i=0}^{nc-1} c_i Omega(k-i) + sum_{i=0}^{nd-1} d_i v_y(k-i)``

    Parameters are named by lag: ``a1`` .. ``a{na}`` (delta(k-1) ..; the
    paper's "a_0" is our ``a1``), ``b0`` .. (phi(k) ..), ``c0`` .., ``d0`` ..
    (v_y(k) ..). Default orders are the paper's (na=2, nb=4, nc=1, nd=2).

    Args:
        na, nb, nc, nd: the orders (0 .. 50 each).
        equation_error_order: lags p of the equation error's autoregression the fit
            estimates (0 .. 10; 0: white, as the paper's; docs/design.md §8.32): the estimator
            then compares the steering whitened by it
            (:mod:`hasa_env.steering.equation_error`).
        **kwargs: :class:`~hasa_env.steering.base.SteeringModel` options.
    """

    model_type = "generalized"

    def __init__(
        self,
        na: int = PAPER_ORDERS["na"],
        nb: int = PAPER_ORDERS["nb"],
        nc: int = PAPER_ORDERS["nc"],
        nd: int = PAPER_ORDERS["nd"],
        equation_error_order: int = 0,
        **kwargs: Any,
    ) -> None:
        orders = {"na": na, "nb": nb, "nc": nc, "nd": nd}
        self.orders: dict[str, int] = {k: _check_order(f"order {k}", v) for k, v in orders.items()}
        self._equation_error_order = _check_order(
            "equation_error_order", equation_error_order, MAX_EQUATION_ERROR_ORDER
        )
        kwargs.setdefault("name", "generalized")
        super().__init__(**kwargs)

    @classmethod
    def from_arx(cls, arx: ARXForm, **kwargs: Any) -> GeneralizedModel:
        """The generalized model with an ARX form's coefficients, orders, distances and Ts."""
        params = [*arx.a, *arx.b, *arx.c, *arx.d]
        kwargs.setdefault("near_distance", arx.near_distance)
        kwargs.setdefault("far_distance", arx.far_distance)
        kwargs.setdefault("dt", arx.dt)
        return cls(len(arx.a), len(arx.b), len(arx.c), len(arx.d), parameters=params, **kwargs)

    @classmethod
    def from_coefficients(
        cls,
        a: Sequence[float],
        b: Sequence[float],
        c: Sequence[float] = (),
        d: Sequence[float] = (),
        **kwargs: Any,
    ) -> GeneralizedModel:
        """The generalized model with the given coefficient tuples (see :class:`ARXForm`)."""
        return cls(len(a), len(b), len(c), len(d), parameters=[*a, *b, *c, *d], **kwargs)

    @classmethod
    def paper(cls, **kwargs: Any) -> GeneralizedModel:
        """The paper's fit on the illustrative driver (eq. (10)) in OUR convention (docs/design.md §5.4).

        a = (1.47, -0.51), b = (-5.73, 17.32, -17.65, 6.12), c0 = 0.11,
        d = (-0.02, 0.02), Ts = 0.01 s: the paper prints "a_1 = 0.51" (unstable;
        -0.51 is meant) and its d has the opposite sign (its delta and
        bearings are not ISO 8855). ``kwargs``: other
        :class:`~hasa_env.steering.base.SteeringModel` options (e.g. ``steering_signal``).
        """
        kwargs.setdefault("name", "generalized (paper)")
        model = cls.from_coefficients(
            (1.47, -0.51),
            (-5.73, 17.32, -17.65, 6.12),
            (0.11,),
            (-0.02, 0.02),
            dt=0.01,
            **kwargs,
        )
        model.training_curvature = 0.0  # fitted on the paper's straight track
        return model

    def structure(self) -> dict[str, Any]:
        out: dict[str, Any] = dict(self.orders)
        if self._equation_error_order:  # left out when white: the paper's model as before
            out["equation_error_order"] = self._equation_error_order
        return out

    @property
    def equation_error_order(self) -> int:
        return self._equation_error_order

    @property
    def parameter_names(self) -> tuple[str, ...]:
        o = self.orders
        return (
            *(f"a{i}" for i in range(1, o["na"] + 1)),
            *(f"b{i}" for i in range(o["nb"])),
            *(f"c{i}" for i in range(o["nc"])),
            *(f"d{i}" for i in range(o["nd"])),
        )

    @property
    def regressors(self) -> tuple[Regressor, ...]:
        o = self.orders
        return (
            *(Regressor("delta", i) for i in range(1, o["na"] + 1)),
            *(Regressor("phi", i) for i in range(o["nb"])),
            *(Regressor("omega", i) for i in range(o["nc"])),
            *(Regressor("lateral_velocity", i) for i in range(o["nd"])),
        )

    def design(self, features: pd.DataFrame) -> Design:
        columns = [
            lagged(features[r.feature].to_numpy(dtype=np.float64), r.lag) for r in self.regressors
        ]
        delta = features["delta"].to_numpy(dtype=np.float64)
        matrix = np.column_stack(columns) if columns else np.zeros((delta.size, 0))
        return Design(target=delta, offset=np.zeros_like(delta), matrix=matrix)

    def coefficients(self) -> Mapping[str, tuple[float, ...]]:
        """The coefficient tuples ``{"a": ..., "b": ..., "c": ..., "d": ...}``."""
        theta = self.parameter_vector.tolist()
        out: dict[str, tuple[float, ...]] = {}
        pos = 0
        for key in ("a", "b", "c", "d"):
            n = self.orders["n" + key]
            out[key] = tuple(theta[pos : pos + n])
            pos += n
        return out

    def arx(self) -> ARXForm | None:
        if not self.is_fitted:
            return None
        coef = self.coefficients()
        return ARXForm(
            a=coef["a"],
            b=coef["b"],
            c=coef["c"],
            d=coef["d"],
            near_distance=self.near_distance,
            far_distance=self.far_distance,
            dt=self.dt,
        )


class RoadBlindModel(SteeringModel):
    """The road-blind baseline: an AR model of the steering's own past, blind to the road.

    ``delta(k) = sum_{i=1}^{na} a_i delta(k-i)`` (rad): no bearing, no lateral velocity.
    It is fitted like every other model (ridge regression, the penalty by blocked
    cross-validation on the training runs) and with the generalized model's autoregressive
    order (``na`` = :data:`ROAD_BLIND_ORDER` = 2, the paper's), so what a model predicts
    beyond it is what the road told it: the benchmark's road information
    ``1 - SSE_model / SSE_road_blind`` (docs/design.md §6.3). Its ARX form has no lane
    terms (``static_lane_gain`` 0): it cannot tell lanes apart, so it is a steering
    reference, not an advisor for the estimator (its fit says so with an
    :class:`~hasa_env.steering.identifiability.IdentifiabilityWarning`, by design).

    Args:
        na: the order (0 .. 50); parameters ``a1`` .. ``a{na}`` (delta(k-1) ..).
        **kwargs: :class:`~hasa_env.steering.base.SteeringModel` options.
    """

    model_type = "road_blind"

    def __init__(self, na: int = ROAD_BLIND_ORDER, **kwargs: Any) -> None:
        self.na = _check_order("order na", na)
        kwargs.setdefault("name", "road-blind")
        super().__init__(**kwargs)

    def structure(self) -> dict[str, Any]:
        return {"na": self.na}

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f"a{i}" for i in range(1, self.na + 1))

    @property
    def regressors(self) -> tuple[Regressor, ...]:
        return tuple(Regressor("delta", i) for i in range(1, self.na + 1))

    def design(self, features: pd.DataFrame) -> Design:
        delta = features["delta"].to_numpy(dtype=np.float64)
        columns = [lagged(delta, i) for i in range(1, self.na + 1)]
        matrix = np.column_stack(columns) if columns else np.zeros((delta.size, 0))
        return Design(target=delta, offset=np.zeros_like(delta), matrix=matrix)

    def arx(self) -> ARXForm | None:
        if not self.is_fitted:
            return None
        return ARXForm(
            a=tuple(self.parameter_vector.tolist()),
            b=(),
            near_distance=self.near_distance,
            far_distance=self.far_distance,
            dt=self.dt,
        )
