"""hasa-replay --json: the results as one JSON document, written atomically, kept when the
run ends early after loading."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path
from typing import Any

import pytest
from _recording_files import crash, tamper

import benchmarks.recordings as recordings_module
import hasa_cli.replay as replay
from benchmarks.replay_document import REPLAY_FORMAT
from hasa_cli import EXIT_INTERRUPTED, EXIT_OK, EXIT_PARTIAL, EXIT_USAGE
from hasa_cli.replay import main


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """Two 8 s runs of a synthetic driver (``runs/``), ``broken/`` with a copy of the first
    run's CSV without its sidecar (it cannot be loaded), ``tampered/`` with a copy of both
    runs whose second run's lateral offset is changed at row 400, ``crashed/`` with a copy of
    both runs whose second run's writer crashed inside its last line (it loads, that line
    dropped with a note), and ``model.json``: a generalized model fitted on the first run."""
    from hasa_env.drivers import SyntheticDriver, population, run_driver, save_runs
    from hasa_env.steering import GeneralizedModel

    root = tmp_path_factory.mktemp("replay_json")
    runs = run_driver(SyntheticDriver(population("paper", seed=0)[0]), runs=2, seed=0,
                      config={"time_limit": 8.0})  # fmt: skip
    save_runs(runs, root / "runs")
    (root / "broken").mkdir()
    shutil.copy(root / "runs" / "run_000.csv", root / "broken" / "run_000.csv")
    shutil.copytree(root / "runs", root / "tampered")
    tamper(root / "tampered" / "run_001.csv", 400, "lateral_offset", 1e-6)
    shutil.copytree(root / "runs", root / "crashed")
    crash(root / "crashed" / "run_001.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        GeneralizedModel(equation_error_order=0).fit(runs[0]).save(root / "model.json")
    names = ("runs", "broken", "tampered", "crashed", "model.json")
    return {name: root / name for name in names}


def _replay(capsys, out: Path, *argv: object) -> tuple[int, dict[str, Any], list[str], str]:
    code = main([*map(str, argv), "--json", str(out)])
    captured = capsys.readouterr()
    return code, json.loads(out.read_text()), captured.out.splitlines(), captured.err


def test_two_good_recordings_and_one_that_does_not_load(files, tmp_path, capsys) -> None:
    out = tmp_path / "replay.json"
    code, doc, lines, err = _replay(capsys, out, files["runs"], files["broken"])
    assert code == EXIT_PARTIAL and doc["exit_status"] == EXIT_PARTIAL
    assert doc["format"] == REPLAY_FORMAT and doc["version"] == doc["versions"]["hasa-env"]
    assert doc["arguments"]["atol"] == 0.0 and doc["arguments"]["model"] is None
    assert doc["arguments"]["estimator"] is False and doc["model"] is None
    (bad,) = doc["load_errors"]
    assert bad["path"] == str(files["broken"] / "run_000.csv")  # the CSV whose sidecar is gone
    assert "missing sidecar" in bad["message"] and bad["message"] in err
    paths = [r["path"] for r in doc["recordings"]]
    assert paths == [str(files["runs"] / f"run_00{i}.csv") for i in (0, 1)]
    for rec in doc["recordings"]:
        assert rec["label"] == "synthetic" and rec["complete"] is True and rec["steps"] == 800
        assert rec["replay"]["matches"] is True and rec["replay"]["divergence"] is None
        assert f"{rec['path']}: synthetic, 800 steps: {rec['replay']['text']}" in lines
        assert "model" not in rec and "estimator" not in rec
    assert doc["error"] is None
    assert [p.name for p in tmp_path.iterdir()] == ["replay.json"]  # no temporary file left


def test_where_a_recording_diverges(files, tmp_path, capsys) -> None:
    code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["tampered"])
    assert code == EXIT_PARTIAL and doc["load_errors"] == []
    first, second = doc["recordings"]
    assert first["replay"]["matches"] is True
    assert second["replay"]["matches"] is False
    where = second["replay"]["divergence"]
    assert (where["row"], where["time"], where["column"]) == (400, pytest.approx(4.0),
                                                              "lateral_offset")  # fmt: skip
    assert where["recorded"] == pytest.approx(where["replayed"] + 1e-6)
    assert f"{second['path']}: synthetic, 800 steps: {second['replay']['text']}" in lines
    assert "DIVERGES at row 400 (t = 4.00 s), column 'lateral_offset'" in second["replay"]["text"]


def test_model_scores_and_estimator_results_are_those_printed(files, tmp_path, capsys) -> None:
    code, doc, lines, _ = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                  files["model.json"], "--estimator", "--no-lane-check")  # fmt: skip
    assert code == EXIT_OK and doc["exit_status"] == EXIT_OK
    spec = str(files["model.json"])
    assert doc["arguments"] | {"paths": None} == {
        "paths": None, "atol": 0.0, "model": spec, "fit": False, "fit_on": None,
        "speed_scaled_error": None, "equation_error_order": None, "steering": None,
        "steering_ratio": None, "estimator": True, "lane_check": False,
    }  # fmt: skip
    assert doc["model"] == {"spec": spec, "steering_ratio": 1.0, "fitted_on": None,
                            "fitted_on_recordings": [], "speed_scaled_error": None,
                            "speed_scaled_held_out": None, "speed_scaled_gain": None,
                            "equation_error_order": 0, "equation_error_ar": []}  # fmt: skip
    shared = next(ln for ln in lines if ln.startswith(f"model {spec}: estimator trust: "))
    assert shared.endswith(f"estimator trust: {doc['estimator_trust']}")
    for rec in doc["recordings"]:
        scores = rec["model"]["scores"]
        assert set(scores) == {"rmse", "r2", "r2_increments", "ljung_box_p"}
        printed = next(ln for ln in lines if ln.startswith(f"{rec['path']}: model {spec}: rmse"))
        assert f"rmse {scores['rmse']:.4g}, r2 {scores['r2']:.4g}" in printed
        est = rec["estimator"]
        printed = next(ln for ln in lines if ln.startswith(f"{rec['path']}: estimator: "))
        assert f"lateral RMSE {est['lateral_rmse']:.3f} m" in printed
        assert f"ends {est['final_decision']}" in printed
        assert len(est["hypotheses"]) == len(est["final_weights"]) >= 2
        assert sum(est["final_weights"]) == pytest.approx(1.0)
        assert est["true_lane_weight"] == est["final_weights"][est["true_index"]]
        assert est["trusted_from"] is None or est["trusted_from"] >= 0.0
        assert isinstance(est["refused_by"], str) and isinstance(est["trust_reasons"], list)
        assert "; ".join(est["trust_reasons"]) or doc["estimator_trust"]
        # how much of the time the steering counted, and why not (hasa-bench's states)
        steering = est["steering"]
        assert set(steering) == {"live", "off", "unused", "mismatch", "tempered_model_error",
                                 "tempered_autocorrelation"}  # fmt: skip
        assert all(0.0 <= v <= 1.0 for v in steering.values())
        assert sum(steering.values()) == pytest.approx(1.0, abs=0.02)  # valid rows only
        assert f"steering live {steering['live']:.0%} of the time" in printed
        assert est["lateral_nees"] > 0 and f"lateral NEES {est['lateral_nees']:.2f}" in printed


def test_a_missing_parent_directory_or_stdout_is_a_usage_error(files, tmp_path, capsys) -> None:
    target = tmp_path / "no_such_dir" / "r.json"
    with pytest.raises(SystemExit) as stop:
        main([str(files["runs"]), "--json", str(target)])
    captured = capsys.readouterr()
    assert stop.value.code == EXIT_USAGE and captured.out == ""  # before any work
    assert f"--json {target}: directory {target.parent} does not exist" in captured.err
    with pytest.raises(SystemExit) as stop:
        main([str(files["runs"]), "--json", "-"])
    assert stop.value.code == EXIT_USAGE and "--json -:" in capsys.readouterr().err


def test_a_run_that_ends_early_keeps_the_replay_checks(files, tmp_path, capsys) -> None:
    # the paper's two-point model drives off the road: the lane check refuses the estimator
    code, doc, _, err = _replay(capsys, tmp_path / "r.json", files["runs"], files["broken"],
                                "--model", "two-point", "--estimator")  # fmt: skip
    assert code == EXIT_USAGE and doc["exit_status"] == EXIT_USAGE
    assert "drives off the road" in doc["error"] and doc["error"] in err
    assert [r["replay"]["matches"] for r in doc["recordings"]] == [True, True]
    assert len(doc["load_errors"]) == 1
    # nothing loads: the load errors are kept
    code, doc, _, _ = _replay(capsys, tmp_path / "r.json", files["broken"])
    assert code == EXIT_USAGE and doc["recordings"] == [] and len(doc["load_errors"]) == 1
    assert doc["error"] == "no recordings to replay"


def test_an_interrupted_run_keeps_what_was_done(files, tmp_path, capsys, monkeypatch) -> None:
    def interrupt(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(replay, "prepare_model", interrupt)
    code, doc, _, err = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                "two-point")  # fmt: skip
    assert code == EXIT_INTERRUPTED and doc["exit_status"] == EXIT_INTERRUPTED
    assert doc["error"] == "interrupted" and "interrupted" in err
    assert [r["replay"]["matches"] for r in doc["recordings"]] == [True, True]


def test_a_document_written_among_the_recordings_is_not_taken_for_a_sidecar(
    files, tmp_path, capsys
) -> None:
    """Its ``format`` says it is no recording's sidecar: a later run over the folder skips it."""
    folder = tmp_path / "runs"
    shutil.copytree(files["runs"], folder)
    code, _, _, _ = _replay(capsys, folder / "replay.json", folder)
    assert code == EXIT_OK
    again, doc, _, err = _replay(capsys, tmp_path / "again.json", folder)
    assert again == EXIT_OK and doc["load_errors"] == [] and err == ""
    assert len(doc["recordings"]) == 2


def _warning_lines(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.startswith("hasa-replay: warning: ")]


def test_a_fit_warning_is_kept_with_the_recording_fitted_on(files, tmp_path, capsys) -> None:
    """The paper's generalized model fitted on an 8 s run: its lane-offset gain is not
    identified (an IdentifiabilityWarning); stderr says so as before, the document too."""
    code, doc, _, err = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                "generalized", "--fit")  # fmt: skip
    assert code == EXIT_OK
    first = str(files["runs"] / "run_000.csv")
    assert doc["model"]["fitted_on"] == first
    (fit,) = [w for w in doc["warnings"] if w["category"] == "IdentifiabilityWarning"]
    assert fit["recording"] == first and fit["step"] == "model"
    assert fit["message"].startswith("generalized (paper) fit: ")
    assert f"hasa-replay: warning: {fit['message']}" in err  # still printed, as before
    shown = _warning_lines(err)
    assert [f"hasa-replay: warning: {w['message']}" for w in doc["warnings"]] == shown


def test_a_warning_is_kept_with_the_recording_it_arose_on(
    files, tmp_path, capsys, monkeypatch
) -> None:
    """A warning of the estimator on the second recording only names that recording; one of
    the trust lines (no one recording's) names none."""
    second = files["runs"] / "run_001.csv"
    estimate, trust = recordings_module.estimate_recording, recordings_module.describe_trust

    def estimate_warning(rec: Any, *args: Any, **kwargs: Any) -> Any:
        if rec.path == second:
            warnings.warn("a warning on the second run", RuntimeWarning, stacklevel=2)
        return estimate(rec, *args, **kwargs)

    def trust_warning(*args: Any, **kwargs: Any) -> Any:
        warnings.warn("a warning of the trust lines", UserWarning, stacklevel=2)
        return trust(*args, **kwargs)

    monkeypatch.setattr(recordings_module, "estimate_recording", estimate_warning)
    monkeypatch.setattr(replay, "describe_trust", trust_warning)
    code, doc, _, err = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                files["model.json"], "--estimator", "--no-lane-check")  # fmt: skip
    assert code == EXIT_OK
    assert doc["warnings"] == [
        {"recording": str(second), "step": "estimator", "category": "RuntimeWarning",
         "message": "a warning on the second run"},
        {"recording": None, "step": "estimator", "category": "UserWarning",
         "message": "a warning of the trust lines"},
    ]  # fmt: skip
    assert _warning_lines(err) == [
        "hasa-replay: warning: a warning on the second run",
        "hasa-replay: warning: a warning of the trust lines",
    ]


def test_a_run_that_ends_early_keeps_its_warnings(files, tmp_path, capsys, monkeypatch) -> None:
    def interrupt(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(replay, "estimate_recordings", interrupt)
    code, doc, _, err = _replay(capsys, tmp_path / "r.json", files["runs"], "--model",
                                "generalized", "--fit", "--estimator", "--no-lane-check")  # fmt: skip
    assert code == EXIT_INTERRUPTED and doc["error"] == "interrupted"
    first = str(files["runs"] / "run_000.csv")
    assert any(w["recording"] == first and w["category"] == "IdentifiabilityWarning"
               for w in doc["warnings"])  # fmt: skip
    assert len(doc["warnings"]) == len(_warning_lines(err))


def test_a_run_without_warnings_has_an_empty_list(files, tmp_path, capsys) -> None:
    code, doc, _, err = _replay(capsys, tmp_path / "r.json", files["runs"])
    assert code == EXIT_OK and doc["warnings"] == [] and _warning_lines(err) == []


def test_a_repaired_recording_says_so_on_stderr_and_in_the_document(
    files, tmp_path, capsys
) -> None:
    """A study session's last recording, its writer crashed inside its last line: it loads
    without that line and replays; the note of its loading is printed once on stderr naming
    the file, and kept in the document's warnings with the recording's path (step "load")."""
    crashed = str(files["crashed"] / "run_001.csv")
    code, doc, lines, err = _replay(capsys, tmp_path / "r.json", files["crashed"])
    assert code == EXIT_OK and doc["load_errors"] == []
    first, second = doc["recordings"]
    assert second["path"] == crashed and second["complete"] is False
    assert second["replay"]["matches"] is True
    assert any(ln.startswith(f"{crashed}: synthetic, ") for ln in lines)  # it replayed
    (note,) = doc["warnings"]
    assert note["recording"] == second["path"] and note["step"] == "load"
    assert note["category"] == "RecordingWarning"
    assert note["message"].startswith(f"{crashed}: dropped the partly written line ")
    assert _warning_lines(err) == [f"hasa-replay: warning: {note['message']}"]  # once


def test_a_repaired_recording_says_so_once_per_file_given(files, tmp_path, capsys) -> None:
    """Named as a file (not a folder) too; the complete recording beside it adds nothing."""
    crashed = files["crashed"] / "run_001.csv"
    code, doc, _, err = _replay(capsys, tmp_path / "r.json", files["crashed"] / "run_000.csv",
                                crashed)  # fmt: skip
    assert code == EXIT_OK
    assert [(w["recording"], w["step"]) for w in doc["warnings"]] == [(str(crashed), "load")]
    (shown,) = _warning_lines(err)
    assert shown.startswith(f"hasa-replay: warning: {crashed}: dropped the partly written line")
