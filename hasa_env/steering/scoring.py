"""Scoring steering models (paper table 1; docs/design.md §6.3-6.4).

- :func:`score` / :func:`score_runs` / :func:`score_features`: RMSE, R^2 on delta, R^2 on the
  increments delta(k) - delta(k-1) and the Ljung-Box p-value of the
  residuals, for one-step prediction (measured past steering) and free-run
  simulation; a free run that diverges is reported as such
  (``free_run_diverged``), never as an infinite RMSE.
- :func:`road_information`: the share of a road-blind baseline's one-step error
  that a model explains, ``1 - SSE_model / SSE_road_blind`` (docs/design.md §6.3).
- :func:`residual_diagnostics`: autocorrelation and Ljung-Box whiteness
  (statsmodels' statistics; :func:`ljung_box`) of residuals.
- :func:`simulate_arx`: free run of an ARX model over a run's bearings.

Runs are recordings (:data:`hasa_env.sim.setup.RECORDING_COLUMNS`) or features
frames (:func:`hasa_env.steering.features.steering_features`), one
``pandas.DataFrame`` per run; lags never cross from one run into another.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import signal, stats
from statsmodels.tsa.stattools import acf

from hasa_env.sim.road import Road
from hasa_env.steering.arx import ARXForm
from hasa_env.steering.design import SteeringModelLike as SteeringModel
from hasa_env.steering.design import as_runs, lagged, r_squared

__all__ = [
    "DIVERGENCE_LIMIT",
    "ResidualDiagnostics",
    "ljung_box",
    "residual_diagnostics",
    "road_information",
    "score",
    "score_features",
    "score_runs",
    "simulate_arx",
]

DIVERGENCE_LIMIT = 1e3
"""A free run whose steering exceeds this (rad, model units: far beyond any wheel)
has diverged."""


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
    e, lags, testable = _tested_residuals(residuals, lags)
    n = e.size
    if not testable:
        nan = float("nan")
        return ResidualDiagnostics(np.full(lags + 1, np.nan), nan, nan, nan, nan, n)
    r = acf(e, nlags=lags, fft=True)
    band = 1.96 / math.sqrt(n)
    outside = float(np.mean(np.abs(r[1:]) > band))
    statistic, p_value = ljung_box(e, lags)
    return ResidualDiagnostics(np.asarray(r), band, outside, statistic, p_value, n)


def _tested_residuals(
    residuals: np.ndarray | Sequence[np.ndarray], lags: int
) -> tuple[np.ndarray, int, bool]:
    """The residuals :func:`residual_diagnostics` tests (the runs' finite ones, concatenated),
    its lag count (at most a fifth of them) and whether they can be tested (at least 10 that
    are not all equal)."""
    if isinstance(residuals, np.ndarray) and residuals.ndim == 1:
        parts = [residuals]
    else:
        parts = [np.asarray(r, dtype=np.float64).reshape(-1) for r in residuals]
    e = np.concatenate([p[np.isfinite(p)] for p in parts]) if parts else np.zeros(0)
    n = e.size
    lags = int(min(lags, max(n // 5, 1)))
    return e, lags, not (n < 10 or not np.any(e != e[0] if n else False))


def _ljung_box_p(residuals: np.ndarray, lags: int) -> float:
    """``residual_diagnostics(residuals, lags).ljung_box_p`` without the autocorrelations it
    also computes (the scores use the p-value only)."""
    e, lags, testable = _tested_residuals(residuals, lags)
    return ljung_box(e, lags)[1] if testable else float("nan")


def ljung_box(residuals: np.ndarray, lags: int) -> tuple[float, float]:
    """The Ljung-Box statistic over ``lags`` lags of a 1-D series (no NaN) and its p-value:
    statsmodels' ``acorr_ljungbox(residuals, lags=[lags])`` to the bit, without its
    autocovariances at every lag up to n - 1 (``np.correlate`` of the whole series, O(n^2)):

        Q = n (n + 2) sum_{k=1..lags} r_k^2 / (n - k),   p = P(chi^2_lags > Q)

    with ``r_k = c_k / c_0``, ``c_k = sum_t x_{t+k} x_t / n`` of the demeaned series ``x``.
    Each ``c_k`` is the dot product ``np.correlate`` computes for lag k (the same numpy
    dot routine on the same slices, as statsmodels' own ``acovf`` does when given
    ``nlag``), and the rest is statsmodels' arithmetic in its order; a test compares the
    two on many series.
    """
    x = np.asarray(residuals, dtype=np.float64)
    n = x.shape[0]
    demeaned = x - x.mean()
    covariance = np.empty(lags + 1)
    covariance[0] = demeaned.dot(demeaned)
    for k in range(1, lags + 1):
        covariance[k] = demeaned[k:].dot(demeaned[: n - k])
    covariance = covariance / (n * np.ones(lags + 1))
    autocorrelation = covariance / covariance[0]
    lag = np.array([lags])
    terms = autocorrelation[1 : lags + 1] ** 2 / (n - np.arange(1, lags + 1))
    statistic = n * (n + 2) * np.cumsum(terms)[lag - 1]
    p_value = stats.chi2.sf(statistic, lag)
    return float(statistic[0]), float(p_value[0])


# ------------------------------------------------------------------ scoring
def road_information(
    residuals: np.ndarray, road_blind_residuals: np.ndarray, min_samples: int = 3
) -> float:
    """The share of the road-blind baseline's one-step steering error a model explains.

    ``1 - SSE_model / SSE_road_blind`` over the samples where both one-step residuals
    (measured minus predicted steering, rad, aligned with the run's rows) are finite: the
    out-of-sample R^2 of a forecast against a benchmark forecast (Campbell & Thompson
    2008), with :class:`~hasa_env.steering.models.RoadBlindModel` (an AR model of the
    steering alone) as the benchmark, so it measures what the road told the model
    (docs/design.md §6.3). 1: no error left; 0: no better than blind to the road;
    negative: worse. NaN with fewer than ``min_samples`` common samples or a baseline
    without error.
    """
    model = np.asarray(residuals, dtype=np.float64)
    blind = np.asarray(road_blind_residuals, dtype=np.float64)
    if model.shape != blind.shape:
        raise ValueError(
            f"the residuals have shape {model.shape}, the road-blind baseline's {blind.shape}: "
            "both must be aligned with the same run's rows"
        )
    common = np.isfinite(model) & np.isfinite(blind)
    if int(common.sum()) < min_samples:
        return float("nan")
    sse_blind = float(blind[common] @ blind[common])
    if not sse_blind > 0.0:
        return float("nan")
    return 1.0 - float(model[common] @ model[common]) / sse_blind


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
    delta_sim(k) - delta_sim(k-1), scored where it has a previous value. A
    free run that leaves [-DIVERGENCE_LIMIT, DIVERGENCE_LIMIT] (or overflows)
    has ``diverged`` = 1 and NaN scores: a finding, not a number to average.
    """
    nan = float("nan")
    previous = lagged(delta, 1)
    if free_run:
        finite = np.isfinite(estimate)
        first = int(np.argmax(finite)) if finite.any() else estimate.size
        running = estimate[first:]
        with np.errstate(invalid="ignore"):
            blown = ~np.isfinite(running) | (np.abs(running) > DIVERGENCE_LIMIT)
        if blown.any():
            return {"rmse": nan, "r2": nan, "r2_increments": nan, "ljung_box_p": nan,
                    "n": int(running.size), "diverged": 1.0}  # fmt: skip
    valid = np.isfinite(delta) & np.isfinite(estimate) & np.isfinite(previous)
    if free_run:
        valid &= np.isfinite(lagged(estimate, 1))
    n = int(valid.sum())
    if n < 3:
        return {"rmse": nan, "r2": nan, "r2_increments": nan, "ljung_box_p": nan, "n": n,
                "diverged": 0.0}  # fmt: skip
    error = (delta - estimate)[valid]
    sse = float(error @ error)
    increments = (delta - previous)[valid]
    # increments of the estimate: one-step prediction minus the measured previous
    # steering, free run minus its own previous value (where it has one)
    reference = lagged(estimate, 1) if free_run else previous
    inc_error = increments - (estimate - reference)[valid]
    return {
        "rmse": math.sqrt(sse / n),
        "r2": r_squared(sse, delta[valid]),
        "r2_increments": r_squared(float(inc_error @ inc_error), increments),
        "ljung_box_p": _ljung_box_p(error, lags),
        "n": n,
        "diverged": 0.0,
    }


def score_runs(
    model: SteeringModel,
    runs: pd.DataFrame | Sequence[pd.DataFrame],
    road: Road | None = None,
    lags: int = 20,
    free_run: bool = True,
) -> pd.DataFrame:
    """Scores of a model on each run (one row per run), see :func:`score` for the columns."""
    rows = [
        score_features(model, model.features(run, road), lags, free_run) for run in as_runs(runs)
    ]
    return pd.DataFrame(rows)


def score_features(
    model: SteeringModel,
    features: pd.DataFrame,
    lags: int = 20,
    free_run: bool = True,
    one_step: np.ndarray | None = None,
) -> dict[str, float]:
    """The scores of a model on one run's features (``model.features`` of the run): its row
    of :func:`score_runs`, as a dict. ``one_step``: the model's one-step predictions
    (``model.predict_features(features)``) when the caller has them already."""
    delta = features["delta"].to_numpy(dtype=np.float64)
    if one_step is None:
        one_step = model.predict_features(features)
    row = _metrics(delta, one_step, lags, free_run=False)
    del row["diverged"]
    if free_run:
        simulated = model.simulate(features)
        for key, value in _metrics(delta, simulated, lags, free_run=True).items():
            row[f"free_run_{key}"] = value
    return row


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
    driven by the measured bearings): the same four as ``free_run_*``, means
    over the runs whose free run stayed bounded, and ``free_run_diverged``: how
    many runs' free runs diverged. Also ``n_runs`` and ``n`` (samples scored in
    all). Each metric is the mean over runs of its per-run value (:func:`score_runs`).
    """
    table = score_runs(model, runs, road, lags, free_run)
    out: dict[str, float] = {}
    bounded = table["free_run_diverged"] == 0 if free_run else None
    for key in table.columns:
        if key in ("n", "free_run_n", "free_run_diverged"):
            continue
        column = (
            table[key]
            if bounded is None or not key.startswith("free_run_")
            else table.loc[bounded, key]
        )
        out[key] = float(column.mean()) if len(column) else float("nan")
    if free_run:
        out["free_run_diverged"] = int(table["free_run_diverged"].sum())
    out["n_runs"] = len(table)
    out["n"] = int(table["n"].sum())
    return out
