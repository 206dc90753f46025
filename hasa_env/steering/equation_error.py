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

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.linalg import solve_toeplitz
from statsmodels.tsa.arima_process import arma_acf

from hasa_env.steering.arx import ARXForm, autoregression_roots

__all__ = [
    "MAX_EQUATION_ERROR_ORDER",
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
