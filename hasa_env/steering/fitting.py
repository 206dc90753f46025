"""Fitting steering models that are linear in their parameters (docs/design.md §6).

:func:`fit_model` (what ``model.fit(runs)`` calls) estimates the parameters
from one or many runs (lags never cross from one run into the next) and
checks what it found.

Closed-loop data make regressors collinear (docs/design.md §6.5), so the
default fit is ridge regression on standardized columns with the penalty
chosen by blocked cross-validation on the training data only
(:mod:`hasa_env.steering.regression` states the equations).

Closed-loop data barely constrain how a model splits its memory between the
AR terms and the lagged bearings: very different AR parts predict the next
sample equally well, and the cross-validated choice can have an AR pole
outside the unit circle (measured: the paper's generalized model driving the
car, refitted, has poles of magnitude 5.1 by least squares and 1.13 at the
cross-validated penalty, with one-step residuals within 0.1 % of the true
model's). With ``stable=True`` (default) the fit then moves up the penalty
grid to the smallest penalty whose AR part is stable (here 3.2e-5, residuals
+2.3 %); :class:`FitChecks` records both penalties, and a fit that no penalty
makes stable stays flagged.

Every fit reports :class:`FitChecks`: the condition number of the
standardized design, the ridge ``lambda``, the AR part's poles and whether
they lie inside the unit circle, the identifiability of the lane offset
(:mod:`hasa_env.steering.identifiability`, with the steering-sensor noise
included), and flags; a fit that is unstable or unidentifiable warns
(:class:`~hasa_env.steering.identifiability.StabilityWarning`,
:class:`~hasa_env.steering.identifiability.IdentifiabilityWarning`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from hasa_env.sim.road import Road, curvature_lookup_array
from hasa_env.steering.design import SteeringModelLike as SteeringModel
from hasa_env.steering.design import as_runs, lagged, r_squared
from hasa_env.steering.equation_error import equation_error_autoregression
from hasa_env.steering.identifiability import (
    STABILITY_TOLERANCE,
    IdentifiabilityReport,
    IdentifiabilityWarning,
    StabilityWarning,
    ar_poles,
    check_identifiability,
)
from hasa_env.steering.regression import (
    DEFAULT_LAMBDAS,
    ILL_CONDITIONED,
    CrossValidation,
    LinearSolution,
    check_regression_shapes,
    choose_ridge_lambda,
    least_squares,
    ridge_regression,
    standardize_columns,
)

__all__ = [
    "DEFAULT_LAMBDAS",
    "CrossValidation",
    "FitChecks",
    "FitResult",
    "LinearSolution",
    "choose_ridge_lambda",
    "fit_model",
    "least_squares",
    "ridge_regression",
]


@dataclass(frozen=True)
class FitChecks:
    """What a fit is fit for (docs/design.md §6.5); ``flags`` lists what failed.

    Attributes:
        condition_number: of the standardized design matrix (unit-RMS columns).
        ridge_lambda: the penalty of the fit (0: least squares).
        cross_validated_lambda: the penalty cross-validation chose (larger
            ``ridge_lambda``: raised until the AR part was stable; equal when
            the penalty was given).
        effective_parameters: trace of the fit's hat matrix.
        ar_poles: poles of the AR part (empty without one, or for a model without an ARX form).
        ar_poles_max_abs: largest |pole| (NaN without an AR part).
        stable: every pole inside the unit circle (an integrating pole on it counts
            as stable); None for a model without an ARX form.
        identifiable: the lane offset is identifiable through the model
            (:class:`~hasa_env.steering.identifiability.IdentifiabilityReport.ok`);
            None for a model without an ARX form.
        lane_snr: the report's lane SNR (steering-sensor noise included).
        feature_collinearity: per feature of the model's regressors (all its
            lags together), ``1 - R^2`` of its columns regressed on the other
            features' columns of the standardized training design: how much of
            it the training data let the fit tell apart from the rest (lags of
            one feature are collinear by nature and are not compared).
        flags: ``"unstable"``, ``"unidentifiable"``, ``"ill_conditioned"`` (condition
            number above :data:`ILL_CONDITIONED` and no ridge penalty),
            ``"collinear_features"`` (a feature's ``1 - R^2`` below
            :data:`COLLINEAR`: the training data do not separate it from the
            others, so its coefficients, and what the model predicts where the
            features vary differently, e.g. at other speeds, are not
            identified).
    """

    condition_number: float
    ridge_lambda: float
    cross_validated_lambda: float
    effective_parameters: float
    ar_poles: tuple[complex, ...]
    ar_poles_max_abs: float
    stable: bool | None
    identifiable: bool | None
    lane_snr: float
    flags: tuple[str, ...]
    feature_collinearity: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """No flag raised."""
        return not self.flags

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict (poles as [real, imaginary] pairs)."""
        return {
            "condition_number": self.condition_number,
            "ridge_lambda": self.ridge_lambda,
            "cross_validated_lambda": self.cross_validated_lambda,
            "effective_parameters": self.effective_parameters,
            "ar_poles": [[p.real, p.imag] for p in self.ar_poles],
            "ar_poles_max_abs": self.ar_poles_max_abs,
            "stable": self.stable,
            "identifiable": self.identifiable,
            "lane_snr": self.lane_snr,
            "feature_collinearity": dict(self.feature_collinearity),
            "flags": list(self.flags),
        }


COLLINEAR = 1e-4
"""``1 - R^2`` of a feature on the others below which the fit flags ``collinear_features``.
Measured on the paper protocol's training runs (docs/design.md §6.5): a run at constant
speed leaves phi, Omega and v_y each explained by the others to 1 - R^2 = 2e-7 to 6e-6; a run
whose speed ramps to 45 m/s, to 8e-3 to 3e-2."""


def feature_collinearity(matrix: np.ndarray, features: Sequence[str]) -> dict[str, float]:
    """``1 - R^2`` of each feature's columns on the other features' columns (see
    :class:`FitChecks`); a model with one feature gets an empty dict."""
    if matrix.shape[0] == 0 or len(set(features)) < 2:
        return {}
    scale = np.sqrt(np.mean(matrix * matrix, axis=0))
    Z = matrix / np.where(scale > 0, scale, 1.0)
    out = {}
    for feature in dict.fromkeys(features):
        own = [i for i, f in enumerate(features) if f == feature]
        others = [i for i, f in enumerate(features) if f != feature]
        target, basis = Z[:, own], Z[:, others]
        coefficients, *_ = np.linalg.lstsq(basis, target, rcond=None)
        residual = target - basis @ coefficients
        total = float(np.sum(target * target))
        out[feature] = float(np.sum(residual * residual) / total) if total > 0 else 0.0
    return out


def _stable(model: SteeringModel, solution: LinearSolution) -> bool:
    """Whether the model with these parameters has a stable AR part (True without one)."""
    arx = model.with_parameters(solution.parameters).arx()
    if arx is None:
        return True
    poles = ar_poles(arx)
    return bool(poles.size == 0 or np.max(np.abs(poles)) <= 1.0 + STABILITY_TOLERANCE)


def _checks(
    fitted: SteeringModel,
    solution: LinearSolution,
    report: IdentifiabilityReport | None,
    condition_number: float,
    cv_lambda: float,
    collinearity: dict[str, float] | None = None,
) -> FitChecks:
    arx = fitted.arx()
    poles: tuple[complex, ...] = ()
    max_abs = float("nan")
    stable: bool | None = None
    if arx is not None:
        roots = ar_poles(arx)
        poles = tuple(complex(p) for p in roots)
        max_abs = float(np.max(np.abs(roots))) if roots.size else 0.0
        stable = bool(max_abs <= 1.0 + STABILITY_TOLERANCE)
    flags = []
    if stable is False:
        flags.append("unstable")
    if report is not None and not report.ok:
        flags.append("unidentifiable")
    if condition_number > ILL_CONDITIONED and solution.ridge_lambda == 0:
        flags.append("ill_conditioned")
    collinearity = dict(collinearity or {})
    if any(v < COLLINEAR for v in collinearity.values()):
        flags.append("collinear_features")
    return FitChecks(
        condition_number=condition_number,
        ridge_lambda=solution.ridge_lambda,
        cross_validated_lambda=cv_lambda,
        effective_parameters=solution.effective_parameters,
        ar_poles=poles,
        ar_poles_max_abs=max_abs,
        stable=stable,
        identifiable=None if report is None else report.ok,
        lane_snr=float("nan") if report is None else report.lane_snr,
        flags=tuple(flags),
        feature_collinearity=collinearity,
    )


# ----------------------------------------------------------------- fitting
@dataclass(frozen=True)
class FitResult:
    """A fit of a steering model.

    Attributes:
        parameter_names: names, in order.
        parameters: estimates.
        standard_errors: their standard errors.
        covariance: their covariance matrix.
        residuals: one-step residuals delta(k) - delta_hat(k) of every run (rad), concatenated.
        run_lengths: number of residuals from each run.
        n_obs: samples used; n_params: parameters fitted.
        rss: residual sum of squares (rad^2); residual_std: sqrt(rss / (n - df)) (rad).
        r2: R^2 on delta; r2_increments: R^2 on delta(k) - delta(k-1).
        log_likelihood: Gaussian log-likelihood at the ML variance rss/n.
        aic, bic: n log(rss/n) + 2 df, n log(rss/n) + df log(n), with df the
            effective number of parameters.
        identifiability: the check of :func:`check_identifiability` (None if not ARX).
        checks: :class:`FitChecks`.
        cross_validation: how the ridge penalty was chosen (None if it was given).
        steering_signal: which steering column was fitted ("measured" or "applied").
    """

    parameter_names: tuple[str, ...]
    parameters: np.ndarray
    standard_errors: np.ndarray
    covariance: np.ndarray
    residuals: np.ndarray = field(repr=False)
    run_lengths: tuple[int, ...]
    n_obs: int
    n_params: int
    rss: float
    residual_std: float
    r2: float
    r2_increments: float
    log_likelihood: float
    aic: float
    bic: float
    identifiability: IdentifiabilityReport | None = None
    checks: FitChecks | None = None
    cross_validation: CrossValidation | None = field(default=None, repr=False)
    steering_signal: str = "measured"

    def summary(self) -> pd.DataFrame:
        """Estimates, standard errors and t-values, one row per parameter."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t = self.parameters / self.standard_errors
        return pd.DataFrame(
            {"estimate": self.parameters, "std_error": self.standard_errors, "t": t},
            index=pd.Index(self.parameter_names, name="parameter"),
        )


def criteria(rss: float, n: int, p: float) -> tuple[float, float, float]:
    """(log-likelihood, AIC, BIC) of a Gaussian fit with ``p`` (effective) parameters."""
    if rss <= 0:
        return math.inf, -math.inf, -math.inf
    log_likelihood = -0.5 * n * (math.log(2.0 * math.pi * rss / n) + 1.0)
    base = n * math.log(rss / n)
    return log_likelihood, base + 2.0 * p, base + p * math.log(n)


def design_blocks(
    model: SteeringModel, runs: Sequence[pd.DataFrame], road: Road | None
) -> list[dict[str, np.ndarray]]:
    """Per run: the model's design rows with every entry finite, in time order.

    Each item has ``matrix`` (n_r, p), ``target`` (n_r,) (delta minus the
    model's fixed offset), ``delta`` (n_r,) and ``increment`` (n_r,), the
    measured delta(k) - delta(k-1) (NaN where there is no previous sample), and ``valid``
    (the run's length,): which of the run's rows they are.
    """
    out = []
    for run in runs:
        features = model.features(run, road)
        design = model.design(features)
        previous = lagged(features["delta"].to_numpy(dtype=np.float64), 1)
        valid = design.valid
        out.append(
            {
                "matrix": design.matrix[valid],
                "target": design.target[valid] - design.offset[valid],
                "delta": design.target[valid],
                "increment": (design.target - previous)[valid],
                "valid": valid,
            }
        )
    return out


def training_speed_range(runs: pd.DataFrame | Sequence[pd.DataFrame]) -> tuple[float, float] | None:
    """(min, max) speed (m/s) of the runs a model is fitted on (their ``speed`` column, NaN
    ignored); None when they have none."""
    values = [run["speed"].to_numpy(dtype=np.float64) for run in as_runs(runs) if "speed" in run]
    finite = np.concatenate(values) if values else np.zeros(0)
    finite = finite[np.isfinite(finite)]
    if finite.size == 0:
        return None
    return float(finite.min()), float(finite.max())


def training_curvature(
    runs: pd.DataFrame | Sequence[pd.DataFrame], road: Road | None = None
) -> float | None:
    """The largest |road curvature| (1/m) along the runs a model is fitted on: the runs'
    ``road_curvature`` column, else ``road``'s curvature at their ``station``; 0 when the
    features were computed for a straight road (no ``road`` or a straight one); None when
    neither tells (a curved ``road`` and runs without stations)."""
    largest = 0.0
    for run in as_runs(runs):
        if "road_curvature" in run:
            values = np.abs(run["road_curvature"].to_numpy(dtype=np.float64))
        elif road is None or road.is_straight:
            continue
        elif "station" in run:
            stations = run["station"].to_numpy(dtype=np.float64)
            values = np.abs(curvature_lookup_array(road.curvature, 1.0 / road.spacing, stations))
        else:
            return None
        values = values[np.isfinite(values)]
        if values.size:
            largest = max(largest, float(values.max()))
    return largest


def fit_model(
    model: SteeringModel,
    runs: pd.DataFrame | Sequence[pd.DataFrame],
    road: Road | None = None,
    warn: bool = True,
    *,
    ridge: str | float = "cv",
    folds: int = 5,
    lambdas: Sequence[float] = DEFAULT_LAMBDAS,
    rule: str = "min",
    stable: bool = True,
    sensor_std: float = 0.0,
    aim_offset: bool = False,
) -> SteeringModel:
    """Fit a model that is linear in its parameters (``model.fit`` calls this).

    Args:
        model: the model (its structure; its current parameters are ignored).
        runs: one run or a list of runs (recordings or features frames).
        road: the road of the runs (None: from their metadata, else straight).
        warn: warn when the fit is unstable or loses the identifiability of the
            lane offset (categories in :mod:`hasa_env.steering.identifiability`).
        ridge: ``"cv"`` (default): ridge with the penalty from blocked
            cross-validation on these runs (:func:`choose_ridge_lambda`); a
            number: ridge with that relative penalty; 0: least squares.
        folds: cross-validation folds (blocks per run).
        lambdas: the penalties cross-validation chooses from.
        rule: how cross-validation chooses (see :func:`choose_ridge_lambda`).
        stable: with ``ridge="cv"``, if the chosen penalty leaves the AR part
            unstable, take the smallest larger penalty of ``lambdas`` that
            makes it stable (see the module docstring).
        sensor_std: steering-sensor noise std (rad, model units) the
            identifiability check adds to the residual (see
            :func:`check_identifiability`).
        aim_offset: fit each run's aim offset as a nuisance intercept, one per run
            (:func:`_regression_solution`), left out of the model: a driver who keeps
            the car off the lane centre steers toward that offset, not toward the centre
            the features are measured from, and without the intercept the fit reads the
            held offset as "no position feedback" (docs/design.md §8.18). False: no
            intercept (the paper's eq. 10 as written).

    Returns:
        A new model of the same class with the estimates, their standard
        errors and ``fit_result`` (:class:`FitResult`, with its :class:`FitChecks`).
    """
    frames = as_runs(runs)
    names = model.parameter_names
    blocks = design_blocks(model, frames, road)
    X = np.vstack([b["matrix"] for b in blocks])
    y = np.concatenate([b["target"] for b in blocks])
    if X.shape[1] != len(names):
        raise ValueError(
            f"{model.name}: design has {X.shape[1]} columns for {len(names)} parameters"
        )
    check_regression_shapes(X, y)
    nuisance = len(blocks) if aim_offset and X.shape[1] else 0
    fit_blocks = _with_aim_offsets(blocks) if nuisance else blocks
    solution, cross_validation, cv_lambda = _regression_solution(
        model,
        fit_blocks,
        np.vstack([b["matrix"] for b in fit_blocks]) if nuisance else X,
        y,
        ridge=ridge,
        folds=folds,
        lambdas=lambdas,
        rule=rule,
        stable=stable,
        nuisance=nuisance,
    )
    condition = _condition_number(X, names, solution)
    result = _fit_result(model, blocks, X.shape, solution, cross_validation)
    fitted = model.with_parameters(solution.parameters, solution.standard_errors, fit_result=result)
    report = check_identifiability(
        fitted,
        solution.covariance,
        residual_std=math.sqrt(solution.sigma2),
        sensor_std=sensor_std,
    )
    try:
        regressor_features = [r.feature for r in getattr(model, "regressors", ())]
    except Exception:  # noqa: BLE001 - a user model's regressors need not match its design
        regressor_features = []
    collinearity = (
        feature_collinearity(X, regressor_features) if len(regressor_features) == X.shape[1] else {}
    )
    checks = _checks(fitted, solution, report, condition, cv_lambda, collinearity)
    result = replace(result, identifiability=report, checks=checks)
    fitted.fit_result = result
    fitted.training_curvature = training_curvature(runs, road)
    fitted.training_speed_range = training_speed_range(runs)
    fitted.equation_error_ar = equation_error_autoregression(
        [_run_residuals(block, fitted.parameter_vector) for block in blocks],
        int(getattr(model, "equation_error_order", 0)),
    )
    if warn:
        _warn_about_fit(model.name, report, checks)
    return fitted


def _run_residuals(block: Mapping[str, np.ndarray], parameters: np.ndarray) -> np.ndarray:
    """The fit's one-step residuals on one run's rows (NaN where the run has no design row)."""
    out = np.full(block["valid"].size, np.nan)
    out[block["valid"]] = block["target"] - block["matrix"] @ parameters
    return out


def _with_aim_offsets(blocks: Sequence[Mapping[str, np.ndarray]]) -> list[dict[str, np.ndarray]]:
    """``blocks`` with one indicator column per run appended to every run's matrix (1 in
    the run's own column): the runs' aim offsets, as intercepts."""
    out = []
    for r, block in enumerate(blocks):
        matrix = block["matrix"]
        ones = np.zeros((matrix.shape[0], len(blocks)))
        ones[:, r] = 1.0
        out.append({**block, "matrix": np.hstack([matrix, ones])})
    return out


def _without_nuisance(solution: LinearSolution, nuisance: int) -> LinearSolution:
    """``solution`` with its last ``nuisance`` parameters (the aim offsets) left out of the
    parameters, their covariance and standard errors (the residuals and their statistics are
    the fit's with them)."""
    if not nuisance:
        return solution
    keep = slice(0, solution.parameters.size - nuisance)
    return replace(
        solution,
        parameters=solution.parameters[keep],
        covariance=solution.covariance[keep, keep],
        standard_errors=solution.standard_errors[keep],
    )


def _regression_solution(
    model: SteeringModel,
    blocks: Sequence[Mapping[str, np.ndarray]],
    X: np.ndarray,
    y: np.ndarray,
    *,
    ridge: str | float,
    folds: int,
    lambdas: Sequence[float],
    rule: str,
    stable: bool,
    nuisance: int = 0,
) -> tuple[LinearSolution, CrossValidation | None, float]:
    """The regression of :func:`fit_model` (its arguments of the same names): (solution, the
    cross-validation or None, the penalty cross-validation chose, before any raise for
    stability). ``X``, ``y``: the blocks' matrices and targets stacked. The last ``nuisance``
    columns of the matrices (the runs' aim offsets) are fitted with the model's and left out of the solution::

        delta(k) = theta . x(k) + c_r + e(k),       c_r: run r's intercept

    (c_r = -sum_j beta_j . u_r: the features the driver holds still at, on a straight
    road those of their preferred offset)."""
    names = list(model.parameter_names) + [f"aim_offset_{r}" for r in range(nuisance)]
    cross_validation = None
    if isinstance(ridge, str):
        if ridge != "cv":
            raise ValueError(f"ridge must be 'cv', a number >= 0 or 0, got {ridge!r}")
        if X.shape[1] == 0:
            ridge_lambda = 0.0
        else:
            gap = int(getattr(model, "max_lag", 0))
            cross_validation = choose_ridge_lambda(
                [(b["matrix"], b["target"]) for b in blocks], lambdas, folds, gap, rule
            )
            ridge_lambda = cross_validation.ridge_lambda
    else:
        ridge_lambda = float(ridge)
    solution = _without_nuisance(ridge_regression(X, y, ridge_lambda, names), nuisance)
    if cross_validation is not None and stable and not _stable(model, solution):
        for candidate in sorted(v for v in lambdas if v > ridge_lambda):
            trial = _without_nuisance(ridge_regression(X, y, candidate, names), nuisance)
            if _stable(model, trial):
                solution = trial
                break
    return solution, cross_validation, ridge_lambda


def _condition_number(X: np.ndarray, names: Sequence[str], solution: LinearSolution) -> float:
    """The condition number sigma_max / sigma_min of the design with unit-RMS columns for a
    ridge fit (inf if singular), the solution's own otherwise."""
    if solution.ridge_lambda > 0 and X.shape[1]:
        Z, _ = standardize_columns(X, names)
        singular = np.linalg.svd(Z, compute_uv=False)
        return float(singular[0] / singular[-1]) if singular[-1] > 0 else math.inf
    return solution.condition_number


def _fit_result(
    model: SteeringModel,
    blocks: Sequence[Mapping[str, np.ndarray]],
    shape: tuple[int, ...],
    solution: LinearSolution,
    cross_validation: CrossValidation | None,
) -> FitResult:
    """The :class:`FitResult` of ``solution`` (without identifiability and checks): R^2 of
    the steering and of its increments (rows with a previous sample), AIC and BIC; ``shape``:
    the design's (rows, columns)."""
    n, p = shape
    log_likelihood, aic, bic = criteria(solution.rss, n, solution.effective_parameters)
    increments_all = np.concatenate([b["increment"] for b in blocks])
    has_previous = np.isfinite(increments_all)
    residuals_with_previous = solution.residuals[has_previous]
    return FitResult(
        parameter_names=model.parameter_names,
        parameters=solution.parameters,
        standard_errors=solution.standard_errors,
        covariance=solution.covariance,
        residuals=solution.residuals,
        run_lengths=tuple(int(b["target"].size) for b in blocks),
        n_obs=n,
        n_params=p,
        rss=solution.rss,
        residual_std=math.sqrt(solution.sigma2),
        r2=r_squared(solution.rss, np.concatenate([b["delta"] for b in blocks])),
        r2_increments=r_squared(
            float(residuals_with_previous @ residuals_with_previous), increments_all[has_previous]
        ),
        log_likelihood=log_likelihood,
        aic=aic,
        bic=bic,
        cross_validation=cross_validation,
        steering_signal=getattr(model, "steering_signal", "measured"),
    )


def _warn_about_fit(name: str, report: IdentifiabilityReport | None, checks: FitChecks) -> None:
    """Warn (at the caller of ``model.fit``) when the lane offset is not identified, features
    are collinear, or the AR part is unstable."""
    if report is not None and not report.ok:
        warnings.warn(f"{name} fit: {report.message}", IdentifiabilityWarning, stacklevel=4)
    collinear = {k: v for k, v in checks.feature_collinearity.items() if v < COLLINEAR}
    if collinear:
        shown = ", ".join(f"{k} (1 - R^2 = {v:.1e})" for k, v in collinear.items())
        warnings.warn(
            f"{name} fit: the training data do not tell {shown} apart from the "
            "other features: their coefficients are not identified, and predictions where "
            "the features vary differently (e.g. at other speeds) are extrapolations",
            IdentifiabilityWarning,
            stacklevel=4,
        )
    if checks.stable is False:
        warnings.warn(
            f"{name} fit: its AR part has a pole of magnitude "
            f"{checks.ar_poles_max_abs:.3g} outside the unit circle (ridge lambda "
            f"{checks.ridge_lambda:.3g}, condition number {checks.condition_number:.3g}): "
            "its own steering diverges in free run",
            StabilityWarning,
            stacklevel=4,
        )
