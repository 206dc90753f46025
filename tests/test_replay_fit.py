"""hasa-replay --fit: a generalized model fitted on the first --fit-on recordings gets its
speed-scaled equation error (docs/design.md §8.34) as hasa-bench fits its built-in one
(benchmarks.speed_scaled.add_speed_scaled_error: held out with two recordings or more), so
its filter is the one hasa-bench's trust rule builds for that model."""

from __future__ import annotations

import json
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.recordings import prepare_model
from hasa_cli import EXIT_OK, EXIT_USAGE
from hasa_cli.replay import main
from hasa_env.recording.reader import load_paths
from hasa_env.steering import GeneralizedModel


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """Three 8 s runs of a synthetic driver (``runs/``) and two 2 s runs (``short/``: too few
    residuals for a speed-scaled error)."""
    from hasa_env.drivers import SyntheticDriver, population, run_driver, save_runs

    root = tmp_path_factory.mktemp("replay_fit")
    driver = SyntheticDriver(population("paper", seed=0)[0])
    save_runs(run_driver(driver, runs=3, seed=0, config={"time_limit": 8.0}), root / "runs")
    save_runs(run_driver(driver, runs=2, seed=0, config={"time_limit": 2.0}), root / "short")
    return {"runs": root / "runs", "short": root / "short"}


def _replay(capsys, out: Path, *argv: object) -> tuple[int, dict[str, Any], list[str], str]:
    code = main([*map(str, argv), "--json", str(out)])
    captured = capsys.readouterr()
    return code, json.loads(out.read_text()), captured.out.splitlines(), captured.err


def _recordings(folder: Path) -> list[Any]:
    return list(load_paths([folder]))


def test_fit_on_two_holds_the_error_out_and_gives_hasa_benchs_filter(files, tmp_path, capsys):
    from benchmarks.protocol.models import Candidate, fit_models
    from estimators.offline import recording_filter
    from estimators.settings import FilterSettings
    from estimators.trust import trusted_filter

    code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                  "generalized", "--fit", "--fit-on", "2")  # fmt: skip
    assert code == EXIT_OK
    first, second, third = (str(files["runs"] / f"run_00{i}.csv") for i in range(3))
    assert doc["arguments"]["fit_on"] == 2 and doc["arguments"]["speed_scaled_error"] is True
    model = doc["model"]
    assert model["fitted_on"] == first  # as before --fit-on: the first recording
    assert model["fitted_on_recordings"] == [first, second]
    assert model["speed_scaled_held_out"] is True and model["speed_scaled_gain"] > 0
    numbers = model["speed_scaled_error"]
    assert f"model generalized: fitted on {first}, {second} (2 recordings" in "\n".join(lines)
    said = next(ln for ln in lines if "speed-scaled equation error" in ln)
    assert f"sigma_c {numbers['coloured_std']:.3g} rad" in said and "held out" in said
    assert f"rho {numbers['correlation']:.3f}, sigma_w {numbers['white_std']:.3g}" in said

    recordings = _recordings(files["runs"])
    prepared = prepare_model("generalized", recordings, fit=True, fit_on=2)
    found = prepared.model.equation_error_speed_scaled
    assert found is not None and found.to_dict() == numbers

    # hasa-bench's fit of its built-in generalized model (white equation error, as the
    # preset) on the same two runs, and its trust rule's filter for it
    candidate = Candidate("generalized", "builtin", None, GeneralizedModel.paper())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (bench,), _ = fit_models([r.data for r in recordings[:2]], [candidate], [],
                                 equation_error_order=0, speed_scaled_error=True)  # fmt: skip
    assert bench.model.equation_error_speed_scaled == found
    np.testing.assert_array_equal(prepared.model.parameter_vector, bench.model.parameter_vector)
    held_out = recordings[2]  # not fitted on
    mine = recording_filter(held_out, prepared.model, prepared.steering_ratio)
    theirs = trusted_filter(
        bench.model,
        FilterSettings.from_env_config(held_out.config),
        training=replace(bench.training, residual_std=bench.residual_std),
    )
    assert mine.settings == theirs.settings and mine.arx == theirs.arx
    assert mine.settings.steering_coloured_error_std == found.coloured_std > 0
    assert mine.settings.steering_residual_std == found.white_std


def test_one_recording_fits_it_in_sample(files, tmp_path, capsys):
    code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                  "generalized", "--fit")  # fmt: skip
    assert code == EXIT_OK and doc["arguments"]["fit_on"] == 1
    assert doc["model"]["fitted_on_recordings"] == [doc["model"]["fitted_on"]]
    assert doc["model"]["speed_scaled_held_out"] is False
    assert doc["model"]["speed_scaled_error"] is not None
    assert any("speed-scaled equation error sigma_c" in ln and "in-sample" in ln for ln in lines)


def test_no_speed_scaled_error_leaves_it_none(files, tmp_path, capsys):
    code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                  "generalized", "--fit", "--fit-on", "2",
                                  "--no-speed-scaled-error")  # fmt: skip
    assert code == EXIT_OK and doc["arguments"]["speed_scaled_error"] is False
    assert {k: doc["model"][k] for k in ("speed_scaled_error", "speed_scaled_held_out",
                                         "speed_scaled_gain")} == dict.fromkeys(
        ("speed_scaled_error", "speed_scaled_held_out", "speed_scaled_gain"))  # fmt: skip
    assert "model generalized: speed-scaled equation error not fitted" in "\n".join(lines)
    prepared = prepare_model("generalized", _recordings(files["runs"]), fit=True, fit_on=2,
                             speed_scaled_error=False)  # fmt: skip
    assert prepared.model.equation_error_speed_scaled is None and prepared.speed_scaled is None


def test_none_found_is_said_in_one_line_and_the_run_goes_on(files, tmp_path, capsys):
    code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["short"], "--model",
                                  "generalized", "--fit", "--fit-on", "2")  # fmt: skip
    assert code == EXIT_OK
    assert doc["model"]["speed_scaled_error"] is None
    assert doc["model"]["speed_scaled_held_out"] is True  # tried, held out, none found
    (said,) = [ln for ln in lines if "speed-scaled" in ln]
    assert said.startswith("model generalized: no speed-scaled equation error found")
    assert all("model generalized: rmse" in ln for ln in lines if ": model generalized: " in ln)


def test_other_models_are_left_as_they_are(files, tmp_path, monkeypatch):
    (tmp_path / "replay_fit_user_model.py").write_text(
        "from hasa_env.steering import GeneralizedModel\n"
        "class Mine(GeneralizedModel):\n    model_type = 'replay_fit_user_generalized'\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    recordings = _recordings(files["runs"])
    for spec in ("two-point", "replay_fit_user_model:Mine"):  # a user's subclass is left too
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            prepared = prepare_model(spec, recordings, fit=True, fit_on=2)
        assert prepared.speed_scaled is None, spec
        assert getattr(prepared.model, "equation_error_speed_scaled", None) is None, spec
        assert prepared.fitted_on == tuple(r.path for r in recordings[:2])


def test_fit_on_out_of_range_is_a_usage_error(files, tmp_path, capsys):
    code, doc, _, err = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                "generalized", "--fit", "--fit-on", "4")  # fmt: skip
    message = "--fit-on must be an integer from 1 to 3 (the recordings loaded), got 4"
    assert code == EXIT_USAGE and doc["exit_status"] == EXIT_USAGE
    assert doc["error"] == message and f"hasa-replay: error: {message}" in err.splitlines()
    for argv, said in (
        (["--fit", "--fit-on", "0"], "--fit-on must be an integer from 1 to the number of "
                                     "recordings loaded, got 0"),
        (["--fit-on", "2"], "--fit-on needs --fit"),
    ):  # fmt: skip
        with pytest.raises(SystemExit) as info:
            main([str(files["runs"]), "--model", "generalized", *argv])
        assert info.value.code == EXIT_USAGE
        assert capsys.readouterr().err.splitlines()[-1] == f"hasa-replay: error: {said}"
