"""The benchmark's task planning (near-equal chunks, the largest task first, the seeds' fits
in parallel) and the filter's decision codes that the offline runner stores."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from benchmarks.protocol import tasks
from benchmarks.protocol.config import ProtocolConfig
from benchmarks.protocol.models import FittedModel, load_models
from benchmarks.protocol.plan import RunRef, chunks, load_frames, synthetic_plan
from benchmarks.protocol.run import chunk_tasks, fit_seeds
from estimators import FilterSettings, GaussianMixtureEKF
from estimators.baselines import NoSteeringEKF, OracleEKF
from estimators.evidence import DECISIONS
from estimators.offline import run_estimator
from hasa_env.steering.models import GeneralizedModel, TwoPointModel


def _runs(count: int) -> list[RunRef]:
    return [RunRef("1", "straight", i) for i in range(count)]


@pytest.mark.parametrize(
    ("count", "size", "lengths"),
    [(97, 48, [33, 32, 32]), (93, 100, [93]), (93, 48, [47, 46]), (4, 100, [4]), (0, 5, []),
     (6, 2, [2, 2, 2]), (7, 3, [3, 2, 2])],
)  # fmt: skip
def test_chunks_are_the_fewest_near_equal_ones_in_order(count, size, lengths) -> None:
    runs = _runs(count)
    cut = chunks(runs, size)
    assert [len(c) for c in cut] == lengths
    assert [r for c in cut for r in c] == runs  # every run once, in order


def test_chunks_refuse_a_size_below_one() -> None:
    with pytest.raises(ValueError, match="chunk size"):
        chunks(_runs(3), 0)


SMALL = {"seeds": (3100, 3101, 3102), "drivers": 3, "runs": 2, "ill_runs": 3, "duration": 4.0,
         "curved_runs": 1, "population": "paper-pi"}  # fmt: skip


@pytest.mark.slow
def test_fits_in_parallel_equal_the_fits_one_after_another() -> None:
    config = ProtocolConfig(**SMALL)
    errors: list = []
    candidates = load_models([], errors, time_limit=config.model_time_limit)
    calls: list[tuple] = []
    serial = fit_seeds(config, candidates, errors, lambda *c: None, workers=1)
    parallel = fit_seeds(config, candidates, errors, lambda *c: calls.append(c), workers=2)
    assert not errors
    assert [c for c in calls if c[0] == "fits"][-1] == ("fits", 3, 3)
    assert [f.plan.seed for f in parallel] == [3100, 3101, 3102]
    for one, two in zip(serial, parallel, strict=True):
        assert one.infos == two.infos  # the same fitted coefficients and checks, seed by seed
        assert one.lane_centring == two.lane_centring
        # one task per seed: its curved run and its validation runs (6), tracks mixed
        tasks = chunk_tasks(config, two, False)
        assert [len(t.runs) for t in tasks] == [7]
        assert [r.track for r in tasks[0].runs] == ["curved"] + ["straight"] * 6


def test_decision_codes_name_the_estimate_decision() -> None:
    rng = np.random.default_rng(5)
    runs, steps = 4, 200
    ekf = GaussianMixtureEKF(GeneralizedModel.paper().arx(), FilterSettings(steering_ratio=15.0))
    z = np.stack(
        [
            15.0 + 0.05 * rng.standard_normal((steps, runs)),
            -0.5 + 0.05 * rng.standard_normal((steps, runs)),
            0.002 * rng.standard_normal((steps, runs)),
        ],
        axis=-1,
    )
    z[:, 1, 2] += 0.05  # one run's steering explains one lane far better: it decides
    est = ekf.reset(z[0], [0.0, -1.8])
    seen = set()
    for k in range(1, steps):
        est = ekf.step(z[k], 0.05 * rng.standard_normal((runs, 2)))
        codes = ekf.decision_codes
        assert codes.shape == (runs,)
        assert list(np.asarray(DECISIONS)[codes]) == list(est.decision)
        seen |= set(est.decision)
    assert len(seen) > 1, "every step undecided: the test checks one code only"


def test_a_batch_mixing_tracks_filters_each_straight_run_as_alone() -> None:
    """A task's curved and straight runs are filtered in one batch (the curved ones with their
    road points, the straight ones with the straight road's (near, 0, far, 0)): every straight
    run's estimate is the one it gets in a batch of straight runs, to the bit."""
    config = ProtocolConfig(seeds=(3701,), drivers=2, runs=1, ill_runs=1, duration=3.0,
                            curved_runs=1)  # fmt: skip
    plan = synthetic_plan(config, 3701)
    straight = load_frames(plan.main, "straight", plan.env_config, plan.params)
    curved = load_frames(plan.curved, "curved", plan.env_config, plan.params)
    settings = FilterSettings.from_env_config(straight[0].attrs["config"], steering_ratio=15.0)
    for model in (GeneralizedModel.paper().arx(), None):
        alone = run_estimator(GaussianMixtureEKF(model, settings), straight)
        mixed = run_estimator(GaussianMixtureEKF(model, settings), [*curved, *straight])
        names = ("mean", "std", "weights", "decision", "model_error", "evidence_scale",
                 "channel_nis", "gated", "low_speed", "withheld")  # fmt: skip
        for name in names:
            ours, theirs = getattr(alone, name), getattr(mixed, name)
            assert (ours is None) == (theirs is None), name
            if ours is not None:
                np.testing.assert_array_equal(ours, theirs[len(curved) :], err_msg=name)


def test_a_task_runs_each_distinct_filter_pass_once(monkeypatch) -> None:
    """A task's filters of equal :func:`~estimators.offline.pass_key` (the no-steering
    filters of the models the trust rule refuses, the no-steering baseline) share one pass:
    each gets a copy of its result, equal to the bit to a pass of its own."""
    config = ProtocolConfig(seeds=(5005,), drivers=2, runs=1, ill_runs=1, duration=3.0,
                            curved_runs=1)  # fmt: skip
    plan = synthetic_plan(config, 5005)
    frames = [*load_frames(plan.curved, "curved", plan.env_config, plan.params),
              *load_frames(plan.main, "straight", plan.env_config, plan.params)]  # fmt: skip
    stacks = tasks._Stacks(frames)
    passes: list[object] = []
    real_run = tasks.run_estimator
    monkeypatch.setattr(
        tasks, "run_estimator", lambda est, stacked: passes.append(est) or real_run(est, stacked)
    )
    base = FilterSettings.from_env_config(frames[0].attrs["config"])
    indices = [i for group in stacks.groups.values() for i in group]
    assert len(stacks.groups) == 1, "one settings group expected"
    refused = stacks.run(NoSteeringEKF(replace(base, steering_residual_std=1.4e-4)), indices)
    baseline = stacks.run(NoSteeringEKF(base), indices)
    assert len(passes) == 1
    fresh = real_run(NoSteeringEKF(base), frames)
    for result in (refused, baseline):
        for name in ("mean", "std", "weights", "decision", "model_error", "channel_nis"):
            np.testing.assert_array_equal(getattr(result, name), getattr(fresh, name), name)
    refused.mean[:] = np.nan  # a caller's changes stay its own
    again = stacks.run(NoSteeringEKF(base), indices)
    np.testing.assert_array_equal(again.mean, fresh.mean)
    assert again is not baseline and again.mean is not baseline.mean
    stacks.run(OracleEKF(None, base), indices)  # not shared: a pass of its own
    stacks.run(GaussianMixtureEKF(GeneralizedModel.paper().arx(), base), indices)
    assert len(passes) == 3


def test_models_of_the_same_features_share_them_and_score_as_alone() -> None:
    """A task computes each run's steering features once for the models that take the same
    ones (look-ahead distances, decision lag, steering signal), and their finite rows and the
    driver's own numbers once per run: every model's rows, predictions and residuals are
    those it gets scoring alone, to the bit."""
    config = ProtocolConfig(seeds=(5006,), drivers=2, runs=1, ill_runs=1, duration=3.0,
                            curved_runs=1)  # fmt: skip
    plan = synthetic_plan(config, 5006)
    runs = [*plan.curved, *plan.main]
    frames = [*load_frames(plan.curved, "curved", plan.env_config, plan.params),
              *load_frames(plan.main, "straight", plan.env_config, plan.params)]  # fmt: skip
    models = [
        GeneralizedModel.paper(),
        TwoPointModel.paper(),
        GeneralizedModel.paper(far_distance=25.0),
    ]
    fitted = [FittedModel(f"m{i}", "builtin", m, 1e-3) for i, m in enumerate(models)]
    task = tasks.ChunkTask(
        seed=5006, runs=tuple(runs), env_config=plan.env_config, driver_params=plan.params,
        models=tuple(fitted), estimate=True, ljung_box_lags=20, acf_lags=20,
        weight_threshold=0.95, error_window=2.0, trace_runs=frozenset(),
        detail_driver=plan.illustrative,
    )  # fmt: skip
    stacks = tasks._Stacks(frames)
    for fm in fitted:
        shared, alone = tasks.ChunkResult(), tasks.ChunkResult()
        ours = tasks._score_model(fm, task, frames, shared, stacks)
        theirs = tasks._score_model(fm, task, frames, alone)
        assert pd.DataFrame(shared.steering).equals(pd.DataFrame(alone.steering))
        for mine, other in zip(ours[0] + ours[1], theirs[0] + theirs[1], strict=True):
            np.testing.assert_array_equal(mine, other)
        for mine, other in zip(shared.acf[fm.name], alone.acf[fm.name], strict=True):
            np.testing.assert_array_equal(mine, other)
    # the two paper models share each run's features; the far-sighted one has its own
    assert len(stacks._features) == 2 * len(frames)
    assert stacks.features(models[0], 0) is stacks.features(models[1], 0)
