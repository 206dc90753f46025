"""An autoregressive equation error for an ARX steering model (docs/design.md §8.32).

The paper's ARX model (eq. 8) takes its equation error as white. Fitted to human-like
drivers, whose remnant is filtered noise, its one-step residuals are not: at the true state
they are correlated at lags of one and two samples (0.2-0.3 each, §8.31). An estimator that
multiplies the likelihoods of such residuals counts the same evidence several times, so the
estimator's evidence rule tempers it and the steering counts for little. This module models the error instead (an ARARX model, Ljung 1999 §4.2)::

    A(q) delta(k) = B(q) phi(k) + C(q) Omega(k) + D(q) v_y(k) + e(k)     the ARX model
    e(k) = r_1 e(k-1) + ... + r_p e(k-p) + w(k),     w white               its error, AR(p)

with ``r`` by Yule-Walker from the fit's one-step residuals (:func:`equation_error_autoregression`).
Multiplying the model through by ``R(q) = 1 - r_1 q^-1 - ... - r_p q^-p`` gives an ARX model of
higher orders whose error is the white ``w`` (:func:`whitened_arx`)::

    R(q) A(q) delta = R(q) B(q) phi + R(q) C(q) Omega + R(q) D(q) v_y + w

Its steady state is the model's (``R(1)`` cancels), and the variance of ``w`` is that of ``e``
times ``1 - sum_i r_i rho_i`` (rho: the AR's autocorrelations; :func:`innovation_variance_ratio`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.linalg import solve_toeplitz
from statsmodels.tsa.arima_process import arma_acf
from statsmodels.tsa.statespace.mlemodel import MLEModel

from hasa_env.steering.arx import ARXForm, autoregression_roots

__all__ = [
    "MAX_EQUATION_ERROR_ORDER",
    "SPEED_SCALED_REFERENCE_SPEED",
    "MAX_CORRELATION",
    "MIN_SCALE_SPEED",
    "MIN_WHITE_RATIO",
    "SpeedScaledError",
    "speed_scale",
    "speed_scaled_error",
    "speed_scaled_log_likelihood",
    "check_equation_error_ar",
    "equation_error_autoregression",
    "innovation_variance_ratio",
    "whitened_arx",
]

MAX_EQUATION_ERROR_ORDER = 10
"""Most lags of the equation error's autoregression."""


def equation_error_autoregression(residuals: Sequence[np.ndarray], order: int) -> tuple[float, ...]:
    """(r_1, ..., r_order): the Yule-Walker autoregression of the one-step ``residuals`` (one
    array per run, in time order, NaN where a sample has no residual).

    Autocovariances are pooled over runs, each run's mean removed, over the pairs of samples
    ``lag`` apart that both have a residual (lags never cross runs), divided by the number of
    residuals (the biased estimate Yule-Walker takes). ``()`` when ``order`` is 0, there are
    fewer than ``10 (order + 1)`` residuals, or the autoregression is not stationary (a root
    of ``R`` on or inside the unit circle)."""
    order = int(order)
    if not 0 <= order <= MAX_EQUATION_ERROR_ORDER:
        raise ValueError(f"order must be in 0..{MAX_EQUATION_ERROR_ORDER}, got {order}")
    if order == 0:
        return ()
    covariances = np.zeros(order + 1)
    count = 0
    for values in residuals:
        values = np.asarray(values, dtype=np.float64)
        finite = np.isfinite(values)
        if not finite.any():
            continue
        centred = np.where(finite, values - values[finite].mean(), 0.0)
        count += int(finite.sum())
        for lag in range(order + 1):
            covariances[lag] += float(np.dot(centred[: centred.size - lag], centred[lag:]))
    if count < 10 * (order + 1) or not covariances[0] > 0:
        return ()
    ar = solve_toeplitz(covariances[:order], covariances[1:])
    try:
        return check_equation_error_ar(ar)
    except ValueError:
        return ()


def check_equation_error_ar(ar: Sequence[float]) -> tuple[float, ...]:
    """``ar`` as a tuple of floats; ValueError naming the problem unless it is at most
    :data:`MAX_EQUATION_ERROR_ORDER` finite numbers of a stationary autoregression (every root
    of ``z^p - r_1 z^(p-1) - ... - r_p`` strictly inside the unit circle)."""
    values = tuple(float(v) for v in ar)
    if len(values) > MAX_EQUATION_ERROR_ORDER:
        raise ValueError(
            f"the equation error's autoregression has {len(values)} lags, at most "
            f"{MAX_EQUATION_ERROR_ORDER} allowed"
        )
    if not all(np.isfinite(values)):
        raise ValueError(f"the equation error's autoregression {values} is not finite")
    if values:
        largest = float(np.max(np.abs(autoregression_roots(values))))
        if largest >= 1.0:
            raise ValueError(
                f"the equation error's autoregression {values} is not stationary "
                f"(largest root modulus {largest:.4g}, must be < 1)"
            )
    return values


def whitened_arx(arx: ARXForm, ar: Sequence[float]) -> ARXForm:
    """``arx`` multiplied through by ``R(q) = 1 - sum_i ar_i q^-i`` (module docstring): the
    ARX form whose equation error is white; ``arx`` itself when ``ar`` is empty."""
    if not len(ar):
        return arx
    factor = np.r_[1.0, -np.asarray(ar, dtype=np.float64)]
    steering = np.convolve(factor, np.r_[1.0, -np.asarray(arx.a, dtype=np.float64)])

    def times(values: tuple[float, ...]) -> tuple[float, ...]:
        return tuple(float(v) for v in np.convolve(factor, values)) if values else ()

    return replace(
        arx,
        a=tuple(float(v) for v in -steering[1:]),
        b=times(arx.b),
        c=times(arx.c),
        d=times(arx.d),
    )


def innovation_variance_ratio(ar: Sequence[float]) -> float:
    """Var w / Var e of the AR(p) error ``e`` (module docstring): ``1 - sum_i r_i rho_i``
    with ``rho`` the autocorrelations of the stationary AR (statsmodels' ``arma_acf``); 1 for
    an empty ``ar``."""
    if not len(ar):
        return 1.0
    values = np.asarray(ar, dtype=np.float64)
    rho = arma_acf(np.r_[1.0, -values], np.array([1.0]), lags=values.size + 1)[1:]
    return float(1.0 - np.dot(values, rho))


SPEED_SCALED_REFERENCE_SPEED = 15.0
"""v_ref (m/s) of :class:`SpeedScaledError`: the speed its coloured level is quoted at."""
MIN_SCALE_SPEED = 5.0
"""The speed (m/s) below which :func:`speed_scale` stops growing."""
_RUN_GAP = 100  # missing samples between runs in the joint likelihood (rho^100 ~ 0)


def speed_scale(speed: np.ndarray | float, reference_speed: float) -> np.ndarray:
    """``(v_ref / max(|v|, MIN_SCALE_SPEED))^2`` at the speeds ``speed`` (m/s): the steering a
    given lateral acceleration needs at v, relative to v_ref (docs/design.md §8.34)."""
    ratio = reference_speed / np.maximum(
        np.abs(np.asarray(speed, dtype=np.float64)), MIN_SCALE_SPEED
    )
    return ratio * ratio


MAX_CORRELATION = 0.99
"""The largest correlation per sample :func:`speed_scaled_error` accepts: above it the
coloured part is nearly a random walk, which would absorb a constant steering offset (the
lane evidence itself) and is not told apart from a slow drift of the model."""
MIN_WHITE_RATIO = 0.01
"""The smallest white std, relative to the coloured one, :func:`speed_scaled_error` accepts:
below it the fit sits on the boundary of no white part, where the level is not identified."""


@dataclass(frozen=True)
class SpeedScaledError:
    """An equation error whose coloured part scales with the speed (docs/design.md §8.34)::

        e(k) = (v_ref / v(k))^2 c(k) + w(k),   c(k) = rho c(k-1) + eta(k)
        Var c = coloured_std^2 (stationary),   Var w = white_std^2

    ``(v_ref / v)^2``: the steering a given lateral acceleration needs, relative to v_ref
    (``v`` floored at 5 m/s). Units: rad (model units), m/s, rho per sample."""

    coloured_std: float
    correlation: float
    white_std: float
    reference_speed: float = SPEED_SCALED_REFERENCE_SPEED
    log_likelihood: float = math.nan
    samples: int = 0

    def to_dict(self) -> dict[str, float]:
        """The four numbers a model file and ``results.json`` keep (not the fit's
        log-likelihood and sample count)."""
        return {
            "coloured_std": self.coloured_std,
            "correlation": self.correlation,
            "white_std": self.white_std,
            "reference_speed": self.reference_speed,
        }

    def scale(self, speed: np.ndarray | float) -> np.ndarray:
        """:func:`speed_scale` at the speeds ``speed`` (m/s)."""
        return speed_scale(speed, self.reference_speed)


def _stacked(
    residuals: Sequence[np.ndarray], speeds: Sequence[np.ndarray], reference_speed: float
) -> tuple[np.ndarray, np.ndarray]:
    """The runs' residuals, each run's mean removed (a driver's aim offset, which the filter
    models apart, as :func:`equation_error_autoregression` removes it), and their scales end to
    end, ``_RUN_GAP`` missing samples between runs (a sample without a residual or a finite
    speed is missing)."""
    values, scales = [], []
    for e, v in zip(residuals, speeds, strict=True):
        e = np.asarray(e, dtype=np.float64).reshape(-1)
        v = np.asarray(v, dtype=np.float64).reshape(-1)
        if e.shape != v.shape:
            raise ValueError(f"a run has {e.size} residuals but {v.size} speeds")
        ok = np.isfinite(e) & np.isfinite(v)
        centred = e - np.mean(e[ok]) if ok.any() else e  # a run's own offset is not its error
        values += [np.where(ok, centred, np.nan), np.full(_RUN_GAP, np.nan)]
        scales += [speed_scale(np.where(ok, v, reference_speed), reference_speed)]
        scales += [np.ones(_RUN_GAP)]
    if not values:
        return np.empty(0), np.empty(0)
    return np.concatenate(values), np.concatenate(scales)


class _SpeedScaledModel(MLEModel):
    """statsmodels' state-space form of :class:`SpeedScaledError` on residuals in units of
    their std: state c, design s(v(k)) (time-varying), transition rho, state noise
    ``sigma_c^2 (1 - rho^2)``, observation noise ``sigma_w^2``, c started stationary.
    Parameters (sigma_c, rho, sigma_w), rho kept in (0, 1) by a logistic map."""

    def __init__(self, endog: np.ndarray, design: np.ndarray) -> None:
        super().__init__(endog, k_states=1, initialization="stationary")
        self["design"] = design[None, None, :]
        self["selection", 0, 0] = 1.0

    @property
    def start_params(self) -> np.ndarray:
        return np.array([0.8, 0.5, 0.5])

    @property
    def param_names(self) -> list[str]:
        return ["coloured_std", "correlation", "white_std"]

    def transform_params(self, unconstrained: np.ndarray) -> np.ndarray:
        sigma_c, logit, sigma_w = unconstrained
        return np.array([np.exp(sigma_c), 1.0 / (1.0 + np.exp(-logit)), np.exp(sigma_w)])

    def untransform_params(self, constrained: np.ndarray) -> np.ndarray:
        sigma_c, rho, sigma_w = constrained
        return np.array([np.log(sigma_c), np.log(rho / (1.0 - rho)), np.log(sigma_w)])

    def update(self, params: np.ndarray, **kwargs: Any) -> None:
        sigma_c, rho, sigma_w = super().update(params, **kwargs)
        self["transition", 0, 0] = rho
        self["state_cov", 0, 0] = sigma_c * sigma_c * (1.0 - rho * rho)
        self["obs_cov", 0, 0] = sigma_w * sigma_w


def _in_units(
    residuals: Sequence[np.ndarray], speeds: Sequence[np.ndarray], reference_speed: float
) -> tuple[_SpeedScaledModel, float, int] | None:
    """The state-space model of the runs' residuals in units of their std, that std (rad) and
    the number of residuals; None without residuals or spread."""
    endog, design = _stacked(residuals, speeds, reference_speed)
    finite = np.isfinite(endog)
    unit = float(np.std(endog[finite])) if finite.any() else 0.0
    if not unit > 0:
        return None
    return _SpeedScaledModel(endog / unit, design), unit, int(finite.sum())


def speed_scaled_log_likelihood(
    error: SpeedScaledError, residuals: Sequence[np.ndarray], speeds: Sequence[np.ndarray]
) -> tuple[float, int]:
    """(the Gaussian log-likelihood of the one-step ``residuals`` (one array per run, NaN
    where a sample has none; rad) under ``error`` at the runs' ``speeds`` (m/s), the number
    of residuals); (NaN, 0) without any."""
    found = _in_units(residuals, speeds, error.reference_speed)
    if found is None:
        return math.nan, 0
    model, unit, count = found
    params = np.array([error.coloured_std / unit, error.correlation, error.white_std / unit])
    if not (params[0] > 0 and params[2] > 0):  # a degenerate part: the log-likelihood's limit
        params = np.maximum(params, [1e-12, 0.0, 1e-12])
    return float(model.loglike(params)) - count * math.log(unit), count


def speed_scaled_error(
    residuals: Sequence[np.ndarray],
    speeds: Sequence[np.ndarray],
    *,
    reference_speed: float = SPEED_SCALED_REFERENCE_SPEED,
    min_samples: int = 500,
) -> SpeedScaledError | None:
    """The :class:`SpeedScaledError` of the one-step ``residuals`` (one array per run, NaN
    where a sample has none) at the runs' ``speeds`` (m/s, same shapes), by maximum
    likelihood: statsmodels' Kalman filter on the model ``e = s(v) c + w`` with the time-varying
    design s(v), runs joined by missing samples, c started stationary. None with fewer than
    ``min_samples`` residuals, when the optimizer does not converge, or when the fit ends on
    the boundary (correlation above :data:`MAX_CORRELATION` or white std below
    :data:`MIN_WHITE_RATIO` times the coloured one: not identified)."""
    found = _in_units(residuals, speeds, reference_speed)
    if found is None or found[2] < min_samples:
        return None
    model, unit, count = found
    result = model.fit(disp=False, maxiter=200)
    if not result.mle_retvals.get("converged", False):
        return None
    sigma_c, rho, sigma_w = (float(p) for p in result.params)
    if rho > MAX_CORRELATION or sigma_w < MIN_WHITE_RATIO * sigma_c:
        return None  # on the boundary: a random walk, or no white part, is not identified
    return SpeedScaledError(
        coloured_std=sigma_c * unit,
        correlation=rho,
        white_std=sigma_w * unit,
        reference_speed=float(reference_speed),
        log_likelihood=float(result.llf) - count * math.log(unit),
        samples=count,
    )
