"""Fitting and scoring steering models (paper section 3.3; docs/design.md §6).

- :func:`fit_model` (what ``model.fit(runs)`` calls): ordinary least squares
  on one or many runs, with standard errors and the identifiability check.
- :func:`residual_diagnostics`: autocorrelation and Ljung-Box whiteness
  (statsmodels) of residuals.
- :func:`check_identifiability`: the static lane-offset gain
  ``sum(b)/near + sum(c)/far`` must be clearly non-zero (with the sign of
  ``1 - sum(a)``) for the estimator to tell lanes apart; the paper's "any
  b_i or c_0 non-zero" is not enough. Fits that lose it warn
  (:class:`IdentifiabilityWarning`).
- :func:`score` / :func:`score_runs`: RMSE, R^2 on delta, R^2 on the
  increments delta(k) - delta(k-1) and Ljung-Box p-value, for one-step
  prediction (measured past steering) and free-run simulation.

Runs are recordings (:data:`hasa_env.sim.setup.RECORDING_COLUMNS`) or features
frames (:func:`hasa_env.steering.features.steering_features`), one
``pandas.DataFrame`` per run; lags never cross from one run into another.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd
from scipy import signal
from statsmodels.stats.diagnostic import acorr_ljungbox
from statsmodels.tsa.stattools import acf

from hasa_env.sim.road import Road
from hasa_env.steering.arx import ARXForm
from hasa_env.steering.design import SteeringModelLike as SteeringModel
from hasa_env.steering.design import lagged

__all__ = [
    "FitResult",
    "IdentifiabilityReport",
    "IdentifiabilityWarning",
    "ResidualDiagnostics",
    "check_identifiability",
    "fit_model",
    "least_squares",
    "residual_diagnostics",
    "score",
    "score_runs",
    "simulate_arx",
]


class IdentifiabilityWarning(UserWarning):
    """A fitted model's static lane-offset gain is not clearly non-zero (or has the wrong sign)."""


# --------------------------------------------------------------------------- OLS
@dataclass(frozen=True)
class LeastSquares:
    """Result of :func:`least_squares`.

    Attributes:
        parameters: estimates, shape (p,).
        covariance: their covariance sigma^2 (X'X)^-1, shape (p, p).
        standard_errors: sqrt of its diagonal.
        residuals: y - X parameters, shape (n,).
        rss: residual sum of squares.
        sigma2: residual variance rss / (n - p).
    """

    parameters: np.ndarray
    covariance: np.ndarray
    standard_errors: np.ndarray
    residuals: np.ndarray
    rss: float
    sigma2: float


def least_squares(
    matrix: np.ndarray, target: np.ndarray, names: Sequence[str] = ()
) -> LeastSquares:
    """Ordinary least squares ``target ~ matrix @ parameters`` with standard errors.

    Columns are scaled to unit norm and solved by QR (robust to the strong
    collinearity of 100 Hz lags). Raises ``ValueError`` if there are not more
    rows than columns or the columns are linearly dependent (naming them).
    """
    X = np.asarray(matrix, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    n, p = X.shape
    if n <= p:
        raise ValueError(
            f"least squares needs more samples than parameters, got {n} samples for {p}"
        )
    if p == 0:
        residuals = y.copy()
        rss = float(residuals @ residuals)
        empty = np.zeros(0)
        return LeastSquares(empty, np.zeros((0, 0)), empty, residuals, rss, rss / n)
    norms = np.linalg.norm(X, axis=0)
    dead = np.flatnonzero(norms == 0)
    if dead.size:
        label = [names[i] if i < len(names) else f"column {i}" for i in dead]
        raise ValueError(
            f"regressors {label} are identically zero in the data; they cannot be fitted"
        )
    Xs = X / norms
    q, r = np.linalg.qr(Xs)
    diag = np.abs(np.diag(r))
    if diag.min() < 1e-12 * diag.max():
        worst = int(np.argmin(diag))
        label = names[worst] if worst < len(names) else f"column {worst}"
        raise ValueError(
            f"regressors are linearly dependent in the data (at {label!r}); use a lower order "
            "or more varied data"
        )
    scaled = np.linalg.solve(r, q.T @ y)
    theta = scaled / norms
    residuals = y - X @ theta
    rss = float(residuals @ residuals)
    sigma2 = rss / (n - p)
    r_inv = np.linalg.solve(r, np.eye(p))
    cov_scaled = sigma2 * (r_inv @ r_inv.T)
    covariance = cov_scaled / np.outer(norms, norms)
    se = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    return LeastSquares(theta, covariance, se, residuals, rss, sigma2)


# ----------------------------------------------------------- identifiability
@dataclass(frozen=True)
class IdentifiabilityReport:
    """The static lane-offset gain of a model (docs/design.md §5.7).

    Attributes:
        static_lane_gain: G = sum(b)/near + sum(c)/far (rad/m). With
            phi ~ -y/near, omega ~ -y/far, a lane-centre error of e metres
            held over the model's memory moves its one-step prediction by
            -G e; at steady state (1 - sum a) delta = -G y.
        standard_error: SE of G from the fit's covariance (NaN if unknown).
        memory_gain: 1 - sum(a) (0 for an integrating model such as the two-point).
        memory_standard_error: its SE (NaN if unknown).
        integrating: 1 - sum(a) is zero or within z SE of zero.
        steady_state_gain: delta/y at steady state = -G / (1 - sum a) (rad/m;
            +-inf for an integrating model).
        lane_snr: |G| * lane_separation / residual std: how many residual
            standard deviations one prediction moves between two lane
            hypotheses ``lane_separation`` m apart (NaN without a fit).
        identifiable: G is clearly non-zero: |G| > z SE when the SE is
            known, else |G| > min_gain.
        sign_consistent: at steady state the model steers towards the lane
            centre: G has the sign of 1 - sum(a), or G > 0 if it integrates.
        message: a sentence saying what was found.
    """

    static_lane_gain: float
    standard_error: float
    memory_gain: float
    memory_standard_error: float
    integrating: bool
    steady_state_gain: float
    lane_snr: float
    identifiable: bool
    sign_consistent: bool
    message: str

    @property
    def ok(self) -> bool:
        """Identifiable and sign-consistent."""
        return self.identifiable and self.sign_consistent


def _arx_gradient(model: SteeringModel, quantity: Callable[[ARXForm], float]) -> np.ndarray | None:
    """d quantity(arx) / d parameters (exact when the ARX form is affine in the parameters)."""
    theta = model.parameter_vector
    grad = np.zeros(theta.size)
    for j in range(theta.size):
        step = max(1.0, abs(theta[j]))
        up, down = theta.copy(), theta.copy()
        up[j] += step
        down[j] -= step
        arx_up = model.with_parameters(up).arx()
        arx_down = model.with_parameters(down).arx()
        if arx_up is None or arx_down is None:
            return None
        grad[j] = (quantity(arx_up) - quantity(arx_down)) / (2.0 * step)
    return grad


def _standard_error(grad: np.ndarray | None, covariance: np.ndarray | None) -> float:
    if grad is None or covariance is None:
        return float("nan")
    return float(math.sqrt(max(float(grad @ covariance @ grad), 0.0)))


def check_identifiability(
    model: SteeringModel | ARXForm,
    covariance: np.ndarray | None = None,
    z: float = 3.0,
    min_gain: float = 1e-6,
    residual_std: float | None = None,
    lane_separation: float = 1.8,
) -> IdentifiabilityReport | None:
    """Is the lane offset identifiable through this model? (docs/design.md §5.7)

    The paper's "observable if any b_i or c_0 is non-zero" is not enough:
    b = (0.3, -0.3) is non-zero but carries no information on a constant
    lane-centre error. What matters is the static lane-offset gain
    G = sum(b)/near + sum(c)/far.

    Args:
        model: a steering model (its :meth:`arx` form is used) or an :class:`ARXForm`.
        covariance: covariance of the model's parameters; default: that of the
            model's fit, if any. With it, "clearly non-zero" means ``z``
            standard errors away from zero.
        z: how many standard errors "clearly non-zero" means.
        min_gain: smallest |G| (rad/m) accepted when no standard error is known.
        residual_std: the one-step residual std (rad) for ``lane_snr``;
            default: the model's fit's.
        lane_separation: distance (m) between the lane hypotheses for ``lane_snr``.

    Returns:
        An :class:`IdentifiabilityReport`, or None if the model is not an ARX model.
    """
    grad_gain = grad_memory = None
    if isinstance(model, ARXForm):
        arx = model
    else:
        arx = model.arx()
        if arx is None:
            return None
        if model.fit_result is not None:
            if covariance is None:
                covariance = model.fit_result.covariance
            if residual_std is None:
                residual_std = model.fit_result.residual_std
        if covariance is not None:
            grad_gain = _arx_gradient(model, lambda f: f.static_lane_gain)
            grad_memory = _arx_gradient(model, lambda f: 1.0 - sum(f.a))
    gain = arx.static_lane_gain
    se = _standard_error(grad_gain, covariance)
    memory = 1.0 - sum(arx.a)
    memory_se = _standard_error(grad_memory, covariance)
    integrating = abs(memory) < 1e-9 or (math.isfinite(memory_se) and abs(memory) <= z * memory_se)
    if integrating:
        steady = math.copysign(math.inf, -gain) if gain != 0 else float("nan")
    else:
        steady = -gain / memory
    snr = (
        abs(gain) * lane_separation / residual_std
        if residual_std is not None and residual_std > 0
        else float("nan")
    )
    identifiable = abs(gain) > z * se if math.isfinite(se) else abs(gain) > min_gain
    sign_consistent = gain > 0 if integrating else gain * memory > 0
    if not identifiable:
        detail = (
            f" (SE {se:.3g}, needs > {z:g} SE)"
            if math.isfinite(se)
            else f" (needs |G| > {min_gain:g})"
        )
        message = (
            f"static lane-offset gain sum(b)/near + sum(c)/far = {gain:.3g} rad/m is not clearly "
            f"non-zero{detail}: the steering carries no information on the lane offset"
        )
    elif not sign_consistent:
        message = (
            f"static lane-offset gain {gain:.3g} rad/m has the wrong sign for 1 - sum(a) = "
            f"{memory:.3g}: at steady state the model steers away from the lane centre"
        )
    else:
        parts = [f"identifiable: static lane-offset gain {gain:.3g} rad/m"]
        if math.isfinite(se) and se > 0:
            parts.append(f" ({abs(gain) / se:.1f} SE)")
        if integrating:
            parts.append(", integrating (1 - sum(a) ~ 0)")
        else:
            parts.append(f", steady-state steering {steady:.3g} rad/m")
        if math.isfinite(snr):
            parts.append(
                f"; lanes {lane_separation:g} m apart move a prediction by {snr:.2g} residual SDs"
            )
        message = "".join(parts)
    return IdentifiabilityReport(
        gain,
        se,
        memory,
        memory_se,
        integrating,
        steady,
        snr,
        identifiable,
        sign_consistent,
        message,
    )


# ------------------------------------------------------------------- fitting
@dataclass(frozen=True)
class FitResult:
    """A least-squares fit of a steering model.

    Attributes:
        parameter_names: names, in order.
        parameters: estimates.
        standard_errors: their standard errors.
        covariance: their covariance matrix.
        residuals: one-step residuals delta(k) - delta_hat(k) of every run (rad), concatenated.
        run_lengths: number of residuals from each run.
        n_obs: samples used; n_params: parameters fitted.
        rss: residual sum of squares (rad^2); residual_std: sqrt(rss / (n - p)) (rad).
        r2: R^2 on delta; r2_increments: R^2 on delta(k) - delta(k-1).
        log_likelihood: Gaussian log-likelihood at the ML variance rss/n.
        aic, bic: n log(rss/n) + 2p, n log(rss/n) + p log(n).
        identifiability: the check of :func:`check_identifiability` (None if not ARX).
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

    def summary(self) -> pd.DataFrame:
        """Estimates, standard errors and t-values, one row per parameter."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t = self.parameters / self.standard_errors
        return pd.DataFrame(
            {"estimate": self.parameters, "std_error": self.standard_errors, "t": t},
            index=pd.Index(self.parameter_names, name="parameter"),
        )


def _as_runs(runs: pd.DataFrame | Sequence[pd.DataFrame]) -> list[pd.DataFrame]:
    if isinstance(runs, pd.DataFrame):
        return [runs]
    out = list(runs)
    if not out:
        raise ValueError("no runs given")
    for i, run in enumerate(out):
        if not isinstance(run, pd.DataFrame):
            raise TypeError(f"run {i} is a {type(run).__name__}, expected a pandas DataFrame")
    return out


def _criteria(rss: float, n: int, p: int) -> tuple[float, float, float]:
    """(log-likelihood, AIC, BIC) of a Gaussian least-squares fit."""
    if rss <= 0:
        return math.inf, -math.inf, -math.inf
    log_likelihood = -0.5 * n * (math.log(2.0 * math.pi * rss / n) + 1.0)
    base = n * math.log(rss / n)
    return log_likelihood, base + 2.0 * p, base + p * math.log(n)


def _r2(residual_ss: float, values: np.ndarray) -> float:
    total = float(np.sum((values - values.mean()) ** 2)) if values.size else 0.0
    return 1.0 - residual_ss / total if total > 0 else float("nan")


def fit_model(
    model: SteeringModel,
    runs: pd.DataFrame | Sequence[pd.DataFrame],
    road: Road | None = None,
    warn: bool = True,
) -> SteeringModel:
    """Least-squares fit of a model that is linear in its parameters (``model.fit`` calls this).

    Args:
        model: the model (its structure; its current parameters are ignored).
        runs: one run or a list of runs (recordings or features frames).
        road: the road of the runs (None: from their metadata, else straight).
        warn: emit an :class:`IdentifiabilityWarning` when the fit loses the
            identifiability of the lane offset.

    Returns:
        A new model of the same class with the estimates, their standard
        errors and ``fit_result`` (:class:`FitResult`).
    """
    frames = _as_runs(runs)
    matrices, targets, deltas, increments, lengths = [], [], [], [], []
    for run in frames:
        features = model.features(run, road)
        design = model.design(features)
        previous = lagged(features["delta"].to_numpy(dtype=np.float64), 1)
        valid = design.valid
        matrices.append(design.matrix[valid])
        targets.append(design.target[valid] - design.offset[valid])
        deltas.append(design.target[valid])
        increments.append((design.target - previous)[valid])
        lengths.append(int(valid.sum()))
    X = np.vstack(matrices)
    y = np.concatenate(targets)
    names = model.parameter_names
    if X.shape[1] != len(names):
        raise ValueError(
            f"{model.name}: design has {X.shape[1]} columns for {len(names)} parameters"
        )
    solution = least_squares(X, y, names)
    n, p = X.shape
    log_likelihood, aic, bic = _criteria(solution.rss, n, p)
    increments_all = np.concatenate(increments)
    has_previous = np.isfinite(increments_all)
    residuals_with_previous = solution.residuals[has_previous]
    result = FitResult(
        parameter_names=names,
        parameters=solution.parameters,
        standard_errors=solution.standard_errors,
        covariance=solution.covariance,
        residuals=solution.residuals,
        run_lengths=tuple(lengths),
        n_obs=n,
        n_params=p,
        rss=solution.rss,
        residual_std=math.sqrt(solution.sigma2),
        r2=_r2(solution.rss, np.concatenate(deltas)),
        r2_increments=_r2(
            float(residuals_with_previous @ residuals_with_previous), increments_all[has_previous]
        ),
        log_likelihood=log_likelihood,
        aic=aic,
        bic=bic,
    )
    fitted = model.with_parameters(solution.parameters, solution.standard_errors, fit_result=result)
    report = check_identifiability(
        fitted, solution.covariance, residual_std=math.sqrt(solution.sigma2)
    )
    result = _replace(result, identifiability=report)
    fitted.fit_result = result
    if warn and report is not None and not report.ok:
        warnings.warn(f"{model.name} fit: {report.message}", IdentifiabilityWarning, stacklevel=3)
    return fitted


def _replace(result: FitResult, **changes: Any) -> FitResult:
    return replace(result, **changes)


# --------------------------------------------------------------- diagnostics
@dataclass(frozen=True)
class ResidualDiagnostics:
    """Whiteness of residuals.

    Attributes:
        autocorrelation: sample autocorrelation at lags 0..lags.
        confidence_band: 1.96 / sqrt(n), the 95 % band of white noise.
        fraction_outside: share of lags 1..lags outside the band (about 0.05 if white).
        ljung_box_statistic, ljung_box_p: Ljung-Box Q over lags 1..lags and its p-value
            (statsmodels ``acorr_ljungbox``); small p: not white.
        n: number of residuals.
    """

    autocorrelation: np.ndarray
    confidence_band: float
    fraction_outside: float
    ljung_box_statistic: float
    ljung_box_p: float
    n: int

    @property
    def white(self) -> bool:
        """Ljung-Box does not reject whiteness at the 5 % level."""
        return bool(self.ljung_box_p > 0.05)


def residual_diagnostics(
    residuals: np.ndarray | Sequence[np.ndarray], lags: int = 20
) -> ResidualDiagnostics:
    """Autocorrelation and Ljung-Box test of residuals (one array, or one per run).

    Several runs are concatenated (NaNs dropped); the few lag products that
    straddle two runs do not matter at thousands of samples per run.
    """
    if isinstance(residuals, np.ndarray) and residuals.ndim == 1:
        parts = [residuals]
    else:
        parts = [np.asarray(r, dtype=np.float64).reshape(-1) for r in residuals]
    e = np.concatenate([p[np.isfinite(p)] for p in parts]) if parts else np.zeros(0)
    n = e.size
    lags = int(min(lags, max(n // 5, 1)))
    if n < 10 or not np.any(e != e[0] if n else False):
        nan = float("nan")
        return ResidualDiagnostics(np.full(lags + 1, np.nan), nan, nan, nan, nan, n)
    r = acf(e, nlags=lags, fft=True)
    band = 1.96 / math.sqrt(n)
    outside = float(np.mean(np.abs(r[1:]) > band))
    lb = acorr_ljungbox(e, lags=[lags], return_df=True)
    return ResidualDiagnostics(
        np.asarray(r),
        band,
        outside,
        float(lb["lb_stat"].iloc[0]),
        float(lb["lb_pvalue"].iloc[0]),
        n,
    )


# ------------------------------------------------------------------ scoring
def simulate_arx(arx: ARXForm, features: pd.DataFrame, start: int) -> np.ndarray:
    """Free run of an ARX model over a features frame, from sample ``start`` on.

    ``delta_sim(k) = sum a_i delta_sim(k-i) + sum b_i phi(k-i) + ...`` with
    the measured bearings and lateral velocity and the measured steering before
    ``start``. Returns NaN before ``start``.
    """
    n = len(features)
    out = np.full(n, np.nan)
    if start >= n:
        return out
    zero_a = ARXForm(a=(), b=arx.b, c=arx.c, d=arx.d, near_distance=arx.near_distance,
                     far_distance=arx.far_distance, dt=arx.dt)  # fmt: skip
    exogenous = zero_a.predict(
        np.zeros(n),
        features["phi"].to_numpy(dtype=np.float64),
        features["omega"].to_numpy(dtype=np.float64),
        features["lateral_velocity"].to_numpy(dtype=np.float64),
    )
    delta = features["delta"].to_numpy(dtype=np.float64)
    u = exogenous[start:]
    if not np.all(np.isfinite(u)):
        bad = start + int(np.flatnonzero(~np.isfinite(u))[0])
        u = u[: bad - start]
    denominator = np.concatenate([[1.0], -np.asarray(arx.a, dtype=np.float64)])
    if len(arx.a):
        past = delta[max(0, start - len(arx.a)) : start][::-1]
        if past.size < len(arx.a):
            past = np.concatenate([past, np.zeros(len(arx.a) - past.size)])
        zi = signal.lfiltic([1.0], denominator, past)
        with np.errstate(over="ignore", invalid="ignore"):
            sim, _ = signal.lfilter([1.0], denominator, u, zi=zi)
    else:
        sim = u
    out[start : start + sim.size] = sim
    return out


def _metrics(
    delta: np.ndarray, estimate: np.ndarray, lags: int, free_run: bool
) -> dict[str, float]:
    """Scores of ``estimate`` against the measured ``delta``.

    Increments: a one-step prediction's is delta_hat(k) - delta(k-1) (so its
    increment error equals its error); a free run's is its own change
    delta_sim(k) - delta_sim(k-1), scored where it has a previous value.
    """
    previous = lagged(delta, 1)
    valid = np.isfinite(delta) & np.isfinite(estimate) & np.isfinite(previous)
    if free_run:
        valid &= np.isfinite(lagged(estimate, 1))
    n = int(valid.sum())
    if n < 3:
        nan = float("nan")
        return {"rmse": nan, "r2": nan, "r2_increments": nan, "ljung_box_p": nan, "n": n}
    if free_run and np.any(np.abs(estimate[valid]) > 1e6):
        # a free run of an unstable model: it diverged (road-wheel angles beyond any car)
        return {
            "rmse": math.inf,
            "r2": -math.inf,
            "r2_increments": -math.inf,
            "ljung_box_p": float("nan"),
            "n": n,
        }
    error = (delta - estimate)[valid]
    sse = float(error @ error)
    increments = (delta - previous)[valid]
    # increments of the estimate: one-step prediction minus the measured previous
    # steering, free run minus its own previous value (where it has one)
    reference = lagged(estimate, 1) if free_run else previous
    inc_error = increments - (estimate - reference)[valid]
    diag = residual_diagnostics(error, lags)
    return {
        "rmse": math.sqrt(sse / n),
        "r2": _r2(sse, delta[valid]),
        "r2_increments": _r2(float(inc_error @ inc_error), increments),
        "ljung_box_p": diag.ljung_box_p,
        "n": n,
    }


def score_runs(
    model: SteeringModel,
    runs: pd.DataFrame | Sequence[pd.DataFrame],
    road: Road | None = None,
    lags: int = 20,
    free_run: bool = True,
) -> pd.DataFrame:
    """Scores of a model on each run (one row per run), see :func:`score` for the columns."""
    rows = []
    for run in _as_runs(runs):
        features = model.features(run, road)
        delta = features["delta"].to_numpy(dtype=np.float64)
        one_step = model.predict_features(features)
        row = _metrics(delta, one_step, lags, free_run=False)
        if free_run:
            simulated = model.simulate(features)
            for key, value in _metrics(delta, simulated, lags, free_run=True).items():
                row[f"free_run_{key}"] = value
        rows.append(row)
    return pd.DataFrame(rows)


def score(
    model: SteeringModel,
    runs: pd.DataFrame | Sequence[pd.DataFrame],
    road: Road | None = None,
    lags: int = 20,
    free_run: bool = True,
) -> dict[str, float]:
    """Steering-prediction scores of a model, averaged over runs (paper table 1).

    One-step prediction (with the measured past steering):

    - ``rmse`` (rad);
    - ``r2``: R^2 on delta (about 0.99 for any sensible model);
    - ``r2_increments``: R^2 on delta(k) - delta(k-1), the skill over
      "steer as before" (where the paper's "R^2 Acc" pattern shows);
    - ``ljung_box_p``: Ljung-Box p-value of the residuals over ``lags`` lags.

    Free-run simulation (:meth:`~hasa_env.steering.base.SteeringModel.simulate`,
    driven by the measured bearings): the same four as ``free_run_*``.
    Also ``n_runs`` and ``n`` (samples scored in all). Each metric is the mean
    over runs of its per-run value (:func:`score_runs`).
    """
    table = score_runs(model, runs, road, lags, free_run)
    out = {key: float(table[key].mean()) for key in table.columns if key not in ("n", "free_run_n")}
    out["n_runs"] = len(table)
    out["n"] = int(table["n"].sum())
    return out
