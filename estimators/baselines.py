"""Baselines of the human-as-advisor estimator (docs/design.md §8.10).

- :class:`NoSteeringEKF`: the mixture filter without the human's steering
  (speed and camera only). The camera measures y + b, so the lanes cannot be
  told apart: with two hypotheses 1.8 m apart the weights stay at the prior
  and the lateral RMSE of the mixture estimate is about 0.9 m.
- :class:`SingleHypothesisEKF`: one EKF that trusts one lane hypothesis (the
  nominal markings, index 0 by default): exact when that lane is true, off
  by the hypotheses' spacing otherwise.
- :class:`OracleEKF`: one EKF told the true bias: the best any of them can do.
- The filterpy reference implementation is
  :class:`estimators.filterpy_ekf.FilterpyGMEKF`.

All three are :class:`~estimators.gm_ekf.GaussianMixtureEKF` (same
equations, settings and interface), so they run batched over many runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from estimators.base import Estimate
from estimators.gm_ekf import GaussianMixtureEKF
from estimators.settings import FilterSettings
from hasa_env.steering.arx import ARXForm

__all__ = ["NoSteeringEKF", "SingleHypothesisEKF", "OracleEKF"]


class NoSteeringEKF(GaussianMixtureEKF):
    """Gaussian mixture over the lane hypotheses without the steering channel.

    State [v_x, y, v_y, b] (paper eq. 4), measurements speed and camera
    (paper's z_1, z_2). See :class:`GaussianMixtureEKF` for the equations.

    Args:
        settings: :class:`FilterSettings` (the steering fields are unused).
        dt: sample time (s), default 0.01.
        **overrides: fields of the settings to replace.
    """

    def __init__(
        self, settings: FilterSettings | None = None, *, dt: float = 0.01, **overrides: Any
    ) -> None:
        super().__init__(None, settings, dt=dt, decision_lag=0, **overrides)


class SingleHypothesisEKF(GaussianMixtureEKF):
    """One EKF that assumes lane hypothesis ``hypothesis_index`` is the true one.

    Args:
        steering_model: optional ARX steering model (default None: a plain
            speed + camera + IMU filter).
        settings: :class:`FilterSettings`.
        hypothesis_index: which of the hypotheses passed to :meth:`reset` it
            trusts (default 0, the nominal markings).
        dt, decision_lag, **overrides: as in :class:`GaussianMixtureEKF`.
    """

    def __init__(
        self,
        steering_model: ARXForm | None = None,
        settings: FilterSettings | None = None,
        *,
        hypothesis_index: int = 0,
        dt: float | None = None,
        decision_lag: int = 1,
        **overrides: Any,
    ) -> None:
        super().__init__(steering_model, settings, dt=dt, decision_lag=decision_lag, **overrides)
        self.hypothesis_index = int(hypothesis_index)

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
        """Reset with only hypothesis ``hypothesis_index`` of ``hypotheses`` (weight 1)."""
        hyp = np.asarray(hypotheses, dtype=np.float64)
        count = hyp.shape[-1]
        if not -count <= self.hypothesis_index < count:
            raise IndexError(
                f"hypothesis_index {self.hypothesis_index} is out of range for {count} hypotheses"
            )
        i = self.hypothesis_index % count
        return super().reset(measurement, hyp[..., i : i + 1], runs=runs, road_points=road_points)


class OracleEKF(GaussianMixtureEKF):
    """One EKF that is told the true camera bias (``reset(..., true_bias=b)``).

    Args:
        steering_model: optional ARX steering model (default None).
        settings, dt, decision_lag, **overrides: as in :class:`GaussianMixtureEKF`.
    """

    uses_true_bias = True

    def __init__(
        self,
        steering_model: ARXForm | None = None,
        settings: FilterSettings | None = None,
        *,
        dt: float | None = None,
        decision_lag: int = 1,
        **overrides: Any,
    ) -> None:
        super().__init__(steering_model, settings, dt=dt, decision_lag=decision_lag, **overrides)

    def reset(
        self,
        measurement: np.ndarray,
        hypotheses: Sequence[float] | np.ndarray | None = None,
        *,
        prior: np.ndarray | None = None,
        true_bias: np.ndarray | float | None = None,
        runs: np.ndarray | None = None,
        road_points: np.ndarray | None = None,
    ) -> Estimate:
        """Reset with the single hypothesis ``true_bias`` (scalar, or one per run); required."""
        if true_bias is None:
            raise ValueError("OracleEKF.reset needs true_bias (the camera bias b of each run, m)")
        measurement = np.asarray(measurement, dtype=np.float64)
        bias = np.asarray(true_bias, dtype=np.float64)
        if measurement.ndim == 1:
            hyp = bias.reshape(1)
        else:
            hyp = np.broadcast_to(bias.reshape(-1, 1), (measurement.shape[0], 1))
        return super().reset(measurement, hyp, runs=runs, road_points=road_points)
