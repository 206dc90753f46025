"""The mixture filter's fast paths give the plain API's results, to the bit.

- :func:`estimators.offline.run_estimator` steps a :class:`GaussianMixtureEKF` with
  ``advance`` (road points checked once, no per-step :class:`Estimate`) and records its states
  in blocks (:mod:`estimators.mixture_trace`): every field of the result equals the per-step
  loop over ``step`` and the estimate and properties it returns;
- the prediction computes each transition variant on its own runs' rows only, and the gated
  update repeats the update on the gated runs' rows only: every row's result equals the one of
  the computation over all rows.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd
import pytest

from benchmarks.protocol.config import ProtocolConfig
from benchmarks.protocol.plan import load_frames, synthetic_plan
from estimators import FilterSettings, GaussianMixtureEKF
from estimators.baselines import NoSteeringEKF, OracleEKF
from estimators.filter_matrices import _MIN_RUNS_SKIPPED
from estimators.mixture_trace import BLOCK_STEPS
from estimators.offline import (
    STEERING_ONLY_FIELDS,
    EstimationResult,
    pass_key,
    run_estimator,
    stack_recordings,
)
from hasa_env.steering.models import GeneralizedModel, TwoPointModel

FIELDS = ("hypotheses", "time", "valid", "lengths", "mean", "std", "weights", "most_likely",
          "truth", "component_means", "gated", "low_speed", "decision", "model_error",
          "channel_nis", "evidence_scale", "withheld")  # fmt: skip


class _PerStep:
    """The filter behind a plain object: :func:`run_estimator` takes its per-step loop
    (``step``, the estimate and the filter's properties at every step)."""

    def __init__(self, ekf: GaussianMixtureEKF) -> None:
        self._ekf = ekf

    def __getattr__(self, name: str) -> Any:
        return getattr(self._ekf, name)


def _assert_equal_results(fast: EstimationResult, plain: EstimationResult) -> None:
    assert fast.state_names == plain.state_names
    for name in FIELDS:
        ours, theirs = getattr(fast, name), getattr(plain, name)
        assert (ours is None) == (theirs is None), name
        if isinstance(ours, dict):
            assert ours.keys() == theirs.keys()
            for key in ours:
                np.testing.assert_array_equal(ours[key], theirs[key], err_msg=key)
        elif ours is not None:
            assert ours.dtype == theirs.dtype, name
            np.testing.assert_array_equal(ours, theirs, err_msg=name)


@pytest.fixture(scope="module")
def frames() -> list[pd.DataFrame]:
    """Curved and straight runs of one synthetic seed, of unequal lengths, with missing,
    non-finite and outlying readings (the missing-data, gating and padding paths)."""
    config = ProtocolConfig(seeds=(5003,), drivers=2, runs=2, ill_runs=1, duration=2.0,
                            curved_runs=2)  # fmt: skip
    plan = synthetic_plan(config, 5003)
    curved = load_frames(plan.curved, "curved", plan.env_config, plan.params)
    straight = load_frames(plan.main, "straight", plan.env_config, plan.params)
    runs = [f.copy() for f in [*curved, *straight]]
    for run in runs:
        run.attrs = dict(run.attrs)
    rng = np.random.default_rng(5003)
    for run in runs[1:4]:
        rows = rng.choice(np.arange(5, len(run)), size=12, replace=False)
        run.loc[rows[:4], "sensor_steering"] = np.nan
        run.loc[rows[4:6], "sensor_camera_lateral"] = np.inf
        run.loc[rows[6:9], "sensor_camera_lateral"] += 3.0  # outliers: gated
        run.loc[rows[9:], "sensor_imu_lateral"] = np.nan
    runs[2] = runs[2].iloc[: len(runs[2]) - BLOCK_STEPS - 7]  # padded steps
    return runs


@pytest.mark.parametrize("model", ["generalized", "two-point", None])
def test_the_offline_fast_path_equals_the_per_step_loop(frames, model) -> None:
    arx = {"generalized": GeneralizedModel.paper().arx(), "two-point": TwoPointModel.paper().arx(),
           None: None}[model]  # fmt: skip
    settings = FilterSettings.from_env_config(frames[0].attrs["config"], steering_ratio=15.0)
    for batch in (frames, frames[2:], frames[:1]):
        fast = run_estimator(GaussianMixtureEKF(arx, settings), batch, store_components=True)
        plain = run_estimator(_PerStep(GaussianMixtureEKF(arx, settings)), batch,
                              store_components=True)  # fmt: skip
        _assert_equal_results(fast, plain)
        if batch is frames:  # the gate's path was taken
            assert fast.gated is not None and fast.gated.any()


def _batch(
    runs: int, seed: int, hypotheses: list[float]
) -> tuple[GaussianMixtureEKF, np.ndarray, np.ndarray]:
    """A generalized-model filter after 30 random steps of ``runs`` runs, and its x, P."""
    rng = np.random.default_rng(seed)
    ekf = GaussianMixtureEKF(GeneralizedModel.paper().arx(), FilterSettings(steering_ratio=15.0))
    z = np.stack([15.0 + 0.05 * rng.standard_normal((30, runs)),
                  -0.5 + 0.05 * rng.standard_normal((30, runs)),
                  0.002 * rng.standard_normal((30, runs))], axis=-1)  # fmt: skip
    ekf.reset(z[0], hypotheses)
    for k in range(1, 30):
        ekf.step(z[k], 0.05 * rng.standard_normal((runs, 2)))
    state = ekf.mixture_state
    return ekf, state.x, state.P


HYPOTHESES = pytest.mark.parametrize("hypotheses", [[0.0, -1.8], [0.0]], ids=["C=2", "C=1"])


@HYPOTHESES
@pytest.mark.parametrize("held_runs", [[2], [2, 4], [0, 2, 3, 4]])
def test_each_transition_variant_is_predicted_as_for_all_rows(held_runs, hypotheses) -> None:
    """Runs of three transition variants in one batch (one of them on a single row when
    C = 1): each run's prediction is the one of a batch whose runs all take its variant."""
    runs, n_comp = 6, len(hypotheses)
    ekf, x, cov = _batch(runs, 5004, hypotheses)
    rng = np.random.default_rng(5004)
    acc = 0.05 * rng.standard_normal((runs, 2))
    acc[4, 1] = np.nan
    steering = 0.03 * rng.standard_normal(runs)
    steering[[1, 3]] = np.nan  # no reading: the plain transition
    held = np.isin(np.arange(runs), held_runs)  # the memory held
    points = np.tile([10.0, 0.0, 25.0, 0.0], (runs, 1))
    points[5] = [10.0, 0.3, 25.0, 1.9]
    predict = ekf.matrices.predict_batch
    every = np.ones(runs, dtype=bool)
    variants = ["held" if h else "full" if np.isnan(s) else "decorrelated"
                for h, s in zip(held, steering, strict=True)]  # fmt: skip
    for _ in range(20):  # states near the filter's (rounding differences are rare)
        x = x * (1.0 + 1e-3 * rng.standard_normal(x.shape))
        x_new, cov_new = predict(x, cov, acc, steering, n_comp, road_points=points, held=held)
        uniform = {
            "decorrelated": predict(x, cov, acc, np.nan_to_num(steering), n_comp,
                                    road_points=points),
            "full": predict(x, cov, acc, np.full(runs, np.nan), n_comp, road_points=points),
            "held": predict(x, cov, acc, steering, n_comp, road_points=points, held=every),
        }  # fmt: skip
        assert set(variants) == set(uniform)
        for r, variant in enumerate(variants):
            rows = slice(n_comp * r, n_comp * (r + 1))
            np.testing.assert_array_equal(x_new[rows], uniform[variant][0][rows], err_msg=str(r))
            np.testing.assert_array_equal(cov_new[rows], uniform[variant][1][rows])


@HYPOTHESES
def test_the_gated_update_is_repeated_as_for_all_rows(hypotheses) -> None:
    """Three of twelve runs gate a channel: the update repeated on their rows only gives what
    the update of every row without the gated channels gives."""
    runs, n_comp = 12, len(hypotheses)
    ekf, x, cov = _batch(runs, 5005, hypotheses)
    log_w = ekf.mixture_state.log_w
    first = x[::n_comp]  # each run's first hypothesis
    z = np.column_stack([np.hypot(first[:, 0], first[:, 2]), first[:, 1] + first[:, 3],
                         first[:, -1]])  # fmt: skip
    z[[0, 1], 1] += 2.0  # camera outliers
    z[3, 2] += 1.0  # steering outlier
    z[4, 0] = np.nan
    matrices = ekf.matrices
    x_post, cov_post, log_lik, gated, normalized = matrices.gated_update_batch(
        x, cov, z, n_comp, False, gate=6.0, log_weights=log_w
    )
    assert gated[0, 1] and gated[1, 1] and gated[3, 2] and gated.sum() == 3
    assert runs - 3 >= _MIN_RUNS_SKIPPED  # the rows-only path
    without = np.where(gated, np.nan, z)
    every_row = matrices._update(x, cov, without, n_comp, False, None)
    for name, ours, theirs in zip(("x", "P", "log_lik"), (x_post, cov_post, log_lik),
                                  every_row, strict=False):  # fmt: skip
        np.testing.assert_array_equal(ours, theirs, err_msg=name)
    expected = every_row[3] / np.sqrt(every_row[4])
    expected[np.repeat(np.isnan(without), n_comp, axis=0)] = np.nan
    np.testing.assert_array_equal(normalized, expected)


def test_the_evidence_rule_verifies_as_verified_steps() -> None:
    """:func:`estimators.evidence.verified_steps` (the bound's arithmetic without its guards,
    computed only with enough samples) is its definition by :func:`model_error_bound`, on
    both sides of every threshold."""
    from estimators.evidence import (
        VERIFY_MIN_SAMPLES,
        VERIFY_QUANTILE_Z,
        EvidenceRule,
        model_error_bound,
        verified_steps,
    )

    rule = EvidenceRule.from_settings(FilterSettings(), 0.01)
    rng = np.random.default_rng(5006)
    samples = np.concatenate([[0.0, 1.0, 9.999, VERIFY_MIN_SAMPLES], rng.uniform(0, 500, 400)])
    model_error = rng.uniform(0.0, 2.0 * rule.mismatch_model_error, samples.size)
    model_error[[0, 5, 9]] = np.nan
    bound = model_error_bound(model_error, samples, VERIFY_QUANTILE_Z)
    expected = (samples >= VERIFY_MIN_SAMPLES) & (bound <= rule.mismatch_model_error)
    with np.errstate(all="raise"):  # no division by zero, no invalid value
        fast = verified_steps(rule, model_error, samples)
    assert expected.any() and not expected.all()
    np.testing.assert_array_equal(fast, expected)
    # no run with enough samples: none verified, nothing computed
    few = verified_steps(rule, model_error[:3], samples[:3])
    assert few.dtype == bool and not few.any()


@pytest.mark.parametrize("confidence", [0.0, 0.95])
def test_the_evidence_rule_without_steering_data_gives_the_formulas_values(confidence) -> None:
    """Runs that never used the steering channel (no model; the channel off): the rule skips
    its statistics' arithmetic; its values are those the formulas give such runs in a batch
    with a run that did use it."""
    from estimators.evidence import (
        EvidenceRule,
        _run_statistics,
        _updated_statistics,
        initial_evidence_state,
    )

    rule = EvidenceRule.from_settings(FilterSettings(evidence_confidence=confidence), 0.01)
    log_prior = np.log(np.full((4, 2), 0.5))
    state = initial_evidence_state(log_prior)
    no_data = np.full((4, 2), np.nan)
    with_data = no_data.copy()
    with_data[3] = [0.4, -1.2]  # the last run used it
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        alone = _updated_statistics(rule, no_data[:3], None, initial_evidence_state(log_prior[:3]))
        mixed = _updated_statistics(rule, with_data, None, state)
        for key, value in alone.items():
            np.testing.assert_array_equal(value, mixed[key][:3], err_msg=key)
        skipped = _run_statistics(rule, alone, None)
        computed = _run_statistics(rule, mixed, None)
    for ours, theirs in zip(skipped, computed, strict=True):
        assert ours.dtype == theirs.dtype
        np.testing.assert_array_equal(ours, theirs[:3])


@pytest.mark.parametrize(
    ("make", "kwargs"),
    [(lambda s: OracleEKF(None, s), {}), (NoSteeringEKF, {"hypotheses": [0.0]})],
)
def test_each_run_is_gated_as_alone_also_with_one_hypothesis(frames, make, kwargs) -> None:
    """The gate's quick exit looks at every run's own most likely hypothesis: a run with an
    outlier is gated in a batch whose first run has none (with one hypothesis per run the exit
    once read the first run's distance only, so an outlier went ungated in a batch)."""
    clean = frames[0]  # no outliers
    noisy = frames[3]  # outlying camera readings
    settings = FilterSettings.from_env_config(clean.attrs["config"])
    alone = run_estimator(make(settings), [noisy], **kwargs)
    batch = run_estimator(make(settings), [clean, noisy], **kwargs)
    assert alone.gated is not None and alone.gated.any(), "no outlier gated: nothing tested"
    for name in ("mean", "std", "weights", "gated"):
        np.testing.assert_array_equal(
            getattr(batch, name)[1, : alone.lengths[0]], getattr(alone, name)[0], err_msg=name
        )


def test_recordings_stacked_once_give_every_filter_its_own_results(frames) -> None:
    """:func:`stack_recordings` once for several filters (the benchmark's batches): each
    gets the results it gets from the frames, and none can write into the shared arrays."""
    stacked = stack_recordings(frames)
    settings = FilterSettings.from_env_config(frames[0].attrs["config"], steering_ratio=15.0)
    for model in (GeneralizedModel.paper().arx(), TwoPointModel.paper().arx(), None):
        alone = run_estimator(GaussianMixtureEKF(model, settings), frames)
        shared = run_estimator(GaussianMixtureEKF(model, settings), stacked)
        _assert_equal_results(shared, alone)
    assert stacked.road_points  # the curved runs' road points, computed once per look-ahead
    with pytest.raises(ValueError, match="read-only"):
        stacked.measurements[0, 0, 0] = 1.0


def test_filters_without_steering_of_equal_pass_keys_give_equal_results(frames) -> None:
    """:func:`pass_key`: a filter without a steering model never reads the steering-only
    settings (the benchmark runs one pass for the no-steering filters of the models the trust
    rule refuses and the no-steering baseline), whatever their values; the key tells apart
    the settings that matter and leaves every other estimator out."""
    base = FilterSettings.from_env_config(frames[0].attrs["config"])
    reference = NoSteeringEKF(base)
    key = pass_key(reference)
    assert key is not None
    expected = run_estimator(reference, frames)
    changed = {"steering_residual_std": 0.05, "steering_sensor_std": 0.0, "steering_ratio": 15.0,
               "min_speed": 12.0, "steering_max_speed": 5.0, "steering_curvature_limit": 1e-4,
               "aim_offset_std": 0.0, "aim_offset_time": 7.0}  # fmt: skip
    assert set(changed) == set(STEERING_ONLY_FIELDS)
    variants = [{name: value} for name, value in changed.items()] + [changed]
    for overrides in variants:
        other = NoSteeringEKF(replace(base, **overrides))
        assert pass_key(other) == key, overrides
        _assert_equal_results(run_estimator(other, frames), expected)
    assert pass_key(NoSteeringEKF(replace(base, camera_noise_std=0.1))) != key
    assert pass_key(GaussianMixtureEKF(None, base)) != key  # another class
    steering = GaussianMixtureEKF(GeneralizedModel.paper().arx(), base)
    for estimator in (steering, OracleEKF(None, base)):
        assert pass_key(estimator) is None
    assert reference.num_runs and pass_key(reference) is None  # it has run: no key
