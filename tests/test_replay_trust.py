"""hasa-replay --estimator: the trust it prints is that of the filter each recording got.

A declared equation-error autoregression is taken only on a recording where whitening by it
lowers the model's one-step residual there (docs/design.md §8.32), so whether it is taken is
said beside that recording's result, never in the line printed once per model.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from benchmarks.recordings import RecordingOutcome, describe_trust, prepare_model
from estimators.trust import STEERING_EVERYWHERE, trusted_filter
from hasa_cli import EXIT_PARTIAL
from hasa_cli.replay import main
from hasa_env.steering import GeneralizedModel, SteeringModel

WRONG_AR = (-0.6, 0.3)
"""An autoregression the synthetic driver's residuals do not have: it predicts worse."""

IGNORED = "its equation error's autoregression r = (-0.6, 0.3) ignored: whitened by it"


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """Two 8 s runs of a synthetic driver (``runs/``), a run of a white-noise model driver
    (``model_driven/``), a run at another sample rate (``other_rate/``) and three model
    files fitted on the first synthetic run: ``white.json`` (no autoregression),
    ``wrong.json`` (the same declaring :data:`WRONG_AR`) and ``own.json`` (the
    autoregression of its own residuals, fitted)."""
    from hasa_env.drivers import ModelDriver, SyntheticDriver, population, run_driver, save_runs

    root = tmp_path_factory.mktemp("replay_trust")
    config = {"time_limit": 8.0}
    runs = run_driver(SyntheticDriver(population("paper", seed=0)[0]), runs=2, seed=0,
                      config=config)  # fmt: skip
    save_runs(runs, root / "runs")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        white = GeneralizedModel(equation_error_order=0).fit(runs[0])
        own = GeneralizedModel(equation_error_order=2).fit(runs[0])
    white.save(root / "white.json")
    own.save(root / "own.json")
    white.equation_error_ar = WRONG_AR
    white.save(root / "wrong.json")
    white.equation_error_ar = ()
    driven = run_driver(ModelDriver(white, noise_std=1e-4), runs=1, seed=1, config=config)
    save_runs(driven, root / "model_driven")
    other = run_driver(SyntheticDriver(population("paper", seed=0)[1]), runs=1, seed=2,
                       config={**config, "action_repeat": 2})  # fmt: skip
    save_runs(other, root / "other_rate")
    return {
        name: root / name
        for name in ("runs", "model_driven", "other_rate", "white.json", "wrong.json", "own.json")
    }


def _replay(capsys, *argv: object) -> tuple[int, list[str], str]:
    code = main([*map(str, argv), "--estimator", "--no-lane-check"])
    captured = capsys.readouterr()
    return code, captured.out.splitlines(), captured.err


def _trust_lines(lines: list[str]) -> tuple[str, dict[str, str]]:
    """The once-per-model trust line and, by recording path, each recording's own."""
    model = next(ln for ln in lines if ln.startswith("model ") and "estimator trust:" in ln)
    own = dict(
        ln.split(": estimator trust: ", 1)
        for ln in lines
        if not ln.startswith("model ") and ": estimator trust: " in ln
    )
    return model.split(": estimator trust: ", 1)[1], own


def test_a_declaration_ignored_on_each_recording_is_said_beside_each(files, capsys) -> None:
    code, lines, _ = _replay(capsys, files["runs"], "--model", files["wrong.json"])
    assert code == 0
    model, own = _trust_lines(lines)
    # the filter each recording got does not whiten: neither line may say it does
    assert "autoregression" not in model and not any("compared whitened" in ln for ln in lines)
    runs = [str(files["runs"] / name) for name in ("run_000.csv", "run_001.csv")]
    assert sorted(own) == runs
    for path, text in own.items():
        assert text.startswith(IGNORED) and "not below its own" in text
        at = lines.index(f"{path}: estimator trust: {text}")
        assert lines[at + 1].startswith(f"{path}: estimator: lateral RMSE")  # beside its result
    # the rest of the model's trust is the white model's, as it was printed before
    white = SteeringModel.load(files["white.json"])
    assert model == trusted_filter(white).describe()


def test_taken_on_one_recording_ignored_on_another_a_bad_one_named(files, capsys) -> None:
    paths = (files["runs"], files["model_driven"], files["other_rate"])
    code, lines, err = _replay(capsys, *paths, "--model", files["own.json"])
    assert code == EXIT_PARTIAL  # the recording at another rate cannot be scored nor filtered
    assert "other_rate/run_000.csv: cannot run the estimator" in err
    model, own = _trust_lines(lines)
    assert "autoregression" not in model
    runs = [str(files["runs"] / name) for name in ("run_000.csv", "run_001.csv")]
    driven = str(files["model_driven"] / "run_000.csv")
    assert sorted(own) == sorted([*runs, driven])  # not the one that failed
    taken = "the steering compared whitened by its equation error's autoregression r = ("
    for run in runs:  # the synthetic driver's residuals: taken there
        assert own[run].startswith(taken) and "whitened, the one-step residual is" in own[run]
    # the model driver's residuals are white: ignored there
    assert "autoregression r = (" in own[driven] and ") ignored: whitened by it" in own[driven]
    assert sum(": estimator: lateral RMSE" in ln for ln in lines) == 3


def test_a_model_without_a_declaration_prints_one_line_as_before(files, capsys) -> None:
    code, lines, _ = _replay(capsys, files["runs"], "--model", files["white.json"])
    assert code == 0
    model, own = _trust_lines(lines)
    assert own == {}
    assert model == trusted_filter(SteeringModel.load(files["white.json"])).describe()


def test_without_any_filter_the_line_is_the_models_without_its_declaration(files) -> None:
    from hasa_env.recording.reader import load_paths

    recordings = load_paths([files["runs"]])
    prepared = prepare_model(str(files["wrong.json"]), recordings)
    failed = [RecordingOutcome(0, Path("a.csv"), error="no")]
    lines = describe_trust(prepared, failed)
    alone = prepared.trust()
    assert alone.equation_error_reason in alone.reasons  # taken as declared without data
    assert lines.recordings == {}
    assert lines.model == "; ".join(r for r in alone.reasons if r != alone.equation_error_reason)
    only_ar = prepare_model(str(files["wrong.json"]), recordings)
    only_ar.model.training_speed_range = None  # no limits: only its declaration is left
    only_ar.model.training_curvature = None
    assert describe_trust(only_ar, failed).model == STEERING_EVERYWHERE
