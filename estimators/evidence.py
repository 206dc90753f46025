"""How much the lane weights may move: the steering channel's consistency checks.

The mixture filter's weights multiply, sample after sample, the likelihoods
of each hypothesis' innovations (paper eq. 19). That product is only as good
as the steering model: when the model's equation error is larger than the
filter assumes, or autocorrelated (a model that misses part of the driver's
dynamics), the log-likelihood ratio between two hypotheses grows by tiny,
correlated increments that add up to a confident verdict even when the model
carries no lane information at all (measured before this rule: an
unidentifiable fit ended 5 of 18 runs below 0.01 on the true lane). This
module decides, per run and sample, how much of the steering evidence to
believe (docs/design.md §8.11).

Statistics (per run r and hypothesis i, over the samples where the steering
channel was used; ``u_i(k) = nu_i,3(k) / sqrt(S_i,33(k))`` is hypothesis i's
normalized steering innovation, ``alpha = Ts / evidence_window``)::

    n(k)     = (1 - alpha) n(k-1) + alpha                     weight of the data so far
    e_i(k)   = (1 - alpha) e_i(k-1) + alpha u_i(k)^2
    c_i(k)   = (1 - alpha) c_i(k-1) + alpha u_i(k) u_i(k-1)   (0 after a gap)
    lambda_i = e_i / n                                         model-error ratio (NIS; 1: consistent)
    rho_i    = c_i / e_i                                       lag-1 autocorrelation of u_i

The hypothesis that fits best, ``b = argmin_i lambda_i``, speaks for the
model: what even it cannot explain is model error, not lane evidence
(``lambda = lambda_b``, ``rho = rho_b``; one scale for all hypotheses of a
run, so the rule cannot favour the hypothesis that fits worse).

Tempered evidence (a quasi-likelihood: the log-likelihood increments are
divided by the factor by which their variance is understated: the model-error
ratio, and the variance inflation of a sum of AR(1)-correlated terms)::

    rho+    = clip(rho, 0, 0.98)
    tau     = max(1, lambda) (1 + rho+) / (1 - rho+)         evidence scale (>= 1)
    s(k)     = (1 - alpha)^2 s(k-1) + alpha^2
    N        = (n^2 / s) (1 - rho+) / (1 + rho+)               effective independent samples
    mismatch = lambda > mismatch_model_error * chi2_0.999(N) / N   (Wilson-Hilferty)

The mismatch test asks whether lambda exceeds the threshold by more than
chance allows with N effective samples: early in a run, or with strongly
autocorrelated innovations, a large lambda alone proves little (measured: a
good model's lambda exceeds 4 now and then in the first second, from the
filter's start-up transient).

    log w_i <- log w_i + l_i(k) / tau       (l_i: the update's log-likelihood)
    beta    = Ts / forgetting_time
    log w_i <- (1 - beta) log w_i + beta log pi_i               forgetting toward the prior pi
    log w_i <- max(log w_i - logsumexp_j log w_j, log weight_floor)  then normalized again

and on a mismatch the weights go back to the last *verified* weights, those
of the last step at which the model was checked (at least
``MIN_CHECKED_SAMPLES`` effective samples) and fitted (the prior before the
first check), and stay there while the mismatch lasts: evidence gathered
while the model fitted stays, evidence from a model that fits neither
hypothesis never enters, and a model that never fits leaves the weights at
the prior. No hypothesis is ever pruned by default (its filter keeps
running and its log weight stays finite), so any decision can be reversed
by later evidence. ``forgetting_time`` (off by default) makes the log-odds
decay toward the prior as ``exp(-t / forgetting_time)`` without fresh
evidence, and ``weight_floor`` (off by default) caps them at
``-ln(weight_floor)``; both make a reversal quicker, but both also let a
model whose fit degrades later in a run overturn the early, well-founded
decision (below).

Why no forgetting and no floor by default, and freezing rather than
returning to the prior: measured on the benchmark, a generalized model
fitted at constant speed fits the first seconds of a run (lambda about 1,
the lane decided at once) and then, as the car speeds up to 45 m/s, less and
less (lambda 8-17): its later evidence favours the wrong lane. With a
20 s forgetting time and a 1e-12 floor, 10 of 186 runs of two seeds ended
confidently in the wrong lane (5 of 8 on the curved track), against 1 (and
0) for the raw eq. 19; without them, 2 (and 0) (``hasa-bench paper --seeds
1,4 --stress --filter ...``; the issue notes have the table).

Decision state of a run (:data:`DECISIONS`)::

    "model_mismatch"  mismatch (above)
    "decided"         otherwise, when max_i w_i >= decision_threshold
    "undecided"       otherwise

With ``evidence_checks=False`` (:class:`~estimators.settings.FilterSettings`)
the weights follow paper eq. 19 untempered, without forgetting or floor (the
filter before this rule); the statistics and the decision state are still
reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimators.settings import FilterSettings

__all__ = [
    "DECIDED",
    "DECISIONS",
    "MODEL_MISMATCH",
    "UNDECIDED",
    "EvidenceRule",
    "decision_names",
    "initial_evidence_state",
    "weigh_evidence",
]

DECISIONS = ("undecided", "decided", "model_mismatch")
"""Decision states by code: 0 undecided, 1 decided, 2 model_mismatch."""
UNDECIDED, DECIDED, MODEL_MISMATCH = 0, 1, 2

MAX_AUTOCORRELATION = 0.98
"""rho+ is clipped here: the evidence scale stays finite (at most 99 lambda)."""

MISMATCH_QUANTILE_Z = 3.09
"""Standard-normal quantile of the mismatch test (0.999: one false alarm in a thousand tests
of a model whose lambda is at the threshold)."""

MIN_CHECKED_SAMPLES = 2.0
"""Effective samples lambda needs before weights count as verified."""


def chi2_upper_ratio(samples: np.ndarray) -> np.ndarray:
    """``chi2_0.999(nu) / nu`` for ``nu`` effective samples (Wilson-Hilferty; inf for nu <= 0):
    how far above its true value a mean of nu squared standard normals may lie by chance."""
    nu = np.maximum(np.asarray(samples, dtype=np.float64), 1e-12)
    h = 2.0 / (9.0 * nu)
    ratio = (1.0 - h + MISMATCH_QUANTILE_Z * np.sqrt(h)) ** 3
    return np.where(np.asarray(samples) > 0, ratio, np.inf)


EVIDENCE_STATE = (
    "_evidence_weight",
    "_evidence_weight_sq",
    "_nis",
    "_lag_product",
    "_last_score",
    "_log_prior",
    "_verified_log_w",
)
"""The per-run arrays of the rule (kept by the filter with its other per-run state)."""


@dataclass(frozen=True)
class EvidenceRule:
    """The rule's constants for one sample time (built from :class:`FilterSettings`)."""

    enabled: bool
    alpha: float
    forgetting: float
    mismatch_model_error: float
    decision_threshold: float
    log_floor: float

    @classmethod
    def from_settings(cls, settings: FilterSettings, dt: float) -> EvidenceRule:
        """The rule of ``settings`` at sample time ``dt`` (s)."""
        return cls(
            enabled=settings.evidence_checks,
            alpha=min(1.0, dt / settings.evidence_window),
            forgetting=min(1.0, dt / settings.forgetting_time),
            mismatch_model_error=settings.mismatch_model_error,
            decision_threshold=settings.decision_threshold,
            log_floor=math.log(settings.weight_floor) if settings.weight_floor > 0 else -math.inf,
        )


def initial_evidence_state(log_prior: np.ndarray) -> dict[str, np.ndarray]:
    """The rule's per-run arrays at reset, for the prior ``log_prior`` (R, C)."""
    n_runs, n_comp = log_prior.shape
    return {
        "_evidence_weight": np.zeros(n_runs),
        "_evidence_weight_sq": np.zeros(n_runs),
        "_nis": np.zeros((n_runs, n_comp)),
        "_lag_product": np.zeros((n_runs, n_comp)),
        "_last_score": np.full((n_runs, n_comp), np.nan),
        "_log_prior": log_prior.copy(),
        "_verified_log_w": log_prior.copy(),
    }


def statistics(state: dict[str, np.ndarray], active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lambda, rho) of each run's best-fitting active hypothesis, (R,) each (NaN: no data yet)."""
    weight = state["_evidence_weight"]
    nis = state["_nis"]
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = nis / weight[:, None]
        ratio = np.where(active, ratio, np.nan)
        has = weight > 0
        best = np.argmin(np.where(np.isnan(ratio), np.inf, ratio), axis=1)
        rows = np.arange(nis.shape[0])
        model_error = np.where(has, ratio[rows, best], np.nan)
        rho = state["_lag_product"][rows, best] / nis[rows, best]
        autocorrelation = np.where(has & (nis[rows, best] > 0), rho, np.nan)
    return model_error, autocorrelation


def weigh_evidence(
    rule: EvidenceRule,
    log_w: np.ndarray,
    log_lik: np.ndarray,
    score: np.ndarray,
    state: dict[str, np.ndarray],
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """One sample of the rule (module docstring).

    Args:
        rule: the constants.
        log_w: (R, C) log weights before the update (-inf: zero weight).
        log_lik: (R, C) the update's log-likelihoods.
        score: (R, C) normalized steering innovations u_i (NaN where the
            steering channel was not used: missing, gated, low speed, no model).
        state: the per-run arrays (:data:`EVIDENCE_STATE`).

    Returns:
        The new log weights (R, C) (normalized, unnormalizable runs keep
        ``log_w``), the new per-run arrays, and the per-run statistics
        ``decision`` (int codes), ``model_error`` (lambda),
        ``autocorrelation`` (rho) and ``evidence_scale`` (tau).
    """
    alpha = rule.alpha
    keep = 1.0 - alpha
    active = np.isfinite(log_w)  # pruned (or zero-prior) hypotheses do not count
    # the steering channel was used in this run (missing, gated and low-speed steps: NaN)
    used = ~np.isnan(np.where(active, score, 0.0)).any(axis=1) & active.any(axis=1)
    weight, weight_sq = state["_evidence_weight"], state["_evidence_weight_sq"]
    nis, lag = state["_nis"], state["_lag_product"]
    last = state["_last_score"]
    if used.any():
        # a normalized innovation beyond 1e3 is as inconsistent as it gets (no overflow)
        u = np.clip(np.where(used[:, None] & active, score, 0.0), -1e3, 1e3)
        rows = used[:, None] & active
        weight = np.where(used, keep * weight + alpha, weight)
        weight_sq = np.where(used, keep * keep * weight_sq + alpha * alpha, weight_sq)
        nis = np.where(rows, keep * nis + alpha * u * u, nis)
        previous = np.where(np.isnan(last), 0.0, last)
        lag = np.where(rows, keep * lag + alpha * u * previous, lag)
        new_last = np.where(rows, u, np.nan)
    else:
        new_last = np.full_like(last, np.nan)
    new_state = dict(state)
    new_state.update(
        {
            "_evidence_weight": weight,
            "_evidence_weight_sq": weight_sq,
            "_nis": nis,
            "_lag_product": lag,
            "_last_score": new_last,
        }
    )
    model_error, rho = statistics(new_state, active)
    rho_plus = np.clip(np.nan_to_num(rho, nan=0.0), 0.0, MAX_AUTOCORRELATION)
    with np.errstate(invalid="ignore", divide="ignore"):
        # effective number of independent squared innovations behind lambda
        samples = np.where(weight_sq > 0, weight * weight / weight_sq, 0.0)
        samples = samples * (1.0 - rho_plus) / (1.0 + rho_plus)
        mismatch = model_error > rule.mismatch_model_error * chi2_upper_ratio(samples)
    checked = ~mismatch & (samples >= MIN_CHECKED_SAMPLES)
    scale = np.maximum(1.0, np.nan_to_num(model_error, nan=1.0)) * (1.0 + rho_plus)
    scale /= 1.0 - rho_plus
    if rule.enabled:
        increment = np.where(mismatch[:, None], 0.0, log_lik / scale[:, None])
        new_log_w = log_w + increment
        beta = np.where(mismatch, 0.0, rule.forgetting)[:, None]
        if rule.forgetting > 0:
            with np.errstate(invalid="ignore"):
                forgotten = (1.0 - beta) * new_log_w + beta * state["_log_prior"]
            new_log_w = np.where(active, forgotten, -np.inf)
        new_log_w = normalize_log_weights(new_log_w, log_w)
        if math.isfinite(rule.log_floor):
            floored = np.where(active, np.maximum(new_log_w, rule.log_floor), -np.inf)
            new_log_w = normalize_log_weights(floored, new_log_w)
        verified = state["_verified_log_w"]
        if mismatch.any():
            new_log_w = np.where(mismatch[:, None], verified, new_log_w)
        if checked.any():
            new_state["_verified_log_w"] = np.where(checked[:, None], new_log_w, verified)
    else:
        new_log_w = normalize_log_weights(np.where(active, log_w + log_lik, -np.inf), log_w)
    decided = new_log_w.max(axis=1) >= math.log(rule.decision_threshold)
    decision = np.where(mismatch, MODEL_MISMATCH, np.where(decided, DECIDED, UNDECIDED))
    stats = {
        "decision": decision,
        "model_error": model_error,
        "autocorrelation": rho,
        "evidence_scale": scale,
    }
    return new_log_w, new_state, stats


def normalize_log_weights(log_w: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """``log_w - logsumexp(log_w)`` per run; a run whose weights all vanished keeps ``fallback``."""
    total = np.logaddexp.reduce(log_w, axis=1, keepdims=True)  # logsumexp, stable
    if math.isfinite(total.sum()):
        return log_w - total
    ok = np.isfinite(total)
    with np.errstate(invalid="ignore"):
        return np.where(ok, log_w - np.where(ok, total, 0.0), fallback)


def decision_names(codes: np.ndarray | int) -> np.ndarray | str:
    """The names of decision codes (:data:`DECISIONS`): a str for a scalar code."""
    codes = np.asarray(codes)
    names = np.asarray(DECISIONS)[codes]
    return str(names) if names.ndim == 0 else names
