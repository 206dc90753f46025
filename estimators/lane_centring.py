"""A steering-free baseline: the lane-centring prior (docs/design.md §8.12).

The camera sees y + b with b unknown among the lane hypotheses, so without the
human's steering the lanes cannot be told apart (:class:`NoSteeringEKF`). But a
driver keeps the car near the centre of the lane they are in: under the true
hypothesis the car's offset from the lane centre stays small, under a wrong one it
is off by the hypotheses' spacing. :class:`LaneCentringEKF` weighs the hypotheses
by that prior alone, inside the same mixture filter; a steering model's value is
its gain over this baseline, not over the one that cannot tell the lanes apart.

Model (fitted on a training run by :func:`fit_lane_centring`): the true lateral
offset y, sampled every D = round(T_d / Ts) samples (``decimation_time`` T_d), is a
zero-mean stationary AR(1) process::

    y(k + D) = phi y(k) + e(k),   e(k) ~ N(0, q),   sigma^2 = q / (1 - phi^2)

Likelihood of hypothesis i, on its own filtered offset ``y_i(k) = x_i(k|k)[1]`` (the
camera minus b_i): at the first step its level, then every D samples (k = 1 + D, 1 + 2D,
...) its AR(1) transition::

    k = 1:     u_i = y_i(1) / s                            s^2: the training run's mean y^2
    later:     u_i = (y_i(k) - phi y_i(k - D)) / sqrt(q)
    l_i = -1/2 (u_i^2 + log(2 pi v))                       v = s^2, then q

The first term carries most of the evidence: the car starts near its lane's centre (within
the training run's spread s), off by the hypotheses' spacing under a wrong one. Measured on
the benchmark (seed 50, 5 drivers x 3 runs): lateral RMSE 0.417 m with the AR terms alone at
T_d = 0.1 s, 0.069 m with the first term, 0.021 m with the first term and T_d = 0.5 s (the
same at 1 s; the generalized steering model: 0.037 m).

Under the true hypothesis u_i is the driver's own sway; under one off by d = b_true - b_i
it carries ``d / s`` (first term), then ``(1 - phi) d / sqrt(q)`` more,
``(1 - phi)^2 d^2 / (2 q)`` nats per term on average; the terms' remaining autocorrelation
is what the evidence rule's rho corrects for.

added to the filter's own log-likelihood (speed and camera, which do not tell the
lanes apart). The fitted q is inflated by its estimation uncertainty (q is a mean of
n roughly independent squared residuals, n the training run's decimated samples: the
upper 97.5 % bound ``q n / chi2_0.025(n)``, Wilson-Hilferty).

Tempering: the centring evidence goes through the mixture filter's evidence rule
(:mod:`estimators.evidence`) with ``u_i`` in the place of the normalized steering
innovation, at the decimated rate: a driver who sways more than the training driver
(lambda > 1), or whose offset stays correlated (rho > 0), gets his evidence divided by
tau; one the model fits under no hypothesis (a driver who keeps a large offset) is a
``model_mismatch`` and the weights stay at their last verified values.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from estimators.evidence import EvidenceRule
from estimators.gm_ekf import GaussianMixtureEKF, MixtureState
from estimators.settings import FilterSettings

__all__ = ["DEFAULT_DECIMATION_TIME", "LaneCentringEKF", "LaneCentringParams", "fit_lane_centring"]

DEFAULT_DECIMATION_TIME = 0.5
"""Seconds between the AR(1) terms of the lane-centring likelihood (T_d)."""

_UPPER_Z = 1.96
"""Standard-normal quantile of the bound on q (97.5 %)."""

_LAST_Y = "_centring_last_y"
_COUNT = "_centring_count"


@dataclass(frozen=True)
class LaneCentringParams:
    """The fitted lane-centring prior (module docstring).

    Attributes:
        decimation_time: T_d (s), the time between the likelihood's terms.
        autoregression: phi, the AR(1) coefficient at lag T_d.
        innovation_variance: q (m^2), inflated by its estimation uncertainty.
        fitted_innovation_variance: q as fitted (m^2), before the inflation.
        samples: n, the training run's decimated samples behind the fit.
        level_variance: s^2 (m^2), the training run's mean squared offset (start included),
            inflated like q: the variance of the first term.
    """

    decimation_time: float
    autoregression: float
    innovation_variance: float
    fitted_innovation_variance: float
    samples: float
    level_variance: float

    @property
    def stationary_variance(self) -> float:
        """sigma^2 = q / (1 - phi^2) (m^2)."""
        return self.innovation_variance / (1.0 - self.autoregression**2)

    def to_dict(self) -> dict[str, float]:
        """The parameters as JSON numbers (and sigma, m)."""
        return asdict(self) | {"stationary_std": math.sqrt(self.stationary_variance)}


def fit_lane_centring(
    frames: pd.DataFrame | Sequence[pd.DataFrame],
    *,
    decimation_time: float = DEFAULT_DECIMATION_TIME,
) -> LaneCentringParams:
    """Fit the lane-centring prior on training runs (columns ``time`` (s) and
    ``lateral_offset`` (m), the true offset from the lane centre), by least squares on
    every pair D samples apart (D = round(T_d / Ts), Ts the median row spacing)::

        phi = clip(sum y(k) y(k - D) / sum y(k - D)^2, 0, 0.99)
        q   = mean (y(k) - phi y(k - D))^2
        s^2 = mean y(k)^2                           (every row: the start's offset too)
        n   = sum over runs (rows - D) / D          (roughly independent pairs)
        q+  = q / (1 - h - z sqrt(h))^3,  h = 2 / (9 n),  z = 1.96   (s^2 inflated alike)

    Raises:
        ValueError: no run has more than D rows, or the offset never varies.
    """
    runs = [frames] if isinstance(frames, pd.DataFrame) else list(frames)
    if not runs:
        raise ValueError("fit_lane_centring needs at least one run")
    lagged: list[np.ndarray] = []
    current: list[np.ndarray] = []
    level: list[np.ndarray] = []
    samples = 0.0
    for frame in runs:
        time = frame["time"].to_numpy(dtype=np.float64)
        y = frame["lateral_offset"].to_numpy(dtype=np.float64)
        if len(time) < 2:
            continue
        lag = max(1, int(round(decimation_time / float(np.median(np.diff(time))))))
        if len(y) <= lag:
            continue
        before, after = y[:-lag], y[lag:]
        ok = np.isfinite(before) & np.isfinite(after)
        level.append(y[np.isfinite(y)])
        lagged.append(before[ok])
        current.append(after[ok])
        samples += float(ok.sum()) / lag
    if not lagged or samples <= 0:
        raise ValueError(f"no run is longer than the decimation time {decimation_time} s")
    before, after = np.concatenate(lagged), np.concatenate(current)
    energy = float(before @ before)
    if not energy > 0:
        raise ValueError("the lateral offset of the training run never varies")
    phi = min(max(float(before @ after) / energy, 0.0), 0.99)
    residual = after - phi * before
    q = float(residual @ residual) / len(residual)
    if not q > 0:
        raise ValueError("the lateral offset of the training run never varies")
    h = 2.0 / (9.0 * samples)
    lower = max(1.0 - h - _UPPER_Z * math.sqrt(h), 0.1) ** 3
    return LaneCentringParams(
        decimation_time=float(decimation_time),
        autoregression=phi,
        innovation_variance=q / lower,
        fitted_innovation_variance=q,
        samples=float(samples),
        level_variance=float(np.mean(np.concatenate(level) ** 2)) / lower,
    )


class LaneCentringEKF(GaussianMixtureEKF):
    """Mixture filter without the steering channel, weighing the hypotheses by the
    lane-centring prior (module docstring states the equations).

    Args:
        params: the fitted prior (:func:`fit_lane_centring`).
        settings: :class:`FilterSettings` (the steering fields are unused; the evidence
            rule's fields temper the centring evidence).
        dt: sample time (s), default 0.01.
        **overrides: fields of the settings to replace.
    """

    def __init__(
        self,
        params: LaneCentringParams,
        settings: FilterSettings | None = None,
        *,
        dt: float = 0.01,
        **overrides: Any,
    ) -> None:
        super().__init__(None, settings, dt=dt, decision_lag=0, **overrides)
        self.params = params
        self.decimation = max(1, int(round(params.decimation_time / self.dt)))
        # the rule's statistics run at the decimated rate: its window stays in seconds; its
        # first term is a level check made once, and its fitted q already carries an upper
        # bound: the tempering uses lambda itself (no evidence_confidence bound); the aim cap
        # bounds a steering model's evidence, and this filter has none
        self._rule = replace(
            EvidenceRule.from_settings(self.settings, self.dt * self.decimation),
            bound_z=0.0,
            aim_variance=0.0,
        )
        self._posterior: np.ndarray | None = None

    def _initial_state(
        self, z: np.ndarray, hyp: np.ndarray, log_w: np.ndarray, points: np.ndarray | None
    ) -> MixtureState:
        """The mixture's state at reset, with the centring likelihood's memory: each
        hypothesis' y_i(0) and the sample count 0 (the first term comes at the first step)."""
        state = super()._initial_state(z, hyp, log_w, points)
        state.evidence[_LAST_Y] = state.x[:, 1].reshape(hyp.shape).copy()
        state.evidence[_COUNT] = np.zeros(hyp.shape[0], dtype=np.int64)
        return state

    def _update(
        self,
        x_pred: np.ndarray,
        cov_pred: np.ndarray,
        z: np.ndarray,
        all_observed: bool,
        log_w: np.ndarray,
        points: np.ndarray | None,
        drop_steering: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The mixture's update; keeps x(k|k) for :meth:`_weigh`."""
        out = super()._update(x_pred, cov_pred, z, all_observed, log_w, points, drop_steering)
        self._posterior = out[0]
        return out

    def _weigh(
        self,
        state: MixtureState,
        all_active: bool,
        log_lik: np.ndarray,
        normalized: np.ndarray,
        evidence: dict[str, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Evidence: at the first step and every D samples after it the centring terms l_i and
        u_i (module docstring) are
        added to the filter's log-likelihood and, as the normalized innovation, to the
        evidence rule's statistics; in between only the filter's own log-likelihood."""
        assert self._posterior is not None
        n_runs, n_comp = state.log_w.shape
        count = state.evidence[_COUNT] + 1
        due = (count - 1) % self.decimation == 0
        first = (count == 1)[:, None]
        y = self._posterior[:, 1].reshape(n_runs, n_comp)
        last = state.evidence[_LAST_Y]
        p = self.params
        variance = np.where(first, p.level_variance, p.innovation_variance)
        score = np.where(first, y, y - p.autoregression * last) / np.sqrt(variance)
        centring = -0.5 * (score * score + np.log(2.0 * math.pi * variance))
        log_lik = log_lik.reshape(n_runs, n_comp)
        log_lik = np.where(due[:, None], log_lik + centring, log_lik)
        centring_score = normalized.copy()
        centring_score[:, :, 2] = np.where(due[:, None], score, np.nan)
        log_w, new_log_w, evidence, stats = super()._weigh(
            state, all_active, log_lik, centring_score, evidence
        )
        evidence = dict(evidence)
        evidence[_LAST_Y] = np.where(due[:, None], y, last)
        evidence[_COUNT] = count
        return log_w, new_log_w, evidence, stats
