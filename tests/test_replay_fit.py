"""hasa-replay --fit: a generalized model fitted on the first --fit-on recordings gets its
equation error's autoregression of hasa-bench's order (--equation-error-order; docs/design.md
§8.32) and its speed-scaled equation error (docs/design.md §8.34) as hasa-bench fits its
built-in one (benchmarks.speed_scaled.add_speed_scaled_error: held out with two recordings or
more), so its filter is the one hasa-bench's trust rule builds for that model."""

from __future__ import annotations

import json
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.recordings import ModelSetupError, prepare_model
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

    # hasa-bench's fit of its built-in generalized model on the same two runs, and its trust
    # rule's filter for it
    bench = _bench_fit(recordings[:2], speed_scaled_error=True)
    assert bench.model.equation_error_speed_scaled == found
    assert prepared.model.equation_error_ar == bench.model.equation_error_ar != ()
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


def _bench_fit(recordings: list[Any], **options: Any) -> Any:
    """hasa-bench's fit of its built-in generalized model on ``recordings`` (its protocol's
    default equation-error order), as hasa-bench fits it (benchmarks.protocol.models)."""
    from benchmarks.protocol import ProtocolConfig
    from benchmarks.protocol.models import Candidate, fit_models

    candidate = Candidate("generalized", "builtin", None, GeneralizedModel.paper())
    order = ProtocolConfig().equation_error_order
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (bench,), _ = fit_models([r.data for r in recordings], [candidate], [],
                                 equation_error_order=order, **options)  # fmt: skip
    return bench


def test_without_speed_scaled_error_it_fits_hasa_benchs_autoregression_and_filter(
    files, tmp_path, capsys
):
    """With --no-speed-scaled-error (as when none is found) the filter whitens the steering by
    the equation error's autoregression: hasa-bench's AR(2), not the preset's white level."""
    from estimators.offline import recording_filter
    from estimators.settings import FilterSettings
    from estimators.trust import trusted_filter

    recordings = _recordings(files["runs"])
    prepared = prepare_model("generalized", recordings, fit=True, fit_on=2,
                             speed_scaled_error=False)  # fmt: skip
    bench = _bench_fit(recordings[:2], speed_scaled_error=False)
    assert bench.model.structure() == prepared.model.structure()  # the order: 2
    np.testing.assert_array_equal(prepared.model.parameter_vector, bench.model.parameter_vector)
    assert prepared.model.equation_error_ar == bench.model.equation_error_ar
    assert len(bench.model.equation_error_ar) == 2

    code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                  "generalized", "--fit", "--fit-on", "2",
                                  "--no-speed-scaled-error")  # fmt: skip
    assert code == EXIT_OK and doc["arguments"]["equation_error_order"] is None  # not given
    assert doc["model"]["equation_error_order"] == 2
    assert doc["model"]["equation_error_ar"] == list(bench.model.equation_error_ar)
    shown = ", ".join(f"{r:.3g}" for r in bench.model.equation_error_ar)
    assert (f"model generalized: equation error AR(2): {shown} (--equation-error-order 2: hasa-bench's default)"
            in lines)  # fmt: skip

    held_out = recordings[2]  # not fitted on
    mine = recording_filter(held_out, prepared.model, prepared.steering_ratio)
    assert mine == recording_filter(held_out, bench.model, prepared.steering_ratio)
    assert mine.arx != bench.model.arx()  # the form whitened by the autoregression
    assert "whitened by its equation error's autoregression" in mine.equation_error_reason
    # hasa-bench's trust rule on its training record: the same filter (hasa-replay measures
    # the residual levels on the recording instead, PreparedModel.trust)
    training = replace(bench.training, residual_std=bench.residual_std)
    theirs = trusted_filter(
        bench.model, FilterSettings.from_env_config(held_out.config), training=training
    )
    assert recording_filter(held_out, prepared.model, training=training) == theirs
    assert mine.arx == theirs.arx


def test_order_zero_gives_the_white_model(files, tmp_path, capsys):
    code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                  "generalized", "--fit", "--no-speed-scaled-error",
                                  "--equation-error-order", "0")  # fmt: skip
    assert code == EXIT_OK and doc["arguments"]["equation_error_order"] == 0
    assert doc["model"]["equation_error_order"] == 0 and doc["model"]["equation_error_ar"] == []
    assert "model generalized: white equation error (--equation-error-order 0)" in lines
    recordings = _recordings(files["runs"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prepared = prepare_model("generalized", recordings, fit=True, speed_scaled_error=False,
                                 equation_error_order=0)  # fmt: skip
        white = GeneralizedModel(equation_error_order=0).fit(recordings[0].data)
    assert prepared.model.structure() == white.structure() == GeneralizedModel().structure()
    assert prepared.model.equation_error_ar == ()
    np.testing.assert_array_equal(prepared.model.parameter_vector, white.parameter_vector)
    assert prepared.trust().arx == white.arx()  # not whitened


def test_a_model_file_keeps_its_own_order_unless_given(files, tmp_path, capsys):
    """--fit refits a model file in its own structure (orders, equation-error order);
    --equation-error-order sets another, for a GeneralizedModel file only."""
    recordings = _recordings(files["runs"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        GeneralizedModel(equation_error_order=1).fit(recordings[0].data).save(
            tmp_path / "model.json"
        )
    spec = str(tmp_path / "model.json")
    for given, order in ((None, 1), (0, 0), (3, 3)):
        argv = [] if given is None else ["--equation-error-order", str(given)]
        code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["runs"], "--model", spec,
                                      "--fit", "--no-speed-scaled-error", *argv)  # fmt: skip
        assert code == EXIT_OK and doc["model"]["equation_error_order"] == order, given
        assert len(doc["model"]["equation_error_ar"]) == order, given
        how = "the model's own order" if given is None else f"(--equation-error-order {given})"
        assert any(ln.startswith(f"model {spec}: ") and how in ln for ln in lines), given
    code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                  "two-point", "--fit", "--equation-error-order", "2")  # fmt: skip
    assert code == EXIT_OK and doc["model"]["equation_error_order"] == 0
    assert any(ln.startswith("model two-point: --equation-error-order not applied") for ln in lines)


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
    # the filter falls back to the equation error's autoregression, hasa-bench's AR(2)
    bench = _bench_fit(_recordings(files["short"]), speed_scaled_error=True)
    assert bench.model.equation_error_speed_scaled is None
    assert doc["model"]["equation_error_ar"] == list(bench.model.equation_error_ar) != []
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


@pytest.mark.parametrize("value", ["11", "-1", "two"])
def test_equation_error_order_out_of_range_is_a_usage_error(files, capsys, value):
    with pytest.raises(SystemExit) as info:
        main([str(files["runs"]), "--model", "generalized", "--fit", "--equation-error-order",
              value])  # fmt: skip
    assert info.value.code == EXIT_USAGE
    assert capsys.readouterr().err.splitlines()[-1] == (
        "hasa-replay: error: argument --equation-error-order: must be an integer in [0, 10] "
        f"(0: white), got {value!r}"
    )


def test_equation_error_order_needs_fit_and_prepare_model_checks_it(files, capsys):
    with pytest.raises(SystemExit) as info:
        main([str(files["runs"]), "--model", "generalized", "--equation-error-order", "2"])
    assert info.value.code == EXIT_USAGE
    assert capsys.readouterr().err.splitlines()[-1] == (
        "hasa-replay: error: --equation-error-order needs --fit"
    )
    for bad in (11, -1, True, 2.0):
        with pytest.raises(ModelSetupError, match=r"--equation-error-order must be an integer "
                                                  r"in \[0, 10\] \(0: white\), got "):  # fmt: skip
            prepare_model("generalized", _recordings(files["short"]), fit=True,
                          equation_error_order=bad)  # fmt: skip
