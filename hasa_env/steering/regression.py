"""Least squares and ridge regression for steering models, with blocked cross-validation.

Closed-loop data make regressors collinear (docs/design.md §6.5): at
constant speed ``v_y(k) - v_y(k-1)`` equals ``(Ts v^2 / L) tan delta(k-1)``
almost exactly and ``v_y`` lies in the span of ``(phi, Omega)``, so plain
least squares returns huge, cancelling, speed-specific coefficients. The
default fit is therefore ridge regression on standardized columns::

    s_j          = sqrt(mean_k X(k, j)^2)            column scale (no centring: the
                                                      models have no intercept)
    Z            = X diag(1/s)
    beta_z       = argmin |y - Z beta_z|^2 + n lambda |beta_z|^2
                 = V diag(sigma_i / (sigma_i^2 + n lambda)) U^T y    (Z = U diag(sigma) V^T)
    theta        = beta_z / s
    df(lambda)   = sum_i sigma_i^2 / (sigma_i^2 + n lambda)          effective parameters
    sigma_e^2    = RSS / (n - df)
    Cov(theta)   = sigma_e^2 diag(1/s) V diag(sigma_i^2 / (sigma_i^2 + n lambda)^2) V^T diag(1/s)

with ``lambda`` chosen on the training data only, by blocked cross-validation
in time (:func:`choose_ridge_lambda`): each run is cut into ``folds``
contiguous blocks; fold j holds out block j of every run and drops
``max_lag`` samples on either side of it from the training part (a
closed-loop run's samples are not independent); the ``lambda`` with the
smallest mean held-out one-step error wins (``rule="min"``; ``rule="1se"``,
the one-standard-error rule, takes the largest ``lambda`` within one standard
error of it instead: it shrinks further, at the price of a bias that, on
synthetic closed-loop runs, removed the lane-informative bearing terms). ``ridge=0`` gives ordinary least
squares through statsmodels (its standard errors and condition number);
a number gives that ``lambda``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import statsmodels.api as sm

__all__ = [
    "DEFAULT_LAMBDAS",
    "ILL_CONDITIONED",
    "CrossValidation",
    "LinearSolution",
    "check_regression_shapes",
    "choose_ridge_lambda",
    "least_squares",
    "ridge_regression",
    "standardize_columns",
]

DEFAULT_LAMBDAS = tuple(float(v) for v in np.logspace(-9.0, 1.0, 21))
"""The ridge penalties cross-validation chooses from (relative: columns have unit RMS).
The smallest, 1e-9, is already far above the squared singular values of an exactly
collinear pair, so every candidate resolves such a pair the minimum-norm way."""

ILL_CONDITIONED = 1e6
"""Condition number of the standardized design above which the regressors are
close to linearly dependent (the fit is flagged ``ill_conditioned``)."""


# ----------------------------------------------------------------- solvers
@dataclass(frozen=True)
class LinearSolution:
    """Parameters of ``target ~ matrix @ parameters`` and their statistics.

    Attributes:
        parameters: estimates, shape (p,).
        covariance: their covariance, shape (p, p).
        standard_errors: sqrt of its diagonal.
        residuals: target - matrix @ parameters, shape (n,).
        rss: residual sum of squares.
        sigma2: residual variance rss / (n - effective_parameters).
        effective_parameters: trace of the hat matrix (p for least squares).
        ridge_lambda: the penalty (relative to unit-RMS columns; 0: least squares).
        condition_number: largest / smallest singular value of the standardized matrix.
    """

    parameters: np.ndarray
    covariance: np.ndarray
    standard_errors: np.ndarray
    residuals: np.ndarray
    rss: float
    sigma2: float
    effective_parameters: float
    ridge_lambda: float
    condition_number: float


def standardize_columns(matrix: np.ndarray, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """(Z, s) with s_j = sqrt(mean_i X_ij^2) and Z = X / s (unit-RMS columns).

    An all-zero column (s_j = 0) is a ``ValueError`` naming it (``names[j]``)."""
    scale = np.sqrt(np.mean(matrix * matrix, axis=0))
    dead = np.flatnonzero(scale == 0)
    if dead.size:
        label = [names[i] if i < len(names) else f"column {i}" for i in dead.tolist()]
        raise ValueError(
            f"regressors {label} are identically zero in the data; they cannot be fitted"
        )
    return matrix / scale, scale


def check_regression_shapes(
    matrix: np.ndarray, target: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(X, y) as float64 arrays; ``ValueError`` unless X is (n, p) and y is (n,) with n > p."""
    X = np.asarray(matrix, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    if X.ndim != 2 or y.shape != (X.shape[0],):
        raise ValueError(f"need matrix (n, p) and target (n,), got {X.shape} and {y.shape}")
    if X.shape[0] <= X.shape[1]:
        raise ValueError(
            f"fitting needs more samples than parameters, got {X.shape[0]} samples for {X.shape[1]}"
        )
    return X, y


def least_squares(
    matrix: np.ndarray, target: np.ndarray, names: Sequence[str] = ()
) -> LinearSolution:
    """Ordinary least squares with standard errors (statsmodels ``OLS``).

    Raises ``ValueError`` if there are not more rows than columns, a column is
    all zeros, or the columns are linearly dependent in the data (naming the
    regressor).
    """
    X, y = check_regression_shapes(matrix, target)
    n, p = X.shape
    if p == 0:
        rss = float(y @ y)
        return LinearSolution(
            np.zeros(0), np.zeros((0, 0)), np.zeros(0), y.copy(), rss, rss / n, 0.0, 0.0, 1.0
        )
    Z, scale = standardize_columns(X, names)
    singular = np.linalg.svd(Z, compute_uv=False)
    if singular[-1] < 1e-12 * singular[0]:
        _, r = np.linalg.qr(Z)
        worst = int(np.argmin(np.abs(np.diag(r))))
        label = names[worst] if worst < len(names) else f"column {worst}"
        raise ValueError(
            f"regressors are linearly dependent in the data (at {label!r}); use a lower order, "
            "more varied data or a ridge penalty"
        )
    ols = sm.OLS(y, Z).fit()
    parameters = np.asarray(ols.params) / scale
    covariance = np.asarray(ols.cov_params()) / np.outer(scale, scale)
    return LinearSolution(
        parameters,
        covariance,
        np.sqrt(np.maximum(np.diag(covariance), 0.0)),
        np.asarray(ols.resid),
        float(ols.ssr),
        float(ols.scale),
        float(p),
        0.0,
        float(singular[0] / singular[-1]),
    )


def ridge_regression(
    matrix: np.ndarray, target: np.ndarray, ridge_lambda: float, names: Sequence[str] = ()
) -> LinearSolution:
    """Ridge regression on standardized columns (the module docstring's equations).

    ``ridge_lambda`` is relative to unit-RMS columns (the penalty is
    ``n * ridge_lambda * |beta_z|^2``); 0 gives least squares (:func:`least_squares`).
    """
    if not (math.isfinite(ridge_lambda) and ridge_lambda >= 0):
        raise ValueError(f"ridge_lambda must be a finite number >= 0, got {ridge_lambda!r}")
    if ridge_lambda == 0:
        return least_squares(matrix, target, names)
    X, y = check_regression_shapes(matrix, target)
    n, p = X.shape
    Z, scale = standardize_columns(X, names)
    u, sigma, vt = np.linalg.svd(Z, full_matrices=False)
    penalty = n * ridge_lambda
    shrink = sigma / (sigma * sigma + penalty)
    beta_z = vt.T @ (shrink * (u.T @ y))
    residuals = y - Z @ beta_z
    rss = float(residuals @ residuals)
    hat = sigma * sigma / (sigma * sigma + penalty)
    df = float(hat.sum())
    sigma2 = rss / max(n - df, 1.0)
    cov_z = sigma2 * (vt.T * (hat / (sigma * sigma + penalty))) @ vt
    covariance = cov_z / np.outer(scale, scale)
    return LinearSolution(
        beta_z / scale,
        covariance,
        np.sqrt(np.maximum(np.diag(covariance), 0.0)),
        residuals,
        rss,
        sigma2,
        df,
        float(ridge_lambda),
        float(sigma[0] / sigma[-1]) if sigma[-1] > 0 else math.inf,
    )


# -------------------------------------------------------- cross-validation
@dataclass(frozen=True)
class CrossValidation:
    """Blocked cross-validation of the ridge penalty (see :func:`choose_ridge_lambda`).

    Attributes:
        lambdas: the candidates (relative penalties).
        mean_error: mean over folds of the held-out mean squared one-step error (rad^2).
        standard_error: its standard error over folds.
        best: index of the smallest mean error.
        chosen: index picked by the rule (``best`` for ``"min"``).
        folds: number of folds.
    """

    lambdas: tuple[float, ...]
    mean_error: np.ndarray
    standard_error: np.ndarray
    best: int
    chosen: int
    folds: int

    @property
    def ridge_lambda(self) -> float:
        """The chosen penalty."""
        return self.lambdas[self.chosen]

    def table(self) -> pd.DataFrame:
        """One row per candidate: lambda, mean held-out MSE, its SE."""
        return pd.DataFrame(
            {
                "ridge_lambda": self.lambdas,
                "cv_mse": self.mean_error,
                "cv_mse_se": self.standard_error,
            }
        )


def choose_ridge_lambda(
    blocks: Sequence[tuple[np.ndarray, np.ndarray]],
    lambdas: Sequence[float] = DEFAULT_LAMBDAS,
    folds: int = 5,
    gap: int = 0,
    rule: str = "min",
) -> CrossValidation:
    """The ridge penalty by blocked cross-validation in time, on training data only.

    Args:
        blocks: per run, its design matrix (n_r, p) and target (n_r,) in time order.
        lambdas: candidate penalties (relative to unit-RMS columns, > 0).
        folds: contiguous blocks per run (>= 2).
        gap: samples dropped from training on each side of a held-out block
            (the model's largest lag, so no training row shares a lagged sample
            with a held-out one).
        rule: ``"min"``: the penalty of the smallest mean held-out error;
            ``"1se"``: the largest penalty whose mean held-out error is within
            one standard error (over folds) of the smallest.

    Returns:
        The :class:`CrossValidation` (its ``ridge_lambda`` is the choice).
    """
    if rule not in ("min", "1se"):
        raise ValueError(f"rule must be 'min' or '1se', got {rule!r}")
    if isinstance(folds, bool) or not isinstance(folds, int) or folds < 2:
        raise ValueError(f"folds must be an integer >= 2, got {folds!r}")
    grid = np.asarray(lambdas, dtype=np.float64)
    if grid.ndim != 1 or grid.size == 0 or not np.all(np.isfinite(grid) & (grid > 0)):
        raise ValueError(f"lambdas must be finite positive numbers, got {list(lambdas)}")
    fold_of = [
        np.minimum((np.arange(m.shape[0]) * folds) // max(m.shape[0], 1), folds - 1)
        for m, _ in blocks
    ]
    X = np.vstack([m for m, _ in blocks])
    y = np.concatenate([t for _, t in blocks])
    scale = np.sqrt(np.mean(X * X, axis=0))
    scale[scale == 0] = 1.0
    Z = X / scale
    errors = np.full((folds, grid.size), np.nan)
    for j in range(folds):
        test = np.concatenate([f == j for f in fold_of])
        train = np.concatenate([_training_rows(f, j, gap) for f in fold_of])
        if test.sum() == 0 or train.sum() <= Z.shape[1]:
            continue
        u, sigma, vt = np.linalg.svd(Z[train], full_matrices=False)
        uty = u.T @ y[train]
        n_train = int(train.sum())
        # beta(lambda) for every candidate at once: V diag(sigma / (sigma^2 + n lambda)) U^T y
        shrink = sigma[None, :] / (sigma[None, :] ** 2 + n_train * grid[:, None])
        betas = (shrink * uty[None, :]) @ vt  # (n_lambdas, p)
        residual = y[test][:, None] - Z[test] @ betas.T
        errors[j] = np.mean(residual * residual, axis=0)
    ok = np.all(np.isfinite(errors), axis=1)
    if ok.sum() < 2:
        raise ValueError(
            f"cross-validation needs at least 2 usable folds; the training data have only "
            f"{sum(m.shape[0] for m, _ in blocks)} samples"
        )
    errors = errors[ok]
    mean = errors.mean(axis=0)
    se = errors.std(axis=0, ddof=1) / math.sqrt(errors.shape[0])
    best = int(np.argmin(mean))
    chosen = best
    if rule == "1se":
        chosen = int(np.flatnonzero(mean <= mean[best] + se[best]).max())
    return CrossValidation(tuple(grid.tolist()), mean, se, best, chosen, int(ok.sum()))


def _training_rows(fold: np.ndarray, held_out: int, gap: int) -> np.ndarray:
    """Rows of one run that train fold ``held_out``: the other blocks, minus ``gap``
    rows on either side of the held-out block."""
    keep = fold != held_out
    held = np.flatnonzero(~keep)
    if gap > 0 and held.size:
        rows = np.arange(fold.size)
        keep &= (rows < held[0] - gap) | (rows > held[-1] + gap)
    return keep


# ------------------------------------------------------------------ checks
