"""The path rule of the evidence rule (estimators.evidence; docs/design.md §8.24): a run in
which the car's average offset has passed ``aim_offset_limit * aim_offset_std`` from the centre
of every hypothesis is refused (weights back to the prior, ``model_mismatch``) for the rest of
the run."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from benchmarks.protocol.config import ProtocolConfig
from benchmarks.protocol.plan import load_frames, synthetic_plan
from estimators import FilterSettings, GaussianMixtureEKF
from estimators.evidence import (
    AIM_OFFSET,
    AIM_REACH,
    DECIDED,
    MODEL_MISMATCH,
    REFUSALS,
    EvidenceRule,
    initial_aim_offsets,
    initial_evidence_state,
    moved_aim_offsets,
    path_left,
    weigh_evidence,
)
from estimators.filterpy_ekf import FilterpyGMEKF
from estimators.offline import run_estimator
from hasa_env.steering.models import GeneralizedModel, TwoPointModel

RULE = EvidenceRule.from_settings(FilterSettings(), 0.01)  # sigma_a 0.3 m, limit 4: 1.2 m


def _step(rule: EvidenceRule, reach: list[list[float]], prior: list[list[float]] | None = None):
    """One step of the rule with steering evidence of 30 nats for hypothesis 1 and the car held
    near its centre; ``reach`` (R, 2) the averages' largest |a_i| so far."""
    n = len(reach)
    log_prior = np.log(np.full((n, 2), 0.5) if prior is None else np.asarray(prior))
    state = initial_evidence_state(log_prior)
    state[AIM_OFFSET] = np.tile([1.7, -0.1], (n, 1))
    state[AIM_REACH] = np.asarray(reach, dtype=np.float64)
    log_lik = np.tile([0.0, 30.0], (n, 1))
    score = np.tile([0.5, 0.1], (n, 1))
    return weigh_evidence(rule, log_prior, log_lik, score, state), log_prior


def test_a_run_that_left_every_centre_is_refused_and_stays_refused():
    (log_w, state, stats), prior = _step(RULE, [[1.8, 1.25], [1.8, 1.15]])
    assert stats["decision"].tolist() == [MODEL_MISMATCH, DECIDED]
    assert [REFUSALS[int(c)] for c in state["_refused_by"]] == ["path rule", ""]
    np.testing.assert_array_equal(log_w[0], prior[0])  # back to the prior
    assert np.exp(log_w[1, 1]) > 0.95
    # the refusal holds for the rest of the run, whatever the evidence
    again = weigh_evidence(RULE, log_w, np.array([[0.0, 30.0]] * 2), np.ones((2, 2)), state)
    assert again[2]["decision"][0] == MODEL_MISMATCH
    np.testing.assert_array_equal(again[0][0], prior[0])


def test_the_rule_is_off_with_an_infinite_limit_no_cap_or_a_decided_prior():
    for settings in (FilterSettings(aim_offset_limit=math.inf), FilterSettings(aim_offset_std=0)):
        rule = EvidenceRule.from_settings(settings, 0.01)
        assert _step(rule, [[1.8, 1.8]])[0][2]["decision"][0] == DECIDED
    # a prior that is itself decided is the user's belief (as in the reversal rule)
    (_, _, stats), _ = _step(RULE, [[1.8, 1.8]], prior=[[0.01, 0.99]])
    assert stats["decision"][0] == DECIDED
    with pytest.raises(ValueError, match="aim_offset_limit"):
        FilterSettings(aim_offset_limit=0.0)


def test_one_run_in_floats_is_the_batch_to_the_bit():
    rng = np.random.default_rng(5131)
    n = 400
    prior = np.log(rng.dirichlet(np.ones(2), n))
    log_w = prior + rng.standard_normal((n, 2)) * 3.0
    log_lik = rng.standard_normal((n, 2)) * 5.0
    score = rng.standard_normal((n, 2))
    state = initial_evidence_state(prior)
    state.update(initial_aim_offsets(rng.uniform(-2, 2, (n, 2))))
    state[AIM_REACH] = rng.uniform(0, 2, (n, 2))
    lateral = rng.uniform(-2, 2, n * 2)
    moved = moved_aim_offsets(state, lateral, 0.3, 0.6)  # some runs held near no centre
    assert 0 < (moved[AIM_REACH].min(axis=1) >= RULE.aim_limit).sum() < n
    batch = weigh_evidence(RULE, log_w, log_lik, score, moved)
    for r in range(n):
        one_state = {k: v[r : r + 1].copy() for k, v in state.items()}
        one_moved = moved_aim_offsets(one_state, lateral[2 * r : 2 * r + 2], 0.3, 0.6)
        for key in (AIM_OFFSET, AIM_REACH):
            np.testing.assert_array_equal(one_moved[key], moved[key][r : r + 1])
        one = weigh_evidence(RULE, log_w[r : r + 1], log_lik[r : r + 1], score[r : r + 1],
                             one_moved)  # fmt: skip
        np.testing.assert_array_equal(one[0], batch[0][r : r + 1])
        assert one[2]["decision"][0] == batch[2]["decision"][r]


def _final(result) -> int:
    return int(result.decision[0, result.lengths[0] - 1])


def test_a_start_far_from_every_centre_is_not_a_path():
    """The reach counts only while the car is held near some centre (within 0.6 m), so a car
    put 1.3 m from both centres at the start and driven back is not refused; a followed shift
    from one centre to the other is."""
    rate = 0.01 / 10.0
    state = initial_evidence_state(np.log(np.full((1, 2), 0.5)))
    state.update(initial_aim_offsets(np.array([[1.3, -0.5 - 1.8]])))  # true 1.3 m, other 2.3 m
    assert state[AIM_REACH].tolist() == [[0.0, 0.0]]
    for k in range(2000):  # back to the centre in 2 s, then held there for 18 s
        y = 1.3 * max(0.0, 1.0 - k / 200)
        state = moved_aim_offsets(state, np.array([y, y - 1.8]), rate, RULE.aim_limit / 2)
    assert state[AIM_REACH][0, 0] <= 0.6 and state[AIM_REACH][0, 1] > 1.2
    assert path_left(RULE, state) is None
    for _ in range(3000):  # then held 1.8 m over for 30 s: a followed shift
        state = moved_aim_offsets(state, np.array([1.8, 0.0]), rate, RULE.aim_limit / 2)
    assert path_left(RULE, state) is not None


@pytest.fixture(scope="module")
def shifted_and_kept():
    """One driver's run of ``lane_shift`` (the driven lane moves 1.8 m from station 150 m
    toward the other hypothesis' centre) and of ``paper``, 40 s each."""
    out = {}
    for scenario in ("lane_shift", "paper"):
        config = ProtocolConfig(seeds=(5131,), drivers=1, runs=1, ill_runs=1, duration=40.0,
                                curved_runs=0, scenario=scenario)  # fmt: skip
        plan = synthetic_plan(config, 5131)
        out[scenario] = load_frames(plan.main, "straight", plan.env_config, plan.params)[0]
    return out


@pytest.mark.parametrize("model", [TwoPointModel, GeneralizedModel])
def test_a_followed_lane_shift_ends_refused_and_lane_keeping_does_not(shifted_and_kept, model):
    frame = shifted_and_kept["lane_shift"]
    settings = FilterSettings.from_env_config(frame.attrs["config"], steering_ratio=15.0)
    arx = model.paper().arx()
    result = run_estimator(GaussianMixtureEKF(arx, settings), frame)
    assert _final(result) == MODEL_MISMATCH
    assert result.refusal_reasons().tolist() == ["path rule"]
    # refused by this rule: without it neither the reversal rule nor the mismatch test does
    off = run_estimator(
        GaussianMixtureEKF(arx, replace(settings, aim_offset_limit=math.inf)), frame
    )
    assert _final(off) != MODEL_MISMATCH
    assert off.refusal_reasons().tolist() == [""]
    kept = shifted_and_kept["paper"]
    settings = FilterSettings.from_env_config(kept.attrs["config"], steering_ratio=15.0)
    result = run_estimator(GaussianMixtureEKF(arx, settings), kept)
    assert not (result.decision[0, : result.lengths[0]] == MODEL_MISMATCH).any()


def test_filterpy_reference_keeps_the_same_path_rule(shifted_and_kept):
    frame = shifted_and_kept["lane_shift"]
    settings = FilterSettings.from_env_config(frame.attrs["config"], steering_ratio=15.0)
    arx = TwoPointModel.paper().arx()
    fast = run_estimator(GaussianMixtureEKF(arx, settings), frame)
    ref = run_estimator(FilterpyGMEKF(arx, settings), frame)
    assert _final(fast) == MODEL_MISMATCH
    np.testing.assert_array_equal(fast.decision, ref.decision)
    np.testing.assert_allclose(fast.weights, ref.weights, rtol=0, atol=1e-9)


def test_hasa_replay_says_which_rule_refused_a_recording(shifted_and_kept, tmp_path):
    from benchmarks.recordings import describe_estimate
    from estimators.offline import estimate_recording
    from hasa_env.drivers.runner import recording_meta
    from hasa_env.recording import load_recording, save_recording

    frame = shifted_and_kept["lane_shift"]
    recording = load_recording(save_recording(frame, tmp_path / "shift", recording_meta(frame)))
    run = estimate_recording(recording, GeneralizedModel.paper(), steering_ratio=15.0)
    assert (run.final_decision, run.refused_by) == ("model_mismatch", "path rule")
    assert "ends model_mismatch (path rule); steering live" in describe_estimate(run)
    kept = shifted_and_kept["paper"]
    recording = load_recording(save_recording(kept, tmp_path / "kept", recording_meta(kept)))
    run = estimate_recording(recording, GeneralizedModel.paper(), steering_ratio=15.0)
    assert run.refused_by == "" and f"ends {run.final_decision}; " in describe_estimate(run)
