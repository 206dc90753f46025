"""One car's filter step in Python floats gives the batch's numbers, to the bit.

A single run's arrays hold a few numbers, where numpy's per-call overhead dominates, so the
mixture filter does some of one run's arithmetic in Python floats
(:mod:`estimators.small_arrays`, ``_features_in_floats``, ``_inverse_3x3_in_floats`` and
``_update_terms_in_floats`` of :mod:`estimators.filter_matrices`, one run's whole evidence rule
with the aim cap in :mod:`estimators.evidence`): the same IEEE operations in the same order as
numpy's, so the same bits. Each is compared with the numpy arithmetic it replaces, and a run
filtered alone (the float paths) with the same run inside a batch large enough for the numpy
paths, at every step and in every output, with the aim cap on, tight and off.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

from benchmarks.protocol.config import ProtocolConfig
from benchmarks.protocol.plan import load_frames, synthetic_plan
from estimators import Estimate, FilterSettings, GaussianMixtureEKF
from estimators.evidence import _logaddexp, _normalized_one
from estimators.filter_matrices import (
    _LOG_2PI,
    _MAX_ROWS_IN_FLOATS,
    FilterMatrices,
    _inverse_3x3,
    _inverse_3x3_in_floats,
    _update_terms_in_floats,
    filter_model,
)
from estimators.offline import run_estimator, stack_recordings
from estimators.small_arrays import (
    SMALL_SIZE,
    all_finite,
    all_true,
    all_within,
    any_equal,
    any_nan,
    any_true,
    min_below,
)
from hasa_env.steering.models import GeneralizedModel, TwoPointModel

SEED = 5100


def test_logaddexp_in_floats_is_numpys() -> None:
    rng = np.random.default_rng(SEED)
    for n_comp in (2, 3, 8):
        log_w = rng.standard_normal((4000, n_comp)) * 10.0 ** rng.uniform(-3, 3, (4000, 1))
        log_w[::7, 1] = log_w[::7, 0]  # equal entries: numpy's special case
        log_w[::11, 0] = -np.inf  # a pruned hypothesis
        total = np.logaddexp.reduce(log_w, axis=1)
        for row, expected in zip(log_w.tolist(), total.tolist(), strict=True):
            ours = row[0]
            for value in row[1:]:
                ours = _logaddexp(ours, value)
            assert ours == expected
            normalized = _normalized_one(row)
            np.testing.assert_array_equal(normalized, np.array(row) - expected)
    assert _normalized_one([-np.inf, -np.inf]) == []  # the caller's fallback


def test_inverse_and_distance_in_floats_are_numpys() -> None:
    rng = np.random.default_rng(SEED + 1)
    for _ in range(3000):
        n_rows = int(rng.integers(1, _MAX_ROWS_IN_FLOATS + 1))
        root = rng.standard_normal((n_rows, 3, 3))
        s = (root @ root.transpose(0, 2, 1)).reshape(n_rows, 9) + 0.1 * np.eye(3).ravel()
        s += 1e-6 * rng.standard_normal((n_rows, 9))  # not quite symmetric
        s *= 10.0 ** rng.uniform(-5, 3)
        v = rng.standard_normal((n_rows, 3)) * 10.0 ** rng.uniform(-3, 2)
        v[:, rng.integers(0, 3)] *= rng.integers(0, 2)  # a missing channel: innovation 0
        inverse, det, distance, normalized = _inverse_3x3_in_floats(s, v)
        # the numpy path: the same rows in a batch too large for the floats
        tiled = _inverse_3x3(np.tile(s, (_MAX_ROWS_IN_FLOATS + 1, 1)))
        assert tiled[2] is None and tiled[3] is None
        np.testing.assert_array_equal(inverse, tiled[0][:n_rows])
        np.testing.assert_array_equal(det, tiled[1][:n_rows])
        np.testing.assert_array_equal(distance, np.einsum("bi,bij,bj->b", v, inverse, v))
        np.testing.assert_array_equal(normalized, v / np.sqrt(s[:, ::4]))
    for singular in (np.zeros((1, 9)), -np.eye(3).reshape(1, 9)):  # no inverse; no sqrt
        with np.errstate(divide="ignore", invalid="ignore"):
            inverse, det, distance, normalized = _inverse_3x3(singular, np.ones((1, 3)))
        assert distance is None and normalized is None


def test_update_terms_in_floats_are_numpys() -> None:
    """S = s + diag(R), its inverse, nu^T S^-1 nu, nu_c / sqrt(S_cc) and the log-likelihoods
    of a few filters in floats are the numpy path's, with every channel observed (R (3,), m
    a float) and with missing ones (R (B, 3), m per filter)."""
    rng = np.random.default_rng(SEED + 4)
    for trial in range(3000):
        n_rows = int(rng.integers(1, _MAX_ROWS_IN_FLOATS + 1))
        root = rng.standard_normal((n_rows, 3, 3))
        s = (root @ root.transpose(0, 2, 1)).reshape(n_rows, 9) * 10.0 ** rng.uniform(-5, 3)
        v = rng.standard_normal((n_rows, 3)) * 10.0 ** rng.uniform(-3, 2)
        r: np.ndarray = rng.uniform(1e-4, 1.0, 3)
        n_obs: float | np.ndarray = 3.0
        if trial % 2:  # missing channels: innovation 0, variance 1, m counts the others
            observed = rng.random((n_rows, 3)) < 0.7
            v, r = np.where(observed, v, 0.0), np.where(observed, r, 1.0)
            n_obs = observed.sum(axis=1)
        inverse, s_diag, log_lik, distance, normalized = _update_terms_in_floats(s, r, v, n_obs)
        with_r = s.copy()
        with_r[:, ::4] += r
        tiles = _MAX_ROWS_IN_FLOATS + 1  # the numpy path: a batch too large for the floats
        numpy_inverse, det, _, _ = _inverse_3x3(np.tile(with_r, (tiles, 1)))
        numpy_inverse, det = numpy_inverse[:n_rows], det[:n_rows]
        expected_distance = np.einsum("bi,bij,bj->b", v, numpy_inverse, v)
        expected = expected_distance + np.log(det)
        expected += n_obs * _LOG_2PI
        expected *= -0.5
        np.testing.assert_array_equal(inverse, numpy_inverse)
        np.testing.assert_array_equal(s_diag, with_r[:, ::4])
        np.testing.assert_array_equal(distance, expected_distance)
        np.testing.assert_array_equal(normalized, v / np.sqrt(with_r[:, ::4]))
        np.testing.assert_array_equal(log_lik, expected)
    for s in (-np.eye(3).reshape(1, 9), -2.0 * np.eye(3).reshape(1, 9)):  # S = 0; S = -I
        with pytest.raises((ZeroDivisionError, ValueError)):  # as the inverse (numpy's then)
            _update_terms_in_floats(s, np.ones(3), np.ones((1, 3)), 3.0)
        with pytest.raises((ZeroDivisionError, ValueError)):
            _inverse_3x3_in_floats(s + np.eye(3).reshape(1, 9), np.ones((1, 3)))


def test_estimate_of_fields_is_the_dataclass() -> None:
    rng = np.random.default_rng(SEED + 5)
    root = rng.standard_normal((2, 8, 8))
    fields = {"mean": rng.standard_normal(8), "component_means": rng.standard_normal((2, 8)),
              "component_covariances": root @ root.transpose(0, 2, 1), "weights": np.ones(2) / 2,
              "log_weights": np.log(np.ones(2) / 2), "most_likely": 1,
              "hypotheses": np.array([0.0, -3.6]), "state_names": tuple("abcdefgh"),
              "decision": "decided", "model_error": 1.5, "innovation_autocorrelation": 0.2,
              "evidence_scale": 3.0}  # fmt: skip
    ours, theirs = Estimate.of_fields(**fields), Estimate(**fields)
    assert set(fields) == {field.name for field in dataclasses.fields(Estimate)}
    assert vars(ours) == vars(theirs) and repr(ours) == repr(theirs)
    np.testing.assert_array_equal(ours.covariance, theirs.covariance)
    np.testing.assert_array_equal(ours.std, theirs.std)


@pytest.mark.parametrize("preferred_offset_std", [0.0, 0.3])
@pytest.mark.parametrize("curved", [False, True])
def test_bearing_features_in_floats_are_numpys(preferred_offset_std, curved) -> None:
    settings = FilterSettings(steering_ratio=15.0, preferred_offset_std=preferred_offset_std)
    model = filter_model(GeneralizedModel.paper().arx(), settings, None, 1)
    matrices = FilterMatrices(model, settings)
    rng = np.random.default_rng(SEED + 2)
    for _ in range(300):
        n_rows = int(rng.integers(1, _MAX_ROWS_IN_FLOATS + 1))
        x = rng.standard_normal((n_rows, model.n_states))
        x[:, 0] = rng.choice([0.0, 1e-7, 15.0, np.nan]) + x[:, 0]  # speeds near zero, NaN
        points = None
        if curved:
            points = np.column_stack([np.full(n_rows, 8.0), rng.standard_normal(n_rows),
                                      np.full(n_rows, 25.0), rng.standard_normal(n_rows)])  # fmt: skip
        speed = np.hypot(x[:, 0], x[:, 2]) if rng.random() < 0.5 else None
        w, deriv = matrices._features(x, points, speed)
        tiles = _MAX_ROWS_IN_FLOATS + 1
        w_all, deriv_all = matrices._features(
            np.tile(x, (tiles, 1)),
            None if points is None else np.tile(points, (tiles, 1)),
            None if speed is None else np.tile(speed, tiles),
        )
        np.testing.assert_array_equal(w, w_all[:n_rows])
        np.testing.assert_array_equal(deriv, deriv_all[:n_rows])


def test_small_array_tests_answer_as_numpy() -> None:
    rng = np.random.default_rng(SEED + 3)
    for size in (1, 2, 3, 6, SMALL_SIZE, SMALL_SIZE + 1, 40):
        for _ in range(200):
            values = rng.standard_normal(size) * 3.0
            values[rng.random(size) < 0.1] = rng.choice([np.nan, np.inf, -np.inf])
            mask = rng.random(size) < rng.choice([0.0, 0.2, 1.0])
            assert any_true(mask) == bool(mask.any())
            assert all_true(mask) == bool(mask.all())
            assert all_finite(values) == bool(np.isfinite(values).all())
            assert all_within(values, 2.0) == bool(np.abs(values).max() <= 2.0)
            assert min_below(values, -1.0) == bool(values.min() < -1.0)
            no_inf = np.where(np.isinf(values), 0.0, values)
            assert any_nan(no_inf) == bool(np.isnan(no_inf).any())
            codes = rng.integers(-1, 3, size)
            assert any_equal(codes, 2) == bool((codes == 2).any())


@pytest.fixture(scope="module")
def frames() -> list[pd.DataFrame]:
    """Curved and straight runs with missing, non-finite and outlying readings."""
    config = ProtocolConfig(seeds=(SEED,), drivers=2, runs=2, ill_runs=1, duration=3.0,
                            curved_runs=2, scenario="lane_shift")  # fmt: skip
    plan = synthetic_plan(config, SEED)
    runs = [f.copy() for f in [*load_frames(plan.curved, "curved", plan.env_config, plan.params),
                               *load_frames(plan.main, "straight", plan.env_config, plan.params)]]  # fmt: skip
    rng = np.random.default_rng(SEED)
    for run in runs[1::2]:
        rows = rng.choice(np.arange(5, len(run)), size=12, replace=False)
        run.loc[rows[:4], "sensor_steering"] = np.nan
        run.loc[rows[4:6], "sensor_camera_lateral"] = np.inf
        run.loc[rows[6:9], "sensor_camera_lateral"] += 3.0  # outliers: gated
        run.loc[rows[9:], "sensor_imu_lateral"] = np.nan
    return runs


def _outputs(ekf: GaussianMixtureEKF, est, run: int | None) -> list[np.ndarray]:
    """Every output of the filter after a step, of ``run`` of a batch (None: a single run)."""
    pick = (lambda a: np.asarray(a)) if run is None else (lambda a: np.asarray(a)[run])
    state = ekf.mixture_state
    rows = slice(None) if run is None else slice(run, run + 1)
    out = [pick(getattr(est, name)) for name in ("mean", "component_means", "weights",
           "log_weights", "most_likely", "decision", "model_error", "innovation_autocorrelation",
           "evidence_scale", "covariance")]  # fmt: skip
    out += [pick(getattr(ekf, name)) for name in ("gated_counts", "last_gated", "channel_nis",
            "decision_codes", "withheld_decisions", "low_speed")]  # fmt: skip
    out.append(pick(est.component_covariances))
    out += [state.steering[rows], state.innovation_log_w[rows], state.normalized_innovation[rows]]
    # (not ``_candidate``: once a run committed its decision the single-run path of the reversal
    # rule stops counting the steps its candidate held, which nothing reads any more)
    out += [state.evidence[name][rows] for name in sorted(state.evidence) if name != "_candidate"]
    return out


@pytest.mark.parametrize(
    ("model", "overrides"),
    [
        ("generalized", {}),
        ("generalized", {"min_speed": 12.0, "innovation_gate": 2.5}),
        ("generalized", {"mismatch_model_error": 1.05, "commit_time": 0.2}),
        ("two-point", {"steering_curvature_limit": 0.004, "max_acceleration": 3.0}),
        ("two-point", {"evidence_checks": False, "preferred_offset_std": 0.3}),
        ("generalized", {"aim_offset_std": 0.0}),
        ("generalized", {"aim_offset_std": 0.1, "aim_offset_time": 0.5, "commit_time": 0.2}),
        ("two-point", {"aim_offset_std": 0.15, "mismatch_model_error": 1.05}),
    ],
)
def test_a_run_alone_is_filtered_as_in_a_large_batch(frames, model, overrides) -> None:
    arx = {"generalized": GeneralizedModel.paper().arx(), "two-point": TwoPointModel.paper().arx()}
    settings = FilterSettings.from_env_config(frames[0].attrs["config"], steering_ratio=15.0,
                                              **overrides)  # fmt: skip
    batch_frames = (frames * 3)[:9]  # 9 runs x 2 hypotheses: the numpy paths (> SMALL_SIZE)
    stacked = stack_recordings(batch_frames)
    n_runs, n_steps = len(batch_frames), int(stacked.lengths.min())
    batch = GaussianMixtureEKF(arx[model], settings)
    alone = [GaussianMixtureEKF(arx[model], settings) for _ in range(n_runs)]
    run_estimator(batch, stacked)  # computes the road points of the tracks
    points = next(v for v in stacked.road_points.values() if v is not None)
    z, acc = stacked.measurements, stacked.accelerations
    hypotheses = [0.0, -3.6]
    est = batch.reset(z[:, 0], hypotheses, road_points=points[:, 0])
    alone_est = [f.reset(z[r, 0], hypotheses, road_points=points[r, 0])
                 for r, f in enumerate(alone)]  # fmt: skip
    assert n_runs * len(hypotheses) > max(SMALL_SIZE, _MAX_ROWS_IN_FLOATS)
    for k in range(1, n_steps):
        est = batch.step(z[:, k], acc[:, k], road_points=points[:, k])
        for r, f in enumerate(alone):
            alone_est[r] = f.step(z[r, k], acc[r, k], road_points=points[r, k])
            for i, (ours, theirs) in enumerate(
                zip(_outputs(f, alone_est[r], None), _outputs(batch, est, r), strict=True)
            ):
                np.testing.assert_array_equal(ours, theirs, err_msg=f"step {k} run {r} output {i}")
    assert math.isfinite(float(np.asarray(est.mean).sum()))
