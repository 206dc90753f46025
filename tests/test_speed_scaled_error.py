"""The equation error as a coloured part scaled by the speed plus a white part
(hasa_env.steering.equation_error.SpeedScaledError, docs/design.md §8.34): fitted by maximum
likelihood, kept in the model file, checked against the data and carried by the filter."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from estimators.trust import TrainingRecord, trusted_filter
from hasa_env.steering import GeneralizedModel, ModelFileError, SteeringModel
from hasa_env.steering.equation_error import (
    SpeedScaledError,
    speed_scale,
    speed_scaled_error,
    speed_scaled_log_likelihood,
)

TRUE = SpeedScaledError(coloured_std=1e-4, correlation=0.6, white_std=3e-5)


def _simulated(error: SpeedScaledError, runs: int = 4, n: int = 3000, seed: int = 0):
    """Residuals e = s(v) c + w on runs whose speed ramps between 12 and 40 m/s."""
    rng = np.random.default_rng(seed)
    residuals, speeds = [], []
    for r in range(runs):
        speed = np.linspace(12.0, 40.0, n)[:: 1 if r % 2 == 0 else -1]
        c = np.empty(n)
        c[0] = rng.normal(scale=error.coloured_std)
        step = error.coloured_std * math.sqrt(1 - error.correlation**2)
        for k in range(1, n):
            c[k] = error.correlation * c[k - 1] + rng.normal(scale=step)
        e = speed_scale(speed, error.reference_speed) * c + rng.normal(
            scale=error.white_std, size=n
        )
        e[:5] = np.nan  # a run's first samples have no residual
        residuals.append(e)
        speeds.append(speed)
    return residuals, speeds


def test_the_fit_recovers_a_simulated_error() -> None:
    residuals, speeds = _simulated(TRUE)
    fitted = speed_scaled_error(residuals, speeds)
    assert fitted is not None and fitted.samples == 4 * 2995
    assert fitted.coloured_std == pytest.approx(TRUE.coloured_std, rel=0.1)
    assert fitted.correlation == pytest.approx(TRUE.correlation, abs=0.05)
    assert fitted.white_std == pytest.approx(TRUE.white_std, rel=0.1)
    again, count = speed_scaled_log_likelihood(fitted, residuals, speeds)
    assert count == fitted.samples and again == pytest.approx(fitted.log_likelihood, rel=1e-9)
    truth, _ = speed_scaled_log_likelihood(TRUE, residuals, speeds)
    assert truth <= fitted.log_likelihood  # the maximum


def test_too_few_residuals_give_none_and_mismatched_runs_are_named() -> None:
    residuals, speeds = _simulated(TRUE, runs=1, n=300)
    assert speed_scaled_error(residuals, speeds) is None
    with pytest.raises(ValueError, match="300 residuals but 299 speeds"):
        speed_scaled_error(residuals, [speeds[0][1:]])


def test_a_fit_on_the_boundary_is_not_identified() -> None:
    rng = np.random.default_rng(1)
    walks = [np.cumsum(rng.normal(scale=1e-5, size=3000)) for _ in range(2)]  # no white part
    assert speed_scaled_error(walks, [np.full(3000, 20.0)] * 2) is None


def test_the_gain_over_one_white_level_tells_a_true_declaration_from_a_bogus_one() -> None:
    from estimators.tuning import speed_scaled_gain

    frames = _closed_loop_frames()
    model = GeneralizedModel().fit(frames)
    assert speed_scaled_gain(model, frames) is None  # none declared
    model.equation_error_speed_scaled = speed_scaled_error(*_residuals_of(model, frames))
    assert model.equation_error_speed_scaled is not None  # its own residuals' error
    assert speed_scaled_gain(model, frames) > 0
    model.equation_error_speed_scaled = SpeedScaledError(1e-7, 0.5, 1e-7)  # far too small
    assert speed_scaled_gain(model, frames) < 0


def _closed_loop_frames():  # noqa: ANN202
    from hasa_env.drivers import SyntheticDriver, population, run_driver

    return run_driver(SyntheticDriver(population("paper", seed=0)[0]), runs=2, seed=4)


def _residuals_of(model, frames):  # noqa: ANN001, ANN202
    from estimators.tuning import residuals_and_speeds

    found = residuals_and_speeds(model, frames, 1.0)
    assert found is not None
    return found


def test_the_model_file_keeps_it_and_names_a_bad_one(tmp_path) -> None:
    model = GeneralizedModel.paper()
    model.equation_error_speed_scaled = TRUE
    path = tmp_path / "model.json"
    model.save(path)
    loaded = SteeringModel.load(path)
    kept = loaded.equation_error_speed_scaled
    assert (kept.coloured_std, kept.correlation, kept.white_std, kept.reference_speed) == (
        1e-4,
        0.6,
        3e-5,
        15.0,
    )
    document = json.loads(path.read_text())
    document["equation_error"]["speed_scaled"]["correlation"] = 1.2
    with pytest.raises(ModelFileError, match=r"equation_error.speed_scaled.correlation"):
        SteeringModel.from_dict(document, "bad.json")
    assert SteeringModel.load(_saved(tmp_path)).equation_error_speed_scaled is None


def _saved(tmp_path):  # noqa: ANN001, ANN202
    path = tmp_path / "plain.json"
    GeneralizedModel.paper().save(path)
    return path


def test_the_trust_rule_carries_a_declaration_the_data_support() -> None:
    model = GeneralizedModel.paper()
    model.equation_error_ar = (0.3, 0.2)
    model.equation_error_speed_scaled = TRUE
    trusted = trusted_filter(
        model, training=TrainingRecord(residual_std=7e-5, speed_scaled_gain=0.2)
    )
    settings = trusted.settings
    assert trusted.arx == model.arx()  # not whitened: the coloured part is a state
    assert settings.steering_residual_std == TRUE.white_std
    assert settings.steering_coloured_error_std == TRUE.coloured_std
    assert settings.steering_coloured_error_correlation == TRUE.correlation
    assert "carried as a coloured part" in trusted.equation_error_reason
    estimator = trusted.estimator()
    assert estimator.model.coloured_error and "coloured_error" in estimator.state_names
    # the data say it describes the residuals worse than one level: ignored, the AR taken
    ignored = trusted_filter(
        model, training=TrainingRecord(residual_std=7e-5, speed_scaled_gain=-0.1)
    )
    assert ignored.settings.steering_coloured_error_std == 0.0
    assert ignored.arx != model.arx()  # whitened by its autoregression instead
    assert "ignored: it describes" in ignored.equation_error_reason
    assert "whitened by its equation error" in ignored.equation_error_reason
    assert not ignored.estimator().model.coloured_error


def test_the_benchmarks_generalized_model_carries_it_fitted_on_held_out_runs() -> None:
    from benchmarks.protocol.run import builtin_model
    from benchmarks.protocol.tasks import model_estimator

    _, _, fitted = builtin_model(8300)  # the default protocol: 9 training runs
    found = fitted.model.equation_error_speed_scaled
    assert found is not None and 0 < found.correlation < 0.99
    assert 0 < found.white_std < found.coloured_std  # the slow-speed part dominates
    assert fitted.training.speed_scaled_gain > 0
    estimator = model_estimator(fitted, None)
    assert estimator.settings.steering_coloured_error_std == found.coloured_std
    assert estimator.settings.steering_residual_std == found.white_std
    assert "coloured_error" in estimator.state_names


def test_hasa_bench_records_it_and_gives_the_whitening_back_on_request(tmp_path) -> None:
    # the tiny protocol's two short training runs do not identify it (its fit ends on the
    # boundary), so the filter whitens by the AR(2) either way; what is recorded differs
    from test_equation_error import TINY_BENCH

    from benchmarks.schema import folder_problems
    from hasa_cli.bench import main

    docs = {}
    for flag in ("--speed-scaled-error", "--no-speed-scaled-error"):
        out = tmp_path / flag
        assert main(["paper", *TINY_BENCH, "--out", str(out), flag]) == 0
        assert folder_problems(out) == []  # the shipped schema holds the new fields
        docs[flag] = json.loads((out / "results.json").read_text())
    on, off = ({m["name"]: m for m in docs[f]["models"]} for f in docs)
    assert docs["--speed-scaled-error"]["config"]["speed_scaled_error"] is True
    assert docs["--no-speed-scaled-error"]["config"]["speed_scaled_error"] is False
    assert on["generalized"]["speed_scaled_error"] is None  # not identified: the fallback
    assert on["generalized"]["speed_scaled_gain"] is None
    assert any("whitened by its equation error" in r for r in on["generalized"]["steering_trust"])
    assert off["generalized"]["speed_scaled_error"] is None
    assert any("whitened by its equation error" in r for r in off["generalized"]["steering_trust"])
    assert on["two_point"]["speed_scaled_error"] is None  # the built-in generalized model only


def test_hasa_replay_checks_a_declaration_on_each_recording(tmp_path, capsys) -> None:
    from estimators.tuning import residuals_and_speeds
    from hasa_cli.replay import main
    from hasa_env.drivers import SyntheticDriver, population, run_driver, save_runs

    runs = run_driver(SyntheticDriver(population("paper", seed=0)[0]), runs=2, seed=0,
                      config={"time_limit": 8.0})  # fmt: skip
    save_runs(runs, tmp_path / "runs")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = GeneralizedModel(equation_error_order=0).fit(runs[0])
    found = residuals_and_speeds(model, runs, 1.0)
    assert found is not None
    rms = float(np.sqrt(np.nanmean(np.concatenate(found[0]) ** 2)))
    lines = {}
    for name, declared in (
        ("right", SpeedScaledError(rms, 0.6, rms / 3)),  # about the level, correlated
        ("tiny", SpeedScaledError(rms / 100, 0.5, rms / 100)),  # far too small
    ):
        model.equation_error_speed_scaled = declared
        model.save(tmp_path / f"{name}.json")
        code = main([str(tmp_path / "runs"), "--model", str(tmp_path / f"{name}.json"),
                     "--estimator", "--no-lane-check"])  # fmt: skip
        assert code == 0
        lines[name] = [ln for ln in capsys.readouterr().out.splitlines() if "estimator trust" in ln]
    assert len(lines["right"]) == 3  # the model's line and one per recording, each taking it
    assert all("carried as a coloured part" in ln for ln in lines["right"][1:])
    assert len(lines["tiny"]) == 3  # the model's line and one per recording, each ignoring it
    assert all("speed-scaled equation error" in ln and "ignored" in ln for ln in lines["tiny"][1:])


def test_hasa_bench_fits_it_for_a_users_generalized_model_as_for_its_own() -> None:
    # `hasa-bench score hasa_env.steering.models:GeneralizedModel` fitted the same model as the
    # built-in one without its speed-scaled error (hasa-replay --fit fitted it): the user's
    # model was scored with a handicap
    from benchmarks.protocol.config import ProtocolConfig
    from benchmarks.protocol.models import fit_models, load_models
    from benchmarks.protocol.plan import make_plan, training_frames

    frames = training_frames(make_plan(ProtocolConfig(seeds=(8300,)), 8300))
    errors: list = []
    spec = "hasa_env.steering.models:GeneralizedModel"
    candidates = load_models([spec], errors, time_limit=None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted, infos = fit_models(frames, candidates, errors, speed_scaled_error=True)
    assert errors == []
    models = {fm.name: fm.model for fm in fitted}
    own, users = models["generalized"], models[spec]
    assert own.equation_error_speed_scaled is not None  # identified on the 9 training runs
    assert users.equation_error_speed_scaled == own.equation_error_speed_scaled
    described = {info["name"]: info for info in infos}
    assert described[spec]["speed_scaled_gain"] == described["generalized"]["speed_scaled_gain"]
    # --no-speed-scaled-error: for neither
    plain, _ = fit_models(frames, candidates, errors, speed_scaled_error=False)
    assert all(fm.model.equation_error_speed_scaled is None for fm in plain)
