"""How much the lane weights may move: the steering channel's consistency checks.

Why this module is long: the docstring states the rule's equations and the traced failure
behind each constant, and the rule has a batched path and a single-run path in Python floats
(the single car's speed) that a test keeps equal; they belong beside each other.

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
of the last step at which the data showed the model consistent (the prior
before the first such step), and stay there while the mismatch lasts::

    verified = N >= VERIFY_MIN_SAMPLES (10)  and  lambda_up <= mismatch_model_error
    lambda_up = lambda / (1 - h - z sqrt(h))^3,  h = 2 / (9 N),  z = 1.645  (95 % bound)

Evidence gathered while the model was shown to fit stays, evidence from a
model that fits neither hypothesis never enters, and a model that is never
shown to fit leaves the weights at the prior. "Shown to fit" is a bound, not
the absence of a mismatch: with a few samples the mismatch test cannot
reject anything, and weights that moved then are not verified by it
(found by tracing a run whose model mismatched its driver, lambda about 25:
two steering innovations 0.04-0.05 s into the run, while lambda rested on
four near-zero start-up innovations, moved the weights to 0.97 on the wrong
lane; the mismatch test fired at 1 s and froze them there, so the run ended
confidently wrong as ``model_mismatch``; docs/design.md §8.16).

No hypothesis is ever pruned by default (its filter keeps running and its
log weight stays finite), so any decision can be reversed
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

Reversal rule (issue 24, the scenario suite): the hypotheses are constant within a run, so
weights that pass the decision threshold on hypothesis i and later on another hypothesis j mean
that the evidence of one of the two periods was wrong, and nothing tells which. The run's
weights then go back to the prior and stay there for the rest of the run, reported as
``model_mismatch``: an estimator that cannot tell says so. A decision commits only once it has
held for ``commit_time`` (1 s) at steps whose evidence was checked (at least
``MIN_CHECKED_SAMPLES`` effective samples, no mismatch), so a start-up flip-flop can still
reverse itself (measured: a fitted model on a stop-and-go drive decided right after 0.2 s,
wrong 0.2 s later, then right for good); a prior that is itself past the
threshold is the user's belief, not evidence: for such a run the rule is off. Found by tracing the ``lane_shift``
and ``lane_change`` scenarios (docs/design.md §14.6), where the driver leaves the marked lane's
centre on purpose and every steering model reads that as evidence for the other lane; its cost
is the runs that were confidently wrong first and right later, which now end undecided.

Aim cap (``aim_offset_std`` sigma_a > 0; docs/design.md §8.19): on a straight road a driver
who aims p off the centre of lane i steers exactly as one who aims p + d off the centre of a
lane d away, so with the aim unknown the steering tells lanes apart only as far as a prior on
where people hold the car does. The filter keeps, per run and hypothesis, the car's lateral
offset from that hypothesis' centre averaged over ``aim_offset_time`` (a_i; 10 s, §8.23), and
after the tempering, before the decision and the reversal rule, no run's log-odds grow past
that prior's::

    A_i = -a_i^2 / (2 sigma_a^2),   b = argmax_i log w_i
    d_i = (log w_b - log pi_b) - (log w_i - log pi_i)
    d_i(k) <= max(|A_b - A_i|, d_i(k-1))                     then normalized

Log-odds gathered under a larger bound are kept (the hypotheses are constant within a run);
the cap never adds evidence and never turns it around (:func:`aim_capped_log_weights`).

Path rule (``aim_offset_limit`` z_a, default 4; docs/design.md §8.24): the filter also keeps
the largest |a_i| each hypothesis' average reached while the car was held near *some*
hypothesis' centre (``_aim_reach``; within half the limit: a car put far from every centre at
the start, and driven back, has not followed a path). A run in which every hypothesis' reach
has passed ``z_a sigma_a`` (1.2 m by default) is refused as under the reversal rule below, for
the rest of the run::

    reach_i(k) = max(reach_i(k-1), |a_i(k)|)  if min_j |a_j(k)| <= z_a sigma_a / 2,  reach_i(0) = 0
    reach_i(k) >= z_a sigma_a  for every i   ->   weights = prior, "model_mismatch"

The driver then held the car, for many seconds, where the aim prior puts no driver under any
hypothesis (a lane shift or a lane change followed on purpose): every lane-keeping steering
model reads that as evidence for the lane the car now sits in, whichever it is. Found on the
two-point model's wrong endings in ``lane_shift`` (it decided for the lane the car had been
moved into, with no earlier decision for the reversal rule to contradict).

Decision state of a run (:data:`DECISIONS`)::

    "model_mismatch"  mismatch (above), a decision reversed (the reversal rule) or the
                      car held off every centre (the path rule)
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
from functools import cached_property
from statistics import NormalDist

import numpy as np

from estimators.settings import FilterSettings
from estimators.small_arrays import all_finite, all_true, any_true

__all__ = [
    "DECIDED",
    "DECISIONS",
    "MODEL_MISMATCH",
    "UNDECIDED",
    "EvidenceRule",
    "decision_names",
    "initial_evidence_state",
    "refusal_reasons",
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

NOT_COMMITTED, CONTRADICTED = -1.0, -2.0
"""Codes of ``_committed`` besides a hypothesis index: no decision yet; a decision reversed."""

REFUSALS = ("", "reversal rule", "path rule")
"""What sent a run back to its prior for good, by the code kept in ``_refused_by`` (R,): 0
nothing, 1 the reversal rule (a decision contradicted), 2 the path rule (the car left every
hypothesis' centre; when both fire at one step, the path rule). A run in ``model_mismatch``
with code 0 is held by the mismatch test, which ends when the model fits again."""
REVERSAL_RULE, PATH_RULE = 1.0, 2.0

MIN_CHECKED_SAMPLES = 2.0
"""Effective samples lambda needs before a step counts as checked (the reversal rule's commit)."""

VERIFY_MIN_SAMPLES = 10.0
"""Effective samples lambda needs before the verification below is tried: with fewer the
Wilson-Hilferty bound is unreliable, and the first innovations after a (re)start are near zero
by construction (the memory starts from the measured steering), so they show nothing."""

VERIFY_QUANTILE_Z = 1.645
"""Standard-normal quantile of the verification: weights count as verified only where the
95 % upper confidence bound on lambda lies at or below ``mismatch_model_error`` (the data
show the model consistent, not merely not yet inconsistent; the mismatch test's 0.999 is the
other side's level, where a false alarm costs a refusal)."""


MAX_EVIDENCE_SCALE = 1e12
"""tau is capped here (an upper bound on lambda from almost no data is unbounded)."""


def model_error_bound(model_error: np.ndarray, samples: np.ndarray, z: float) -> np.ndarray:
    """The one-sided upper confidence bound on the model-error ratio lambda from ``samples``
    effective squared innovations (Wilson-Hilferty; ``z`` the standard-normal quantile of the
    confidence; ``z = 0``: lambda itself)::

        h = 2 / (9 N),  r = (1 - h - z sqrt(h))^3,  lambda_up = lambda / r   (r <= 0: infinite)

    A mean of N squared innovations whose true variance ratio is lambda_up falls below the
    observed lambda with probability 1 - confidence: the largest model error the data so far
    cannot rule out."""
    if z == 0:
        return model_error
    with np.errstate(divide="ignore", invalid="ignore"):
        h = 2.0 / (9.0 * np.asarray(samples, dtype=np.float64))
        root = 1.0 - h - z * np.sqrt(h)
        ratio = np.where(root > 0, root * root * root, 0.0)
        bound = np.where(ratio > 0, model_error / ratio, np.inf)
    return np.where(np.isnan(model_error), np.nan, bound)  # no data: no bound either


def verified_steps(rule: EvidenceRule, model_error: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """(R,) bool: runs whose model the data so far show consistent (module docstring)::

        N >= VERIFY_MIN_SAMPLES  and  lambda_up(N, z = 1.645) <= mismatch_model_error

    (``lambda_up``: :func:`model_error_bound`; NaN lambda, no data: not verified).

    The bound is :func:`model_error_bound`'s arithmetic without its guards, which runs with
    enough samples never need (there ``1 - h - z sqrt(h) > 0.7``); the others, not verified
    whatever their bound, take N = ``VERIFY_MIN_SAMPLES`` in it (no division by zero), and
    none is computed before any run has enough (a run's first samples: the filter's step)."""
    enough = samples >= VERIFY_MIN_SAMPLES
    if not any_true(enough):
        return enough
    h = 2.0 / (9.0 * np.maximum(samples, VERIFY_MIN_SAMPLES))
    root = 1.0 - h - VERIFY_QUANTILE_Z * np.sqrt(h)
    return enough & (model_error / (root * root * root) <= rule.mismatch_model_error)


def _bound_one(model_error: float, samples: float, z: float) -> float:
    """:func:`model_error_bound` for one run, in floats (the same arithmetic; samples > 0)."""
    h = 2.0 / (9.0 * samples)
    root = 1.0 - h - z * math.sqrt(h)
    return model_error / (root * root * root) if root > 0 else math.inf


def _verified_one(rule: EvidenceRule, model_error: float, samples: float) -> bool:
    """:func:`verified_steps` for one run, in floats (the same arithmetic)."""
    if math.isnan(model_error) or samples < VERIFY_MIN_SAMPLES:
        return False
    return _bound_one(model_error, samples, VERIFY_QUANTILE_Z) <= rule.mismatch_model_error


def chi2_upper_ratio(samples: np.ndarray) -> np.ndarray:
    """``chi2_0.999(nu) / nu`` for ``nu`` effective samples (Wilson-Hilferty; NaN for nu = 0,
    so that no test passes without data):
    how far above its true value a mean of nu squared standard normals may lie by chance."""
    h = 2.0 / (9.0 * np.asarray(samples, dtype=np.float64))  # inf for nu = 0
    ratio = 1.0 - h + MISMATCH_QUANTILE_Z * np.sqrt(h)
    return ratio * ratio * ratio


EVIDENCE_STATE = (
    "_evidence_weight",
    "_evidence_weight_sq",
    "_nis",
    "_lag_product",
    "_last_score",
    "_log_prior",
    "_verified_log_w",
    "_committed",
    "_candidate",
    "_withheld",
    "_refused_by",
)
"""The per-run arrays of the rule (kept by the filter with its other per-run state).
``_withheld`` (R,): the hypothesis index of the decision the reversal rule withheld (the
confident decision that contradicted the committed one and sent the run back to its prior),
``NOT_COMMITTED`` (-1) while there is none. ``_refused_by`` (R,): the code of :data:`REFUSALS`."""


@dataclass(frozen=True)
class EvidenceRule:
    """The rule's constants for one sample time (built from :class:`FilterSettings`)."""

    enabled: bool
    alpha: float
    forgetting: float
    mismatch_model_error: float
    decision_threshold: float
    log_floor: float
    commit_steps: float = math.inf
    bound_z: float = 0.0
    aim_variance: float = 0.0
    aim_limit: float = math.inf

    @cached_property
    def log_decision_threshold(self) -> float:
        return math.log(self.decision_threshold)

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
            commit_steps=max(1.0, round(settings.commit_time / dt))
            if math.isfinite(settings.commit_time)
            else math.inf,
            bound_z=_normal_quantile(settings.evidence_confidence),
            aim_variance=settings.aim_offset_std**2,
            aim_limit=settings.aim_offset_limit * settings.aim_offset_std
            if settings.aim_offset_std > 0
            else math.inf,
        )

    @cached_property
    def aim_near(self) -> float:
        """How near (m) some hypothesis' centre the car must be held for the path rule to
        count the averages' reach: half its limit."""
        return 0.5 * self.aim_limit

    @cached_property
    def holds(self) -> bool:
        """Whether the reversal rule or the path rule can change a run's weights."""
        return self.enabled and (math.isfinite(self.commit_steps) or math.isfinite(self.aim_limit))


def _normal_quantile(probability: float) -> float:
    """The standard-normal quantile of ``probability`` (0 for 0.5 or less: no bound)."""
    if probability <= 0.5:
        return 0.0
    return NormalDist().inv_cdf(probability)


def initial_evidence_state(log_prior: np.ndarray) -> dict[str, np.ndarray]:
    """The rule's per-run arrays at reset, for the prior ``log_prior`` (R, C)."""
    n_runs, n_comp = log_prior.shape
    return {
        "_evidence_weight": np.zeros(n_runs),
        "_evidence_weight_sq": np.zeros(n_runs),
        "_nis": np.zeros((n_runs, n_comp)),
        "_lag_product": np.zeros((n_runs, n_comp)),
        "_last_score": np.zeros((n_runs, n_comp)),  # 0: no previous innovation
        "_log_prior": log_prior.copy(),
        "_verified_log_w": log_prior.copy(),
        "_committed": np.full(n_runs, NOT_COMMITTED),
        "_candidate": np.zeros((n_runs, 2)),
        "_withheld": np.full(n_runs, NOT_COMMITTED),
        "_refused_by": np.zeros(n_runs),
    }


def statistics(state: dict[str, np.ndarray], active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lambda, rho) of each run's best-fitting active hypothesis, (R,) each (NaN: no data yet)."""
    weight = state["_evidence_weight"]
    nis = state["_nis"]
    with np.errstate(invalid="ignore", divide="ignore"):
        masked = nis if active.all() else np.where(active, nis, np.inf)
        best = np.argmin(masked, axis=1)
        rows = np.arange(nis.shape[0])
        best_nis = nis[rows, best]
        model_error = best_nis / weight  # NaN (0 / 0) before any data
        rho = state["_lag_product"][rows, best] / best_nis
    return model_error, rho


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
    if log_w.shape[0] == 1 and rule.enabled and rule.forgetting == 0:
        return _weigh_evidence_one(rule, log_w, log_lik, score, state)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        new_log_w, new_state, stats = _weigh(rule, log_w, log_lik, score, state)
    if rule.enabled and rule.aim_variance > 0 and AIM_OFFSET in state:
        new_log_w = _aim_capped(rule, new_log_w, log_w, new_state, stats)
    _store_verified(new_log_w, new_state, stats.pop("verified"))
    if rule.holds:
        new_log_w = _hold_first_decision(rule, new_log_w, new_state, stats)
    stats.pop("checked", None)
    return new_log_w, new_state, stats


def aim_offset_rate(settings: FilterSettings, dt: float, has_steering: bool) -> float:
    """The aim cap's averaging rate Ts / ``aim_offset_time`` per sample of ``dt`` (s); 0 when
    the cap is off (``aim_offset_std`` 0, or no steering model: it bounds steering evidence)."""
    if not has_steering or settings.aim_offset_std <= 0:
        return 0.0
    return min(1.0, dt / settings.aim_offset_time)


AIM_OFFSET = "_aim_offset"
"""The key of the per-run (R, C) average lateral offset a_i of each hypothesis in the rule's
state (kept by the filter when ``aim_offset_std`` > 0; :func:`_aim_capped`)."""

AIM_REACH = "_aim_reach"
"""The key of the per-run (R, C) largest |a_i| at the steps the car was held near some
hypothesis' centre (kept with :data:`AIM_OFFSET`; the path rule, :func:`path_left`)."""


def moved_aim_offsets(
    state: dict[str, np.ndarray], lateral: np.ndarray, rate: float, near: float
) -> dict[str, np.ndarray]:
    """A copy of the rule's per-run arrays ``state`` with the aim cap's averages moved toward
    the posterior lateral offsets ``lateral`` (R * C,) and their reach updated::

        a_i <- a_i + rate (y_i - a_i)
        reach_i <- max(reach_i, |a_i|)   where min_j |a_j| <= near (held near some centre)

    ``rate`` = Ts / ``aim_offset_time`` (:func:`aim_offset_rate`); ``near`` (m):
    :attr:`EvidenceRule.aim_near`."""
    aim = state[AIM_OFFSET]
    moved = dict(state)
    if aim.shape[0] == 1:  # one run: in Python floats (the same operations)
        new, sizes = [], []
        for a, y in zip(aim[0].tolist(), lateral.tolist(), strict=True):
            a += rate * (y - a)
            new.append(a)
            sizes.append(abs(a))
        moved[AIM_OFFSET] = np.array(new, ndmin=2)
        if min(sizes) <= near:
            old = state[AIM_REACH][0].tolist()
            moved[AIM_REACH] = np.array(
                [r if r >= a else a for r, a in zip(old, sizes, strict=True)], ndmin=2
            )
        return moved
    new_aim = aim + rate * (lateral.reshape(aim.shape) - aim)
    moved[AIM_OFFSET] = new_aim
    size = np.abs(new_aim)
    held = size.min(axis=1) <= near
    if any_true(held):
        reach = np.maximum(state[AIM_REACH], size)
        if not all_true(held):
            reach = np.where(held[:, None], reach, state[AIM_REACH])
        moved[AIM_REACH] = reach
    return moved


def initial_aim_offsets(lateral: np.ndarray) -> dict[str, np.ndarray]:
    """The aim cap's per-run arrays at reset from the prior lateral offsets ``lateral``
    (R, C): the averages start there, with no reach yet."""
    aim = np.array(lateral, dtype=np.float64, copy=True)
    return {AIM_OFFSET: aim, AIM_REACH: np.zeros_like(aim)}


def path_left(rule: EvidenceRule, state: dict[str, np.ndarray]) -> np.ndarray | None:
    """(R,) True for the runs the path rule (module docstring) refuses at this step: every
    hypothesis' average offset has reached ``aim_limit`` and the prior is not itself decided
    (a decided prior is the user's belief: the rule is off, as the reversal rule). None when
    no run is refused (or the rule is off)."""
    reach = state.get(AIM_REACH)
    if reach is None or not math.isfinite(rule.aim_limit):
        return None
    if reach.shape[0] == 1:  # one run: in Python floats
        if min(reach[0].tolist()) < rule.aim_limit:
            return None
        if max(state["_log_prior"][0].tolist()) >= rule.log_decision_threshold:
            return None
        return np.array([True])
    left = reach.min(axis=1) >= rule.aim_limit
    if not any_true(left):
        return None
    left &= state["_log_prior"].max(axis=1) < rule.log_decision_threshold
    return left if any_true(left) else None


def aim_capped_log_weights(
    log_w: np.ndarray,
    log_prior: np.ndarray,
    aim_offset: np.ndarray,
    aim_variance: float,
    previous: np.ndarray | None = None,
) -> np.ndarray:
    """The aim cap (module docstring) of log weights ``log_w`` (R, C) with prior ``log_prior``
    and average offsets ``aim_offset`` (R, C, m): the log-odds of the run's most likely
    hypothesis b over each other one, against the prior's, held to what the aim prior allows
    or, with the weights of the step before (``previous``), to what they already were::

        A_i = -a_i^2 / (2 sigma_a^2)
        d_i = (log w_b - log pi_b) - (log w_i - log pi_i)
        d_i <= max(|A_b - A_i|, d_i(previous)),  then normalized

    Zero weights (pruned) stay zero."""
    score = aim_offset * aim_offset * (-0.5 / aim_variance)
    rows = np.arange(log_w.shape[0])
    best = np.argmax(log_w, axis=1)
    with np.errstate(invalid="ignore"):
        bound = np.abs(score[rows, best][:, None] - score)
        if previous is not None:
            odds = (previous[rows, best] - log_prior[rows, best])[:, None] - (previous - log_prior)
            bound = np.maximum(bound, np.where(np.isfinite(odds), odds, 0.0))
        floor = (log_w[rows, best] - log_prior[rows, best])[:, None] + log_prior - bound
        capped = np.where(np.isfinite(log_w), np.maximum(log_w, floor), -np.inf)
    return normalize_log_weights(capped, log_w)


def _aim_capped_one(
    log_w: np.ndarray,
    log_prior: np.ndarray,
    aim_offset: np.ndarray,
    aim_variance: float,
    previous: np.ndarray,
) -> np.ndarray:
    """:func:`aim_capped_log_weights` of one run (1, C) in Python floats: the same IEEE
    operations in the same order, so the same bits (a test compares them)."""
    capped, fallback = _aim_capped_list(
        log_w[0].tolist(), log_w, log_prior, aim_offset, aim_variance, previous
    )  # (log_w: the fallback's)
    return np.array([capped]) if fallback is None else fallback


def _aim_capped_list(
    lw: list[float],
    log_w: np.ndarray | None,
    log_prior: np.ndarray,
    aim_offset: np.ndarray,
    aim_variance: float,
    previous: np.ndarray,
) -> tuple[list[float], np.ndarray | None]:
    """:func:`_aim_capped_one` of the weights ``lw`` (``log_w[0]`` as a list; ``log_w`` None:
    not built yet) as a list, and as an array when the normalization fell back to numpy's
    (None: it did not)."""
    (prior,) = log_prior.tolist()
    (prev,) = previous.tolist()
    (aim,) = aim_offset.tolist()
    factor = -0.5 / aim_variance
    best = lw.index(max(lw))
    base, previous_base = lw[best] - prior[best], prev[best] - prior[best]
    best_score = aim[best] * aim[best] * factor
    capped = []
    for w, p, v, a in zip(lw, prior, prev, aim, strict=True):
        s = a * a * factor
        if not math.isfinite(w):
            capped.append(-math.inf)
            continue
        bound = abs(best_score - s)
        odds = previous_base - (v - p)
        if not math.isfinite(odds):
            odds = 0.0
        bound = bound if bound >= odds or bound != bound else odds
        floor = base + p - bound
        capped.append(w if w >= floor else floor)
    normalized = _normalized_one(capped)
    if normalized:
        return normalized, None
    fallback = normalize_log_weights(np.array([capped]), np.array([lw]) if log_w is None else log_w)
    return fallback[0].tolist(), fallback


def _weigh_evidence_one(
    rule: EvidenceRule,
    log_w: np.ndarray,
    log_lik: np.ndarray,
    score: np.ndarray,
    state: dict[str, np.ndarray],
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """:func:`weigh_evidence` of one run with the rule enabled and no forgetting, in Python
    floats: :func:`_rule_one`, :func:`_aim_capped_one`, :func:`_store_verified` and
    :func:`_hold_first_decision`'s arithmetic in the same order, each array built once."""
    lw, new_log_w, new_state, run = _rule_one(rule, log_w, log_lik, score, state)
    decision, model_error, rho, scale, checked, verified = run
    if rule.aim_variance > 0 and AIM_OFFSET in state:
        lw, new_log_w = _aim_capped_list(
            lw, new_log_w, state["_log_prior"], state[AIM_OFFSET], rule.aim_variance, log_w
        )
        if decision != MODEL_MISMATCH:
            decision = DECIDED if max(lw) >= rule.log_decision_threshold else UNDECIDED
    if new_log_w is None:
        new_log_w = np.array(lw, ndmin=2)
    if verified:
        new_state["_verified_log_w"] = new_log_w
    if rule.holds:
        new_log_w, decision = _hold_one(rule, lw, new_log_w, new_state, decision, checked)
    stats = {
        "decision": np.array([decision]),
        "model_error": np.array([model_error]),
        "autocorrelation": np.array([rho]),
        "evidence_scale": np.array([scale]),
    }
    return new_log_w, new_state, stats


def _hold_one(
    rule: EvidenceRule,
    lw: list[float],
    log_w: np.ndarray,
    state: dict[str, np.ndarray],
    decision: int,
    checked: bool,
) -> tuple[np.ndarray, int]:
    """:func:`_hold_first_decision` of one run in Python floats (``lw``: ``log_w[0]`` as a
    list): the same tests in the same order; returns the weights and the decision code."""
    (committed,) = state["_committed"].tolist()
    decided = decision == DECIDED
    left = path_left(rule, state) is not None  # refused by the path rule: no shortcut
    if not left and committed >= 0 and (not decided or lw.index(max(lw)) == committed):
        return log_w, decision
    if not left and not decided and committed == NOT_COMMITTED:
        if state["_candidate"][0].tolist() != [0.0, 0.0]:
            state["_candidate"] = np.zeros((1, 2))
        return log_w, decision
    top = float(_argmax(lw))
    # a prior that is itself decided is the user's belief, not evidence: no commitment
    threshold = rule.log_decision_threshold
    eligible = decided and checked and all(p < threshold for p in state["_log_prior"][0].tolist())
    candidate, held = state["_candidate"][0].tolist()
    held = (held + 1.0 if held > 0 and candidate == top else 1.0) if eligible else 0.0
    candidate = top if eligible else 0.0
    state["_candidate"] = np.array([[candidate, held]])
    is_committed = committed >= 0
    contradicting = decided and is_committed and top != committed
    contradicted = committed == CONTRADICTED or contradicting or left
    commits = not is_committed and committed != CONTRADICTED and held >= rule.commit_steps
    new_committed = CONTRADICTED if contradicted else (top if commits else committed)
    state["_committed"] = np.array([new_committed])
    if not contradicted:
        return log_w, decision
    if committed != CONTRADICTED:
        state["_refused_by"] = np.array([PATH_RULE if left else REVERSAL_RULE])
    prior = state["_log_prior"]
    if contradicting:
        state["_withheld"] = np.array([top])
    state["_verified_log_w"] = prior.copy()
    return prior.copy(), MODEL_MISMATCH


def _argmax(values: list[float]) -> int:
    """``numpy.argmax`` of a list: the first largest entry, or the first NaN."""
    best, top = 0, values[0]
    for i, value in enumerate(values):
        if value != value:
            return i
        if value > top:
            best, top = i, value
    return best


def _store_verified(log_w: np.ndarray, state: dict[str, np.ndarray], verified: np.ndarray) -> None:
    """The verified weights (module docstring): ``log_w`` (the step's final weights, after
    the aim cap) for the runs ``verified`` (R,) at this step (``state`` in place)."""
    if all_true(verified):
        state["_verified_log_w"] = log_w
    elif any_true(verified):
        state["_verified_log_w"] = np.where(verified[:, None], log_w, state["_verified_log_w"])


def _aim_capped(
    rule: EvidenceRule,
    log_w: np.ndarray,
    previous: np.ndarray,
    state: dict[str, np.ndarray],
    stats: dict[str, np.ndarray],
) -> np.ndarray:
    """:func:`aim_capped_log_weights` of the rule's new weights ``log_w`` (``previous``: the
    step's weights before it); the decision of the runs without a mismatch is taken again
    from the capped weights (``stats`` in place)."""
    prior = state["_log_prior"]
    decision = stats["decision"]
    if log_w.shape[0] == 1:  # one run (the single car): Python floats, the same bits
        capped = _aim_capped_one(log_w, prior, state[AIM_OFFSET], rule.aim_variance, previous)
        if int(decision[0]) != MODEL_MISMATCH:
            top = max(capped[0].tolist())
            stats["decision"] = np.array(
                [DECIDED if top >= rule.log_decision_threshold else UNDECIDED]
            )
        return capped
    capped = aim_capped_log_weights(log_w, prior, state[AIM_OFFSET], rule.aim_variance, previous)
    stats["decision"] = np.where(
        decision == MODEL_MISMATCH,
        MODEL_MISMATCH,
        np.where(capped.max(axis=1) >= rule.log_decision_threshold, DECIDED, UNDECIDED),
    )
    return capped


def _hold_first_decision(
    rule: EvidenceRule,
    log_w: np.ndarray,
    state: dict[str, np.ndarray],
    stats: dict[str, np.ndarray],
) -> np.ndarray:
    """The reversal rule (module docstring)::

        candidate: the hypothesis of a checked decision and the steps it has held (reset
                   when the run is not decided, or decided on another hypothesis)
        commit:    candidate held for commit_time (s)          -> committed = i
        contradict: committed = i and the run decided on j != i -> weights = prior, for ever

    Updates ``state``'s ``_committed``, ``_candidate`` (and ``_verified_log_w``, and
    ``_withheld``: the hypothesis j of the contradicting decision, which the weights passed
    the threshold on before they went back to the prior) and ``stats["decision"]`` in place;
    returns the weights."""
    checked = stats.pop("checked")
    committed = state["_committed"]
    left = path_left(rule, state)
    if left is None and committed.size == 1 and committed[0] >= 0:  # one committed run
        lw = log_w[0].tolist()
        if int(stats["decision"][0]) != DECIDED or lw.index(max(lw)) == committed[0]:
            return log_w
    decided = stats["decision"] == DECIDED
    if left is None and not any_true(decided) and not any_true(committed != NOT_COMMITTED):
        if any_true(state["_candidate"] != 0):
            state["_candidate"] = np.zeros_like(state["_candidate"])
        return log_w  # (nothing decided, nothing committed: the common case at the start)
    top = np.argmax(log_w, axis=1).astype(np.float64)
    # a prior that is itself decided is the user's belief, not evidence: no commitment
    eligible = decided & checked
    eligible &= state["_log_prior"].max(axis=1) < rule.log_decision_threshold
    candidate, held = state["_candidate"][:, 0], state["_candidate"][:, 1]
    held = np.where(eligible, np.where((held > 0) & (candidate == top), held + 1.0, 1.0), 0.0)
    candidate = np.where(eligible, top, 0.0)
    state["_candidate"] = np.column_stack((candidate, held))
    is_committed = committed >= 0
    contradicting = decided & is_committed & (top != committed)
    contradicted = (committed == CONTRADICTED) | contradicting
    if left is not None:
        contradicted |= left
    commits = ~is_committed & (committed != CONTRADICTED) & (held >= rule.commit_steps)
    state["_committed"] = np.where(contradicted, CONTRADICTED, np.where(commits, top, committed))
    if not any_true(contradicted):
        return log_w
    newly = contradicted & (committed != CONTRADICTED)
    if any_true(newly):
        reason = REVERSAL_RULE if left is None else np.where(left, PATH_RULE, REVERSAL_RULE)
        state["_refused_by"] = np.where(newly, reason, state["_refused_by"])
    prior = state["_log_prior"]
    if any_true(contradicting):
        state["_withheld"] = np.where(contradicting, top, state["_withheld"])
    state["_verified_log_w"] = np.where(contradicted[:, None], prior, state["_verified_log_w"])
    stats["decision"] = np.where(contradicted, MODEL_MISMATCH, stats["decision"])
    return np.where(contradicted[:, None], prior, log_w)


_RunOutcome = tuple[int, float, float, float, bool, bool]
"""One run's decision code, lambda, rho, tau, and whether its step was checked and verified."""


def _rule_one(
    rule: EvidenceRule,
    log_w: np.ndarray,
    log_lik: np.ndarray,
    score: np.ndarray,
    state: dict[str, np.ndarray],
) -> tuple[list[float], np.ndarray | None, dict[str, np.ndarray], _RunOutcome]:
    """:func:`_weigh` for one run, in Python floats (the same arithmetic in the same order:
    a single car's filter step spends most of its time in numpy's per-call overhead on
    arrays of two numbers; ``tests/test_estimators_evidence.py`` checks the two agree): the
    new log weights as a list (and as an array when one exists already: None, else), the
    new statistics and the run's outcome."""
    (lw,) = log_w.tolist()
    active = list(map(math.isfinite, lw))
    new_state, model_error, rho, samples, mismatch, scale = _statistics_one(
        rule, score, active, state
    )
    verified = not mismatch and _verified_one(rule, model_error, samples)
    checked = (not mismatch) and samples >= MIN_CHECKED_SAMPLES
    if mismatch:
        verified_log_w = state["_verified_log_w"]
        outcome = (MODEL_MISMATCH, model_error, rho, scale, checked, verified)
        return verified_log_w[0].tolist(), verified_log_w, new_state, outcome
    raw = []
    for w, d, a in zip(lw, log_lik[0].tolist(), active, strict=True):
        raw.append(w + d / scale if a else -math.inf)
    new_lw = _normalized_one(raw)
    new_log_w: np.ndarray | None = None
    if not new_lw:
        new_log_w = normalize_log_weights(np.array([raw]), log_w)
    if math.isfinite(rule.log_floor):
        if new_log_w is None:
            new_log_w = np.array([new_lw])
        floored = np.where(np.array([active]), np.maximum(new_log_w, rule.log_floor), -np.inf)
        new_log_w = normalize_log_weights(floored, new_log_w)
    if new_log_w is not None:
        new_lw = new_log_w[0].tolist()
    decision = DECIDED if max(new_lw) >= rule.log_decision_threshold else UNDECIDED
    return new_lw, new_log_w, new_state, (decision, model_error, rho, scale, checked, verified)


def _statistics_one(
    rule: EvidenceRule, score: np.ndarray, active: list[bool], state: dict[str, np.ndarray]
) -> tuple[dict[str, np.ndarray], float, float, float, bool, float]:
    """:func:`_updated_statistics` and :func:`_run_statistics` of one run in floats: the new
    statistics (unchanged arrays kept when the steering channel was not used), lambda, rho,
    the effective samples N, the mismatch test and tau. The scores u_i are clipped to +-1e3
    (0 for the inactive hypotheses; a NaN stays: the channel was not used), and the best
    fitting hypothesis is the active one with the least e_i, the first of equals (0 when
    none is active)."""
    alpha = rule.alpha
    keep = 1.0 - alpha
    (nis,) = state["_nis"].tolist()
    (lag,) = state["_lag_product"].tolist()
    u = []
    used = True
    for v, a in zip(score[0].tolist(), active, strict=True):
        if not a:
            v = 0.0
        elif not -1e3 <= v <= 1e3:
            v = min(max(v, -1e3), 1e3)  # (NaN stays: the channel was not used)
            used = used and v == v
        u.append(v)
    new_state = dict(state)
    weight = state["_evidence_weight"].item()
    weight_sq = state["_evidence_weight_sq"].item()
    if used:
        weight = keep * weight + alpha
        weight_sq = (keep * keep) * weight_sq + alpha * alpha
        new_nis, new_lag = [], []
        for n, g, v, p in zip(nis, lag, u, state["_last_score"][0].tolist(), strict=True):
            new_nis.append(keep * n + alpha * (v * v))
            new_lag.append(keep * g + alpha * (v * p))
        nis, lag = new_nis, new_lag
        new_state["_evidence_weight"] = np.array([weight])
        new_state["_evidence_weight_sq"] = np.array([weight_sq])
        # (1, C) rows (``ndmin=2``: cheaper than numpy's reading of a nested list)
        new_state["_nis"] = np.array(nis, ndmin=2)
        new_state["_lag_product"] = np.array(lag, ndmin=2)
        new_state["_last_score"] = np.array(u, ndmin=2)
    else:  # the statistics stay; the next lag product is 0 (a gap)
        new_state["_last_score"] = np.zeros((1, len(u)))
    best = -1
    for i, a in enumerate(active):
        if a and (best < 0 or nis[i] < nis[best]):
            best = i
    best_nis = nis[max(best, 0)]
    model_error = best_nis / weight if weight > 0 else math.nan
    rho = lag[max(best, 0)] / best_nis if best_nis != 0 else math.nan
    rho_plus = 0.0 if rho != rho else min(max(rho, 0.0), MAX_AUTOCORRELATION)
    inflation = (1.0 + rho_plus) / (1.0 - rho_plus)
    samples = weight * weight / (weight_sq * inflation) if weight_sq > 0 else 0.0
    mismatch = False
    if samples > 0:
        h = 2.0 / (9.0 * samples)
        ratio = 1.0 - h + MISMATCH_QUANTILE_Z * math.sqrt(h)
        mismatch = model_error > rule.mismatch_model_error * (ratio * ratio * ratio)
    bounded = model_error
    if rule.bound_z and model_error == model_error:
        bounded = _bound_one(model_error, samples, rule.bound_z)
    scale = min((1.0 if bounded != bounded else max(bounded, 1.0)) * inflation, MAX_EVIDENCE_SCALE)
    return new_state, model_error, rho, samples, mismatch, scale


def _weigh(
    rule: EvidenceRule,
    log_w: np.ndarray,
    log_lik: np.ndarray,
    score: np.ndarray,
    state: dict[str, np.ndarray],
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """:func:`weigh_evidence` for R runs: the statistics, then the weights."""
    all_active = all_finite(log_w)  # pruned (or zero-prior) hypotheses do not count
    active = None if all_active else np.isfinite(log_w)
    new_state = _updated_statistics(rule, score, active, state)
    model_error, rho, samples, mismatch, scale = _run_statistics(rule, new_state, active)
    any_mismatch = any_true(mismatch)
    if rule.enabled:
        new_log_w = _tempered_log_weights(rule, log_w, log_lik, scale, mismatch, active, state)
        verified = verified_steps(rule, model_error, samples)
        if any_mismatch:
            verified &= ~mismatch
    else:
        verified = np.zeros(log_w.shape[0], dtype=bool)
        raw = log_w + log_lik
        new_log_w = normalize_log_weights(
            raw if active is None else np.where(active, raw, -np.inf), log_w
        )
    decision = np.where(new_log_w.max(axis=1) >= rule.log_decision_threshold, DECIDED, UNDECIDED)
    if any_mismatch:
        decision = np.where(mismatch, MODEL_MISMATCH, decision)
    stats = {
        "decision": decision,
        "model_error": model_error,
        "autocorrelation": rho,
        "evidence_scale": scale,
        "checked": (samples >= MIN_CHECKED_SAMPLES) & ~mismatch,
        "verified": verified,
    }
    return new_log_w, new_state, stats


def _run_statistics(
    rule: EvidenceRule, state: dict[str, np.ndarray], active: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """lambda, rho, the effective samples N, the mismatch test and tau of each run (R,) from
    the updated statistics ``state`` (module docstring). Before any run used the steering
    channel (n = 0 in every run: no steering model, or the channel off since the reset) they
    are what the formulas give for n = s = e = c = 0: NaN, NaN, NaN (0 / 0), no mismatch and
    tau = 1, without the arithmetic."""
    weight, weight_sq = state["_evidence_weight"], state["_evidence_weight_sq"]
    if not weight.any():
        shape = weight.shape
        nan = np.full(shape, np.nan)
        return nan, nan.copy(), nan.copy(), np.zeros(shape, dtype=bool), np.ones(shape)
    nis, lag = state["_nis"], state["_lag_product"]
    # lambda and rho of the best-fitting active hypothesis (NaN before any data)
    best = np.argmin(nis if active is None else np.where(active, nis, np.inf), axis=1)
    rows_index = np.arange(nis.shape[0])
    best_nis = nis[rows_index, best]
    model_error = best_nis / weight
    rho = lag[rows_index, best] / best_nis
    rho_plus = np.minimum(np.fmax(rho, 0.0), MAX_AUTOCORRELATION)  # (NaN: 0)
    inflation = (1.0 + rho_plus) / (1.0 - rho_plus)
    # effective number of independent squared innovations behind lambda (0 before any data)
    samples = weight * weight / (weight_sq * inflation)
    mismatch = model_error > rule.mismatch_model_error * chi2_upper_ratio(samples)
    bounded = model_error_bound(model_error, samples, rule.bound_z) if rule.bound_z else model_error
    scale = np.minimum(np.fmax(bounded, 1.0) * inflation, MAX_EVIDENCE_SCALE)  # (NaN lambda: 1)
    return model_error, rho, samples, mismatch, scale


def _updated_statistics(
    rule: EvidenceRule,
    score: np.ndarray,
    active: np.ndarray | None,
    state: dict[str, np.ndarray],
) -> dict[str, np.ndarray]:
    """The statistics n, s, e_i, c_i and the last score u_i after one sample (module
    docstring), in a copy of ``state``; unchanged in the runs that did not use the steering
    channel (NaN ``score``), whose next lag product is 0 (a gap). ``active``: (R, C) bool
    (None: all)."""
    alpha = rule.alpha
    keep = 1.0 - alpha
    weight, weight_sq = state["_evidence_weight"], state["_evidence_weight_sq"]
    nis, lag = state["_nis"], state["_lag_product"]
    # a normalized innovation beyond 1e3 is as inconsistent as it gets (no overflow)
    u = np.minimum(np.maximum(score if active is None else np.where(active, score, 0.0), -1e3), 1e3)
    if all_finite(u):  # the steering channel was used in every run (the common case)
        weight = keep * weight + alpha
        weight_sq = (keep * keep) * weight_sq + alpha * alpha
        nis = keep * nis + alpha * (u * u)
        lag = keep * lag + alpha * (u * state["_last_score"])
    else:
        used = ~np.isnan(u).any(axis=1)  # missing, gated and low-speed steps: NaN
        if not any_true(used):  # (no steering model, or the channel off in every run)
            new_state = dict(state)
            new_state["_last_score"] = np.zeros_like(u)  # the next lag product is 0 (a gap)
            return new_state
        rows = used[:, None] if active is None else used[:, None] & active
        u = np.where(rows, u, 0.0)  # 0 where not used: the next lag product is 0 (a gap)
        weight = np.where(used, keep * weight + alpha, weight)
        weight_sq = np.where(used, (keep * keep) * weight_sq + alpha * alpha, weight_sq)
        nis = np.where(rows, keep * nis + alpha * (u * u), nis)
        lag = np.where(rows, keep * lag + alpha * (u * state["_last_score"]), lag)
    new_state = dict(state)
    new_state["_evidence_weight"] = weight
    new_state["_evidence_weight_sq"] = weight_sq
    new_state["_nis"] = nis
    new_state["_lag_product"] = lag
    new_state["_last_score"] = u
    return new_state


def _tempered_log_weights(
    rule: EvidenceRule,
    log_w: np.ndarray,
    log_lik: np.ndarray,
    scale: np.ndarray,
    mismatch: np.ndarray,
    active: np.ndarray | None,
    state: dict[str, np.ndarray],
) -> np.ndarray:
    """The tempered weights (module docstring)::

        log w_i <- log w_i + l_i / tau                   (no increment on a mismatch)
        log w_i <- (1 - beta) log w_i + beta log pi_i    (forgetting; not on a mismatch)
        log w_i <- max(log w_i - logsumexp_j log w_j, log weight_floor), normalized again

    and, on a mismatch, the last verified weights."""
    any_mismatch = any_true(mismatch)
    increment = log_lik / scale[:, None]
    if any_mismatch:
        increment = np.where(mismatch[:, None], 0.0, increment)
    new_log_w = log_w + increment
    if rule.forgetting > 0:
        beta = np.where(mismatch, 0.0, rule.forgetting)[:, None]
        forgotten = (1.0 - beta) * new_log_w + beta * state["_log_prior"]
        new_log_w = forgotten if active is None else np.where(active, forgotten, -np.inf)
    new_log_w = normalize_log_weights(new_log_w, log_w)
    if math.isfinite(rule.log_floor):
        floored = np.maximum(new_log_w, rule.log_floor)
        floored = floored if active is None else np.where(active, floored, -np.inf)
        new_log_w = normalize_log_weights(floored, new_log_w)
    if any_mismatch:
        new_log_w = np.where(mismatch[:, None], state["_verified_log_w"], new_log_w)
    return new_log_w


def normalize_log_weights(log_w: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """``log_w - logsumexp(log_w)`` per run; a run whose weights all vanished keeps ``fallback``."""
    total = np.logaddexp.reduce(log_w, axis=1, keepdims=True)  # logsumexp, stable
    if all_finite(total):
        return log_w - total
    ok = np.isfinite(total)
    with np.errstate(invalid="ignore"):
        return np.where(ok, log_w - np.where(ok, total, 0.0), fallback)


def _logaddexp(a: float, b: float) -> float:
    """``numpy.logaddexp(a, b)`` in Python floats: numpy's formula (``npy_logaddexp``) with
    the same C library ``exp`` and ``log1p``, so the same bits (a test compares them)."""
    if a == b:
        return a + _LOG_2
    difference = a - b
    if difference > 0:
        return a + math.log1p(math.exp(-difference))
    if difference <= 0:
        return b + math.log1p(math.exp(difference))
    return difference  # NaN


_LOG_2 = math.log(2.0)


def _normalized_one(log_w: list[float]) -> list[float]:
    """:func:`normalize_log_weights` of one run's log weights as a list, in Python floats:
    ``log_w - logsumexp(log_w)`` with numpy's reduction order (``logaddexp`` from the first
    entry on); ``[]`` when the sum is not finite (the caller falls back)."""
    total = log_w[0]
    for value in log_w[1:]:
        total = _logaddexp(total, value)
    if not -math.inf < total < math.inf:  # (not finite)
        return []
    normalized = []
    for value in log_w:
        normalized.append(value - total)
    return normalized


def decision_names(codes: np.ndarray | int) -> np.ndarray | str:
    """The names of decision codes (:data:`DECISIONS`): a str for a scalar code."""
    codes = np.asarray(codes)
    names = np.asarray(DECISIONS)[codes]
    return str(names) if names.ndim == 0 else names


def refusal_reasons(decisions: np.ndarray | str, codes: np.ndarray | int | None) -> np.ndarray:
    """Why each run whose decision state is ``"model_mismatch"`` is in it: ``"reversal rule"``
    or ``"path rule"`` (:data:`REFUSALS` by ``codes``, the filter's ``refusal_codes``), or
    ``"mismatch test"`` (code 0, or ``codes`` None: an estimator without those rules; the model
    does not fit the steering now); ``""`` for the runs in another state. ``decisions``: decision
    state names (:data:`DECISIONS`), the shape of ``codes``; a str array of that shape."""
    decisions = np.asarray(decisions)
    if codes is None:
        codes = np.zeros(decisions.shape, dtype=np.int64)
    names = np.asarray(REFUSALS, dtype=object)[np.asarray(codes, dtype=np.int64)]
    names[names == ""] = "mismatch test"
    return np.where(decisions == "model_mismatch", names, "").astype(str)
