"""The pieces a steering model's equation is written in: regressors and the design.

:class:`Regressor` names a feature at a lag (``phi(k-1)``); :class:`Design`
is a model's equation over one run, linear in its parameters, as the fitting
code (:mod:`hasa_env.steering.fitting`) consumes it; :func:`lagged` shifts a
series. They sit below the model classes so that fitting and models never
import each other.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import pandas as pd

from hasa_env.sim.road import Road
from hasa_env.steering.arx import ARXForm

__all__ = [
    "FEATURE_NAMES",
    "Design",
    "Regressor",
    "SteeringModelLike",
    "as_runs",
    "lagged",
    "r_squared",
]

FEATURE_NAMES = ("delta", "phi", "omega", "lateral_velocity", "speed")
"""Features a regressor may refer to (the columns of
:func:`~hasa_env.steering.features.steering_features`)."""


@dataclass(frozen=True)
class Regressor:
    """A feature at a lag: ``Regressor("phi", 1)`` is phi(k-1).

    Attributes:
        feature: one of :data:`FEATURE_NAMES` (or a column a custom model adds).
        lag: samples back (0 = the current sample k).
    """

    feature: str
    lag: int

    def __post_init__(self) -> None:
        if not isinstance(self.feature, str) or not self.feature:
            raise ValueError(f"Regressor.feature must be a non-empty string, got {self.feature!r}")
        if isinstance(self.lag, bool) or not isinstance(self.lag, int | np.integer) or self.lag < 0:
            raise ValueError(f"Regressor.lag must be a non-negative integer, got {self.lag!r}")

    def __str__(self) -> str:
        return f"{self.feature}(k)" if self.lag == 0 else f"{self.feature}(k-{self.lag})"


@dataclass(frozen=True)
class Design:
    """A model's equation over one run, linear in its parameters.

    ``target(k) = offset(k) + matrix(k, :) @ parameters + error(k)`` for every
    sample k where all entries are finite (rows with NaN are left out).

    Attributes:
        target: delta(k), the recorded steering (rad), shape (n,).
        offset: the part of delta(k) that is not fitted (e.g. delta(k-1) of the
            two-point model; zeros for a plain ARX model), shape (n,).
        matrix: one column per parameter, in ``parameter_names`` order, shape (n, p).
    """

    target: np.ndarray
    offset: np.ndarray
    matrix: np.ndarray

    def __post_init__(self) -> None:
        target = np.asarray(self.target, dtype=np.float64)
        offset = np.asarray(self.offset, dtype=np.float64)
        matrix = np.asarray(self.matrix, dtype=np.float64)
        if matrix.ndim == 1:
            matrix = matrix[:, None]
        if target.ndim != 1 or offset.shape != target.shape or matrix.ndim != 2:
            raise ValueError(
                "Design needs target (n,), offset (n,) and matrix (n, p); got shapes "
                f"{target.shape}, {offset.shape}, {matrix.shape}"
            )
        if matrix.shape[0] != target.size:
            raise ValueError(f"Design.matrix has {matrix.shape[0]} rows, target has {target.size}")
        object.__setattr__(self, "target", target)
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "matrix", matrix)

    @property
    def valid(self) -> np.ndarray:
        """Rows where target, offset and every column are finite."""
        return (
            np.isfinite(self.target)
            & np.isfinite(self.offset)
            & np.all(np.isfinite(self.matrix), axis=1)
        )


def lagged(values: np.ndarray, lag: int) -> np.ndarray:
    """``values(k - lag)`` aligned with ``values`` (NaN for k < lag)."""
    values = np.asarray(values, dtype=np.float64)
    if lag == 0:
        return values.copy()
    out = np.full(values.shape, np.nan)
    if lag < values.shape[0]:
        out[lag:] = values[:-lag]
    return out


def as_runs(runs: pd.DataFrame | Sequence[pd.DataFrame]) -> list[pd.DataFrame]:
    """One run or a sequence of runs as a non-empty list of DataFrames (clear errors otherwise)."""
    if isinstance(runs, pd.DataFrame):
        return [runs]
    out = list(runs)
    if not out:
        raise ValueError("no runs given")
    for i, run in enumerate(out):
        if not isinstance(run, pd.DataFrame):
            raise TypeError(f"run {i} is a {type(run).__name__}, expected a pandas DataFrame")
    return out


def r_squared(residual_ss: float, values: np.ndarray) -> float:
    """``1 - residual_ss / sum((values - mean)^2)`` (NaN when the values do not vary)."""
    total = float(np.sum((values - values.mean()) ** 2)) if values.size else 0.0
    return 1.0 - residual_ss / total if total > 0 else float("nan")


class SteeringModelLike(Protocol):
    """What the fitting and scoring code needs of a model
    (:class:`hasa_env.steering.base.SteeringModel` has it all)."""

    name: str
    fit_result: Any

    @property
    def parameter_names(self) -> tuple[str, ...]: ...

    @property
    def parameter_vector(self) -> np.ndarray: ...

    def features(self, data: pd.DataFrame, road: Road | None = None) -> pd.DataFrame: ...

    def design(self, features: pd.DataFrame) -> Design: ...

    def predict_features(self, features: pd.DataFrame) -> np.ndarray: ...

    def simulate(self, data: pd.DataFrame, road: Road | None = None) -> np.ndarray: ...

    def arx(self) -> ARXForm | None: ...

    def with_parameters(
        self,
        parameters: Mapping[str, float] | Sequence[float] | np.ndarray,
        standard_errors: Mapping[str, float] | Sequence[float] | np.ndarray | None = None,
        fit_result: Any = None,
    ) -> Any: ...
