"""An autoregressive equation error (hasa_env.steering.equation_error, docs/design.md §8.32):
estimated by the fit, kept in the model file, and whitened by the trust rule's filter."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.settings import FilterSettings
from estimators.trust import TrainingRecord, curvature_feedforward, trusted_filter
from hasa_env.steering import GeneralizedModel, ModelFileError, SteeringModel
from hasa_env.steering.equation_error import (
    check_equation_error_ar,
    equation_error_autoregression,
    innovation_variance_ratio,
    whitened_arx,
)

NOISE = (0.35, 0.25)
"""The simulated equation error's autoregression (stationary: roots 0.72, -0.35)."""


def _ar_series(ar, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = np.zeros(n + 200)
    white = rng.normal(size=out.size)
    for k in range(len(ar), out.size):
        out[k] = sum(r * out[k - i - 1] for i, r in enumerate(ar)) + white[k]
    return out[200:]


def _ararx_runs(runs: int = 3, n: int = 4000, seed: int = 0) -> list[pd.DataFrame]:
    """Feature frames of the paper's generalized model driven by white bearings and lateral
    velocity, with an AR(2) equation error of std 1e-4 rad."""
    arx = GeneralizedModel.paper().arx()
    rng = np.random.default_rng(seed)
    frames = []
    warm = 200  # left out: the start, where delta is not yet the model's
    for r in range(runs):
        phi, omega, vy = rng.normal(scale=(1e-3, 1e-3, 0.05), size=(n + warm, 3)).T
        error = 1e-4 * _ar_series(NOISE, n + warm, seed * 100 + r)
        delta = np.zeros(n + warm)
        for k in range(4, n + warm):
            delta[k] = (
                sum(a * delta[k - i - 1] for i, a in enumerate(arx.a))
                + sum(b * phi[k - i] for i, b in enumerate(arx.b))
                + sum(c * omega[k - i] for i, c in enumerate(arx.c))
                + sum(d * vy[k - i] for i, d in enumerate(arx.d))
                + error[k]
            )
        frames.append(
            pd.DataFrame({"delta": delta, "phi": phi, "omega": omega, "lateral_velocity": vy}).iloc[
                warm:
            ]
        )
    return frames


@pytest.fixture(scope="module")
def fitted() -> GeneralizedModel:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return GeneralizedModel(equation_error_order=2).fit(_ararx_runs(), ridge=0.0)


def test_yule_walker_recovers_an_ar2_pooled_over_runs_with_gaps() -> None:
    series = [_ar_series(NOISE, 30_000, seed) for seed in range(3)]
    series[1][100:120] = np.nan  # a gap: no pair across it counts
    assert equation_error_autoregression(series, 2) == pytest.approx(NOISE, abs=0.02)
    assert equation_error_autoregression(series, 0) == ()
    assert equation_error_autoregression([np.ones(5)], 2) == ()  # too few residuals
    with pytest.raises(ValueError, match="order must be in 0..10"):
        equation_error_autoregression(series, 11)


def test_the_innovation_variance_ratio_is_that_of_the_simulated_ar() -> None:
    assert innovation_variance_ratio(()) == 1.0
    assert innovation_variance_ratio((0.5,)) == pytest.approx(1 - 0.25)  # AR(1): 1 - r^2
    series = _ar_series(NOISE, 200_000, 7)
    assert innovation_variance_ratio(NOISE) == pytest.approx(1 / series.var(), rel=0.02)


@pytest.mark.parametrize(
    ("ar", "message"),
    [((1.2,), "not stationary"), ((0.5, 0.6), "not stationary"), ((math.nan,), "not finite")],
)
def test_a_bad_autoregression_is_named(ar, message) -> None:
    with pytest.raises(ValueError, match=message):
        check_equation_error_ar(ar)
    with pytest.raises(ValueError, match="at most 10 allowed"):
        check_equation_error_ar((0.0,) * 11)


@settings(max_examples=40, deadline=None)
@given(
    r1=st.floats(-0.6, 0.6),
    r2=st.floats(-0.3, 0.3),
)
def test_whitening_keeps_the_steady_state_and_the_lane_gain_ratio(r1: float, r2: float) -> None:
    arx = GeneralizedModel.paper().arx()
    white = whitened_arx(arx, (r1, r2))
    assert len(white.a) == len(arx.a) + 2 and len(white.b) == len(arx.b) + 2
    # R(1) multiplies both sides of the steady state: G is the model's
    assert curvature_feedforward(white, 2.7) == pytest.approx(
        curvature_feedforward(arx, 2.7), rel=1e-9
    )
    assert whitened_arx(arx, ()) is arx


def _residuals(arx, frame: pd.DataFrame) -> np.ndarray:
    args = [frame[c].to_numpy() for c in ("delta", "phi", "omega", "lateral_velocity")]
    return frame["delta"].to_numpy() - arx.predict(*args)


def test_the_fit_takes_the_autoregression_of_its_own_residuals(fitted: GeneralizedModel) -> None:
    # least squares on an ARX with a coloured error is biased (its a absorbs part of the
    # error's memory), so the residuals' AR is not the simulated one: it is what is left
    own = equation_error_autoregression([_residuals(fitted.arx(), f) for f in _ararx_runs()], 2)
    assert fitted.equation_error_ar == pytest.approx(own, rel=1e-9)
    frame = _ararx_runs(runs=1, seed=5)[0]
    residuals = {
        name: error[np.isfinite(error)]
        for name, error in (
            ("own", _residuals(fitted.arx(), frame)),
            ("whitened", _residuals(whitened_arx(fitted.arx(), fitted.equation_error_ar), frame)),
        )
    }
    lag = {k: [np.corrcoef(v[:-j], v[j:])[0, 1] for j in (1, 2)] for k, v in residuals.items()}
    assert max(lag["own"]) > 0.1
    assert max(np.abs(lag["whitened"])) < 0.05
    ratio = residuals["whitened"].var() / residuals["own"].var()
    assert ratio == pytest.approx(innovation_variance_ratio(fitted.equation_error_ar), rel=0.05)


def test_the_model_file_keeps_it_and_names_a_bad_one(fitted: GeneralizedModel, tmp_path) -> None:
    path = tmp_path / "model.json"
    fitted.save(path)
    loaded = SteeringModel.load(path)
    assert loaded == fitted and loaded.equation_error_ar == fitted.equation_error_ar
    assert loaded.structure()["equation_error_order"] == 2
    document = json.loads(path.read_text())
    document["equation_error"]["autoregression"] = [0.9, 0.5]
    with pytest.raises(ModelFileError, match=r"equation_error.autoregression.*not stationary"):
        SteeringModel.from_dict(document, "bad.json")
    # the paper's white error: no key, the file as before
    assert "equation_error" not in GeneralizedModel.paper().to_dict()
    assert "equation_error_order" not in GeneralizedModel().structure()
    with pytest.raises(
        ValueError, match=r"equation_error_order must be an integer in \[0, 10\], got 11"
    ):
        GeneralizedModel(equation_error_order=11)


def test_the_trust_rule_whitens_the_filters_form_and_level(fitted: GeneralizedModel) -> None:
    level = 1e-4
    trusted = trusted_filter(fitted, training=TrainingRecord(residual_std=level))
    assert trusted.arx == whitened_arx(fitted.arx(), fitted.equation_error_ar)
    ratio = innovation_variance_ratio(fitted.equation_error_ar)
    assert trusted.settings.steering_residual_std == pytest.approx(level * math.sqrt(ratio))
    assert any("whitened by its equation error's autoregression" in r for r in trusted.reasons)
    assert trusted.estimator().steering_model == trusted.arx
    # the user's level is the user's; a white model's filter is its own form
    mine = trusted_filter(fitted, overrides={"steering_residual_std": 3e-4})
    assert mine.settings.steering_residual_std == 3e-4
    plain = GeneralizedModel.paper()
    assert trusted_filter(plain).arx == plain.arx()
    assert trusted_filter(plain).settings.steering_residual_std == (
        FilterSettings.steering_residual_std
    )
    fitted_bad = GeneralizedModel.paper()
    fitted_bad.equation_error_ar = (1.5,)
    with pytest.raises(ValueError, match="not stationary"):
        trusted_filter(fitted_bad)


def test_the_benchmark_fits_its_generalized_model_with_the_configured_order() -> None:
    from benchmarks.protocol.config import BenchmarkError, ProtocolConfig
    from benchmarks.protocol.models import fit_models, load_models
    from hasa_env.drivers import SyntheticDriver, TwoPointParams, run_driver

    frames = run_driver(SyntheticDriver(TwoPointParams()), runs=1, seed=2)
    for order in (0, 2):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fitted_models, _ = fit_models(
                frames[0], load_models([], []), [], equation_error_order=order
            )
        models = {fm.name: fm.model for fm in fitted_models}
        assert len(models["generalized"].equation_error_ar) == order
        assert models["two_point"].equation_error_ar == ()  # the paper's two-point as it is
    assert ProtocolConfig().equation_error_order == 2
    with pytest.raises(BenchmarkError, match="equation_error_order"):
        ProtocolConfig(equation_error_order=11)


def test_a_declared_autoregression_that_predicts_worse_is_ignored(
    fitted: GeneralizedModel,
) -> None:
    from estimators.tuning import whitened_residual_std

    runs = _ararx_runs()
    # features frames stand in for recordings here: score the forms directly
    own = float(
        np.sqrt(np.nanmean(np.concatenate([_residuals(fitted.arx(), f) for f in runs]) ** 2))
    )
    white = whitened_arx(fitted.arx(), fitted.equation_error_ar)
    right = float(np.sqrt(np.nanmean(np.concatenate([_residuals(white, f) for f in runs]) ** 2)))
    assert right < own  # the fitted autoregression lowers the one-step residual
    trusted = trusted_filter(
        fitted, training=TrainingRecord(residual_std=own, whitened_residual_std=right)
    )
    assert trusted.arx == white
    ratio = innovation_variance_ratio(fitted.equation_error_ar)
    assert trusted.settings.steering_residual_std == pytest.approx(own * math.sqrt(ratio))
    assert right == pytest.approx(own * math.sqrt(ratio), rel=0.05)  # what Yule-Walker says
    # a declaration of the wrong sign predicts worse: the filter keeps the model's own form
    bogus = GeneralizedModel.paper()
    bogus.equation_error_ar = (-0.6, 0.3)
    wrong = trusted_filter(
        bogus, training=TrainingRecord(residual_std=own, whitened_residual_std=2 * own)
    )
    assert wrong.arx == bogus.arx()
    assert wrong.settings.steering_residual_std == pytest.approx(own)
    assert any("autoregression r = (-0.6, 0.3) ignored" in r for r in wrong.reasons)
    assert whitened_residual_std(GeneralizedModel.paper(), runs) is None  # none declared


DECLARING_MODULE = """
from hasa_env.steering import GeneralizedModel


class {name}(GeneralizedModel):
    model_type = "test_{module}"

    def fit(self, runs, road=None, **options):
        fitted = super().fit(runs, road=road, **options)
        fitted.equation_error_ar = {ar!r}  # not its residuals' autoregression
        return fitted
"""
"""A user model that declares an equation-error autoregression its fit did not estimate."""

TINY_BENCH = ["--seed", "0", "--population", "paper-pi", "--drivers", "2", "--runs", "1",
              "--ill-runs", "2", "--duration", "6", "--curved-runs", "0",
              "--training-drivers", "1", "--no-plots", "--quiet"]  # fmt: skip


def _score_declaring_model(
    tmp_path, monkeypatch, module: str, name: str, ar: tuple[float, ...]
) -> tuple[int, str, dict, Path]:
    """``hasa-bench score`` of a :data:`DECLARING_MODULE` model on a tiny protocol: (exit
    status, its spec, results.json, the output folder)."""
    from hasa_cli.bench import main

    (tmp_path / f"{module}.py").write_text(DECLARING_MODULE.format(name=name, module=module, ar=ar))
    monkeypatch.syspath_prepend(str(tmp_path))
    out, spec = tmp_path / "out", f"{module}:{name}"
    code = main(["score", spec, *TINY_BENCH, "--out", str(out)])
    return code, spec, json.loads((out / "results.json").read_text()), out


def test_hasa_bench_ignores_a_user_models_wrong_declaration(tmp_path, monkeypatch) -> None:
    code, spec, doc, out = _score_declaring_model(
        tmp_path, monkeypatch, "wrong_sign_noise", "WrongSignNoise", (-0.6, 0.3)
    )
    assert code == 0
    models = {m["name"]: m for m in doc["models"]}
    wrong = models[spec]
    assert wrong["whitened_residual_std"] > wrong["filter_residual_std"]
    assert any("ignored" in reason for reason in wrong["steering_trust"])
    own = models["generalized"]  # the built-in's fitted AR(2) lowers its residual: taken
    assert own["whitened_residual_std"] < own["filter_residual_std"]  # (the tiny protocol's
    assert any("whitened by its equation error" in r for r in own["steering_trust"])  # runs
    assert own["speed_scaled_error"] is None  # do not identify the speed-scaled error, §8.34)
    by_speed = own["residual_by_speed"]  # on the same training runs as filter_residual_std
    assert by_speed and all(b["samples"] >= 200 and b["residual_rms"] > 0 for b in by_speed)
    assert "steering residual by speed (training runs" in (out / "report.md").read_text()


def test_hasa_bench_names_and_skips_a_non_stationary_declaration(tmp_path, monkeypatch) -> None:
    from hasa_cli import EXIT_PARTIAL

    code, spec, doc, _ = _score_declaring_model(
        tmp_path, monkeypatch, "non_stationary_noise", "NonStationaryNoise", (1.5,)
    )
    assert code == EXIT_PARTIAL
    (error,) = doc["errors"]
    assert error["model"] == spec and error["stage"] == "fit"
    assert "autoregression (1.5,) is not stationary" in error["message"]
    assert {r["model"] for r in doc["estimation"]} >= {"generalized", "two_point"}


@pytest.fixture(scope="module")
def slow_and_fast_runs() -> list[pd.DataFrame]:
    """One run of a population driver that holds 15 m/s and one that holds 40 m/s."""
    from hasa_env.drivers import SyntheticDriver, population, run_driver

    (params,) = population("paper", 3, 1)
    return [
        run_driver(
            SyntheticDriver(params),
            runs=1,
            seed=seed,
            config={"initial_state": {"speed": speed}, "time_limit": 20.0},
        )[0]
        for seed, speed in ((1, 15.0), (2, 40.0))
    ]


def test_residuals_by_speed_bin_them_and_agree_with_the_one_level(slow_and_fast_runs) -> None:
    """estimators.tuning.steering_residuals_by_speed (results.json models[].residual_by_speed,
    design §8.33): the slow run's residuals are larger than the fast one's (the population's
    command noise scales by (15 / v)^2); one bin over every speed gives the filter's one level
    and the lag-1 autocorrelation of the residuals themselves."""
    from estimators.tuning import (
        steering_residual_std,
        steering_residuals,
        steering_residuals_by_speed,
    )

    arx = GeneralizedModel.paper().arx()
    runs = slow_and_fast_runs
    bins = steering_residuals_by_speed(arx, runs, steering_ratio=15.0)
    assert [b["speed_low"] for b in bins][0] < 20.0 and bins[-1]["speed_low"] >= 35.0
    assert all(b["speed_high"] == b["speed_low"] + 5.0 for b in bins)
    slow = max(b["residual_rms"] for b in bins if b["speed_high"] <= 20.0)
    fast = max(b["residual_rms"] for b in bins if b["speed_low"] >= 35.0)
    assert slow > 1.3 * fast  # 1.7x with the preset (its own mismatch at every speed)
    (one,) = steering_residuals_by_speed(arx, runs, steering_ratio=15.0, bin_width=1000.0)
    residuals = [steering_residuals(arx, r, steering_ratio=15.0) for r in runs]
    assert one["samples"] == sum(r.size for r in residuals)
    assert one["residual_rms"] == pytest.approx(
        steering_residual_std(arx, runs, steering_ratio=15.0), rel=1e-12
    )
    lag1 = sum(float(r[1:] @ r[:-1]) for r in residuals) / sum(
        float(r[1:] @ r[1:]) for r in residuals
    )
    assert one["lag1_autocorrelation"] == pytest.approx(lag1, rel=1e-9)
    assert steering_residuals_by_speed(arx, runs, steering_ratio=15.0, min_samples=10**9) == []
    with pytest.raises(ValueError, match="bin_width must be a finite number > 0 m/s, got 0"):
        steering_residuals_by_speed(arx, runs, bin_width=0.0)
    with pytest.raises(ValueError, match="run 1 has no 'speed' column"):
        steering_residuals_by_speed(arx, [runs[0], runs[1].drop(columns="speed")])
