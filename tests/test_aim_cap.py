"""The aim cap of the evidence rule (estimators.evidence; docs/design.md §8.19): no run's lane
log-odds exceed what a prior on where drivers hold the car gives for where it has been held."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from estimators.evidence import (
    AIM_OFFSET,
    DECIDED,
    UNDECIDED,
    EvidenceRule,
    aim_capped_log_weights,
    initial_evidence_state,
    weigh_evidence,
)
from estimators.settings import FilterSettings

SIGMA = 0.3


def _bound(a_i: float, a_j: float) -> float:
    return abs(a_i * a_i - a_j * a_j) / (2 * SIGMA * SIGMA)


def test_held_offset_between_centres_caps_a_confident_verdict():
    # the car held 0.45 m from hypothesis 0's centre and 0.35 m from hypothesis 1's:
    # steering evidence of 20 nats for hypothesis 1 is cut to the aim prior's 0.44 nats
    log_w = np.log(np.array([[1e-9, 1 - 1e-9]]))
    prior = np.log(np.full((1, 2), 0.5))
    capped = aim_capped_log_weights(log_w, prior, np.array([[0.45, -0.35]]), SIGMA**2)
    assert math.isclose(capped[0, 1] - capped[0, 0], _bound(0.45, -0.35), rel_tol=1e-12)
    assert np.exp(capped[0]).max() < 0.95  # undecided
    assert math.isclose(np.exp(capped[0]).sum(), 1.0)


def test_car_near_one_centre_keeps_the_verdict():
    # hypotheses 1.8 m apart, the car 0.1 m from the centre of the one the evidence favours
    log_w = np.log(np.array([[1e-6, 1 - 1e-6]]))
    prior = np.log(np.full((1, 2), 0.5))
    capped = aim_capped_log_weights(log_w, prior, np.array([[1.7, -0.1]]), SIGMA**2)
    np.testing.assert_allclose(capped, log_w, rtol=0, atol=1e-12)


@given(
    evidence=st.lists(st.floats(-50, 50), min_size=3, max_size=3),
    aims=st.lists(st.floats(-3, 3), min_size=3, max_size=3),
    prior=st.lists(st.floats(0.05, 1), min_size=3, max_size=3),
)
def test_cap_bounds_the_log_odds_and_is_idempotent(evidence, aims, prior):
    p = np.log(np.asarray(prior) / np.sum(prior))[None]
    raw = p + np.asarray(evidence)[None]
    raw -= np.logaddexp.reduce(raw, axis=1, keepdims=True)
    a = np.asarray(aims)[None]
    capped = aim_capped_log_weights(raw, p, a, SIGMA**2)
    best = int(np.argmax(capped[0]))
    for i in range(3):
        odds = (capped[0, best] - p[0, best]) - (capped[0, i] - p[0, i])
        assert odds <= _bound(a[0, best], a[0, i]) + 1e-9
    # never turns the evidence around (the hypothesis it favoured stays among the most
    # favoured), and a second cap changes nothing
    kept = capped[0] - p[0]
    assert kept[int(np.argmax(raw[0] - p[0]))] >= kept.max() - 1e-9
    np.testing.assert_allclose(
        aim_capped_log_weights(capped, p, a, SIGMA**2), capped, rtol=0, atol=1e-9
    )


def test_pruned_hypothesis_stays_pruned():
    log_w = np.array([[-np.inf, 0.0]])
    capped = aim_capped_log_weights(log_w, np.log([[0.5, 0.5]]), np.array([[0.0, 0.1]]), 0.09)
    assert capped[0, 0] == -np.inf and capped[0, 1] == 0.0


def test_rule_decides_on_the_capped_weights():
    rule = EvidenceRule.from_settings(FilterSettings(aim_offset_std=SIGMA), 0.01)
    assert math.isclose(rule.aim_variance, SIGMA**2)
    log_w = np.log(np.full((1, 2), 0.5))
    state = initial_evidence_state(log_w)
    held = {**state, AIM_OFFSET: np.array([[0.45, -0.35]])}
    near = {**state, AIM_OFFSET: np.array([[1.7, -0.1]])}
    log_lik = np.array([[0.0, 30.0]])
    score = np.array([[0.5, 0.1]])
    for evidence, expected in ((held, UNDECIDED), (near, DECIDED)):
        new_log_w, _, stats = weigh_evidence(rule, log_w, log_lik, score, evidence)
        assert stats["decision"][0] == expected
    off = EvidenceRule.from_settings(FilterSettings(aim_offset_std=0.0), 0.01)
    _, _, stats = weigh_evidence(off, log_w, log_lik, score, held)
    assert stats["decision"][0] == DECIDED


def test_one_run_in_floats_is_the_batch_to_the_bit():
    from estimators.evidence import _aim_capped_one

    rng = np.random.default_rng(5130)
    for n_comp in (2, 3):
        n = 3000
        prior = np.log(rng.dirichlet(np.ones(n_comp), n))
        log_w = prior + rng.standard_normal((n, n_comp)) * 10.0 ** rng.uniform(-2, 2, (n, 1))
        previous = prior + rng.standard_normal((n, n_comp)) * 10.0 ** rng.uniform(-2, 2, (n, 1))
        log_w[::9, 1] = -np.inf  # pruned
        previous[::9, 1] = -np.inf
        log_w[::13, 0] = log_w[::13, 1]  # ties
        aim = rng.uniform(-3, 3, (n, n_comp))
        aim[::17] = aim[::17, :1]  # equal offsets: a bound of 0
        batch = aim_capped_log_weights(log_w, prior, aim, 0.09, previous)
        for r in range(n):
            one = _aim_capped_one(log_w[r : r + 1], prior[r : r + 1], aim[r : r + 1], 0.09,
                                  previous[r : r + 1])  # fmt: skip
            np.testing.assert_array_equal(one, batch[r : r + 1])
