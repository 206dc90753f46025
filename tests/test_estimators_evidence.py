"""The evidence checks of the mixture filter (estimators.evidence; docs/design.md §8.11)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.evidence import (
    DECIDED,
    DECISIONS,
    MODEL_MISMATCH,
    UNDECIDED,
    EvidenceRule,
    initial_evidence_state,
    weigh_evidence,
)
from estimators.settings import FilterSettings
from estimators.wrappers import EstimatorInfoWrapper, estimate_info_keys
from hasa_env.steering import GeneralizedModel

DT = 0.01


def _rule(**overrides) -> EvidenceRule:
    return EvidenceRule.from_settings(FilterSettings(**overrides), DT)


def _run(rule, log_lik, score, prior=(0.5, 0.5)):
    """Weights over T steps of a single two-hypothesis run: log_lik, score (T, 2)."""
    log_w = np.log(np.asarray(prior, dtype=np.float64))[None]
    state = initial_evidence_state(log_w)
    weights, decisions, scales = [], [], []
    for k in range(len(log_lik)):
        log_w, state, stats = weigh_evidence(rule, log_w, log_lik[k][None], score[k][None], state)
        weights.append(np.exp(log_w[0]))
        decisions.append(int(stats["decision"][0]))
        scales.append(float(stats["evidence_scale"][0]))
    return np.array(weights), np.array(decisions), np.array(scales)


def _run_batch(rule, log_liks, scores):
    """The runs of :func:`_run`, weighed together (R, T, 2 weights)."""
    log_w = np.log(np.full((len(scores), 2), 0.5))
    state = initial_evidence_state(log_w)
    weights = []
    for k in range(len(scores[0])):
        log_lik = np.stack([ll[k] for ll in log_liks])
        score = np.stack([sc[k] for sc in scores])
        log_w, state, _ = weigh_evidence(rule, log_w, log_lik, score, state)
        weights.append(np.exp(log_w))
    return np.stack(weights, axis=1)


def _ar1(rng, n, rho):
    e = rng.standard_normal(n)
    out = np.empty(n)
    out[0] = e[0]
    for k in range(1, n):
        out[k] = rho * out[k - 1] + math.sqrt(1 - rho * rho) * e[k]
    return out


def test_autocorrelated_uninformative_innovations_do_not_decide_a_lane():
    # both hypotheses see the same AR(1) innovation (rho 0.95) plus a small, slowly
    # wandering difference with no sign: the raw eq. 19 piles it up into a verdict
    rng = np.random.default_rng(1)
    n = 3000
    u = _ar1(rng, n, 0.95)
    wander = 0.3 * _ar1(rng, n, 0.999)
    score = np.stack([u, u + wander], axis=1)
    log_lik = -0.5 * score * score
    raw, _, _ = _run(_rule(evidence_checks=False), log_lik, score)
    checked, decisions, scales = _run(_rule(), log_lik, score)
    assert raw[-1].max() > 0.999  # teeth: without the checks it ends "sure"
    assert checked[-1].max() < 0.95 and decisions[-1] == UNDECIDED
    assert np.median(scales[500:]) > 10  # (1 + 0.95) / (1 - 0.95) = 39


def test_consistent_evidence_decides_at_the_raw_rate():
    # white innovations, the true hypothesis' consistent, the wrong one's offset by 0.5 sigma
    rng = np.random.default_rng(2)
    n = 1000
    u = rng.standard_normal(n)
    score = np.stack([u, u + 0.5], axis=1)
    log_lik = -0.5 * score * score
    checked, decisions, scales = _run(_rule(), log_lik, score)
    assert np.median(scales[500:]) < 1.3  # (early, rho's estimate is noisy)
    assert decisions[-1] == DECIDED and checked[-1, 0] > 0.999


def test_a_model_mismatch_freezes_the_weights():
    rng = np.random.default_rng(3)
    n = 1500
    u = rng.standard_normal(n)
    good = np.stack([u, u + 0.5], axis=1)
    # then a model that fits neither hypothesis (lambda about 100) and favours the wrong one
    bad = 10.0 * np.stack([u + 0.5, u], axis=1)
    score = np.concatenate([good, bad])
    log_lik = -0.5 * score * score
    weights, decisions, _ = _run(_rule(), log_lik, score)
    assert decisions[n - 1] == DECIDED and weights[n - 1, 0] > 0.999
    assert decisions[-1] == MODEL_MISMATCH
    assert weights[-1, 0] > 0.99  # the evidence gathered while the model fitted stays
    raw, _, _ = _run(_rule(evidence_checks=False), log_lik, score)
    assert raw[-1, 1] > 0.99  # teeth: eq. 19 follows the bad model to the wrong lane


def test_weights_moved_before_the_model_was_shown_to_fit_are_not_kept_on_a_mismatch():
    # the traced run in miniature (seed 851, driver 1): four near-zero start-up innovations
    # (lambda about 0 on almost no data), three that favour one lane, then a model that fits
    # neither hypothesis (lambda about 25); the mismatch test fires later
    rng = np.random.default_rng(8)
    n = 600
    u = rng.standard_normal(n)
    score = 5.0 * np.stack([u, u], axis=1)  # lambda about 25 on both hypotheses
    score[:4] = 1e-3
    score[4:7] = [6.0, 1.0]  # three innovations that favour hypothesis 1
    log_lik = -0.5 * score * score
    weights, decisions, _ = _run(_rule(), log_lik, score)
    assert weights[10, 1] > 0.95  # the early innovations did move the weights
    assert decisions[-1] == MODEL_MISMATCH
    assert np.all(np.abs(weights[-1] - 0.5) < 1e-12)  # back to the prior, not frozen wrong
    # teeth: verified at 2 effective samples (the rule before), the wrong weights were kept
    import estimators.evidence as evidence

    old = evidence.VERIFY_MIN_SAMPLES, evidence.VERIFY_QUANTILE_Z
    try:
        evidence.VERIFY_MIN_SAMPLES, evidence.VERIFY_QUANTILE_Z = 2.0, -1e3
        before, _, _ = _run(_rule(), log_lik, score)
    finally:
        evidence.VERIFY_MIN_SAMPLES, evidence.VERIFY_QUANTILE_Z = old
    assert before[-1, 1] > 0.95


def test_a_model_that_never_fits_leaves_the_weights_at_the_prior():
    rng = np.random.default_rng(5)
    u = rng.standard_normal(2000)
    score = 8.0 * np.stack([u, u + 0.3], axis=1)  # lambda about 64 on both (threshold 9)
    weights, decisions, _ = _run(_rule(), -0.5 * score * score, score)
    assert decisions[-1] == MODEL_MISMATCH
    assert abs(weights[-1, 0] - 0.5) < 0.2  # (only the first window's evidence entered)


def test_a_reversed_decision_goes_back_to_the_prior_and_says_so():
    # first 3 s favour hypothesis 1, then 20 s of evidence for hypothesis 0: one of the two
    # periods was wrong (the hypotheses do not change within a run), nothing tells which
    rng = np.random.default_rng(4)
    u = rng.standard_normal(2300)
    score = np.where(np.arange(2300)[:, None] < 300, [[1.0, 0.0]], [[0.0, 1.0]])
    score = score + u[:, None]
    log_lik = -0.5 * score * score
    weights, decisions, _ = _run(_rule(), log_lik, score)
    assert weights[299, 1] > 0.999 and decisions[299] == DECIDED
    assert np.all(weights[-1] == 0.5) and decisions[-1] == MODEL_MISMATCH
    assert weights[300:, 0].max() < 0.95  # never confident in the other lane
    raw, _, _ = _run(_rule(evidence_checks=False), log_lik, score)
    assert raw[-1, 0] > 0.999  # teeth: eq. 19 follows the later evidence to the other lane
    # the floor and forgetting do not lift the rule
    floored, fdecisions, _ = _run(_rule(weight_floor=1e-12, forgetting_time=20.0), log_lik, score)
    assert floored[299, 1] > 0.999 and fdecisions[-1] == MODEL_MISMATCH
    assert floored.min() >= 1e-12 * 0.999  # the floor


def test_the_reversal_rule_names_the_decision_it_withheld():
    # the run of the test above: committed to hypothesis 1, then its weights pass the
    # threshold on hypothesis 0 and go back to the prior; that decision is never reported
    rng = np.random.default_rng(4)
    score = np.where(np.arange(2300)[:, None] < 300, [[1.0, 0.0]], [[0.0, 1.0]])
    score = score + rng.standard_normal(2300)[:, None]
    rule = _rule()
    log_w = np.log(np.array([[0.5, 0.5], [0.5, 0.5]]))
    state = initial_evidence_state(log_w)
    withheld = []
    for k in range(2300):
        both = np.stack([score[k], score[min(k, 299)]])  # run 1: hypothesis 1 throughout
        log_w, state, _ = weigh_evidence(rule, log_w, -0.5 * both * both, both, state)
        withheld.append(state["_withheld"].copy())
    withheld = np.array(withheld)
    assert np.all(withheld[:300] == -1)  # nothing withheld while the first decision holds
    assert np.all(withheld[-1] == [0, -1])  # run 0: a decision for 0 withheld; run 1: none
    first = int(np.argmax(withheld[:, 0] == 0))
    assert np.all(withheld[first:, 0] == 0)  # kept for the rest of the run
    assert state["_refused_by"].tolist() == [1.0, 0.0]  # REFUSALS[1]: "reversal rule"


def test_a_withheld_wrong_decision_counts_as_a_wrong_decision():
    from estimators.offline import EstimationResult

    n_runs, n_steps = 3, 4
    weights = np.full((n_runs, n_steps, 2), 0.5)
    weights[0, 1] = [0.02, 0.98]  # run 0 reports a wrong decision (bias 0: lane 0 is true)
    result = EstimationResult(
        state_names=("v_x", "y"), hypotheses=np.tile([0.0, -1.8], (n_runs, 1)),
        time=np.tile(np.arange(n_steps) * DT, (n_runs, 1)), valid=np.ones((n_runs, n_steps), bool),
        lengths=np.full(n_runs, n_steps), mean=np.zeros((n_runs, n_steps, 2)),
        std=np.ones((n_runs, n_steps, 2)), weights=weights,
        most_likely=np.zeros((n_runs, n_steps), int),
        truth={"bias": np.zeros((n_runs, n_steps))},
        withheld=np.array([-1, 1, 0]),  # run 1: a decision for lane 1 withheld; run 2: lane 0
    )  # fmt: skip
    assert result.wrong_lane_confident_share().tolist() == [0.25, 0.0, 0.0]
    assert result.wrong_decision_ever().tolist() == [True, True, False]
    without = EstimationResult(**{**result.__dict__, "withheld": None})
    assert without.wrong_decision_ever().tolist() == [True, False, False]


def test_one_run_and_many_runs_agree_on_the_reversal_rule():
    rng = np.random.default_rng(6)
    u = rng.standard_normal((2300, 3))
    flip = np.where(np.arange(2300)[:, None] < 300, [[1.0, 0.0]], [[0.0, 1.0]])
    steady = np.tile([[0.0, 0.5]], (2300, 1))
    scores = [flip + u[:, :1], steady + u[:, 1:2], flip[::-1] + u[:, 2:]]
    alone = [_run(_rule(), -0.5 * sc * sc, sc)[0] for sc in scores]
    batch = _run_batch(_rule(), [-0.5 * sc * sc for sc in scores], scores)
    for r in range(3):
        np.testing.assert_allclose(batch[r], alone[r], rtol=0, atol=1e-12)


def test_missing_steering_does_not_move_the_statistics():
    log_w = np.log(np.array([[0.5, 0.5]]))
    state = initial_evidence_state(log_w)
    new_log_w, new_state, stats = weigh_evidence(
        _rule(), log_w, np.zeros((1, 2)), np.full((1, 2), np.nan), state
    )
    assert new_state["_evidence_weight"][0] == 0.0 and np.isnan(stats["model_error"][0])
    np.testing.assert_allclose(new_log_w, log_w)


@pytest.mark.slow
def test_the_wrappers_report_the_decision_state():
    arx = GeneralizedModel.paper().arx()
    from estimators.gm_ekf import GaussianMixtureEKF

    env = EstimatorInfoWrapper(
        gym.make("hasa_env/LaneKeeping-v0"), GaussianMixtureEKF(arx, steering_ratio=1.0)
    )
    _, info = env.reset(seed=0)
    assert set(estimate_info_keys()) <= set(info)
    assert info["estimate_decision"] in DECISIONS
    assert info["estimate_decision_code"] == DECISIONS.index(info["estimate_decision"])
    for _ in range(200):
        _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert isinstance(info["estimate_decision"], str)
    assert info["estimate_evidence_scale"] >= 1.0


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(-50, 5),  # log-likelihood of hypothesis 0
            st.floats(-50, 5),
            st.one_of(st.floats(-20, 20), st.just(math.nan)),  # normalized innovation 0
            st.floats(-20, 20),
        ),
        min_size=1,
        max_size=300,
    ),
    st.sampled_from([(0.5, 0.5), (0.99, 0.01), (1.0, 0.0)]),
    st.sampled_from([0.0, 0.95]),
)
def test_the_single_run_path_equals_the_batched_one(steps, prior, confidence):
    from estimators.evidence import _rule_one, _weigh

    def weigh_one(log_w, log_lik, score, state):  # the float path's outcome as _weigh's arrays
        lw, new_log_w, new_state, run = _rule_one(rule, log_w, log_lik, score, state)
        decision, model_error, rho, scale, checked, verified = run
        stats = {
            "decision": np.array([decision]),
            "model_error": np.array([model_error]),
            "autocorrelation": np.array([rho]),
            "evidence_scale": np.array([scale]),
            "checked": np.array([checked]),
            "verified": np.array([verified]),
        }
        return np.array([lw]) if new_log_w is None else new_log_w, new_state, stats

    rule = _rule(mismatch_model_error=2.0, evidence_confidence=confidence)
    with np.errstate(divide="ignore"):
        log_w = np.log(np.array([prior]))
    one, batched = (log_w, initial_evidence_state(log_w)), (log_w, initial_evidence_state(log_w))
    for l0, l1, s0, s1 in steps:
        log_lik = np.array([[l0, l1]])
        score = np.array([[s0, s0 if math.isnan(s0) else s1]])
        w1, st1, stats1 = weigh_one(one[0], log_lik, score, one[1])
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            w2, st2, stats2 = _weigh(rule, batched[0], log_lik, score, batched[1])
        np.testing.assert_allclose(w1, w2, rtol=1e-12, atol=1e-12)
        for key in stats1:
            np.testing.assert_allclose(stats1[key], stats2[key], rtol=1e-12, atol=1e-12)
        for key in st1:
            np.testing.assert_allclose(st1[key], st2[key], rtol=1e-12, atol=1e-12)
        one, batched = (w1, st1), (w2, st2)


def test_the_model_error_bound_covers_lambda_and_shrinks_with_data():
    from scipy.stats import chi2

    from estimators.evidence import model_error_bound

    samples = np.array([1.0, 5.0, 30.0, 300.0, 3000.0])
    bound = model_error_bound(np.ones(5), samples, 1.645)
    assert bound[0] > 1e6  # one sample rules almost nothing out
    assert np.all(np.diff(bound[1:]) < 0) and bound[-1] == pytest.approx(1.0, abs=0.07)
    # Wilson-Hilferty against the exact chi-square quantile: lambda_up = N / chi2_0.05(N)
    exact = samples[1:] / chi2.ppf(0.05, samples[1:])
    np.testing.assert_allclose(bound[1:], exact, rtol=0.03)
    np.testing.assert_array_equal(model_error_bound(np.ones(5), samples, 0.0), np.ones(5))


def test_a_bounded_model_earns_its_weight_as_the_data_check_it():
    # a consistent model (white unit innovations) with steady evidence for hypothesis 0
    rng = np.random.default_rng(7)
    n = 400
    score = np.stack([rng.standard_normal(n), rng.standard_normal(n) + 0.5], axis=1)
    log_lik = -0.5 * score**2
    _, _, plain = _run(_rule(), log_lik, score)
    _, _, bounded = _run(_rule(evidence_confidence=0.95), log_lik, score)
    assert np.all(bounded >= plain - 1e-12)
    assert bounded[5] > 5 * plain[5]  # the first samples count for little
    assert bounded[-1] < 1.5 * plain[-1]  # 4 s of data: about the same weight
