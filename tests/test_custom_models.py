"""A user's steering model, from a module and from a saved JSON file, in all three CLIs
(hasa-replay --model, hasa-drive --estimator, hasa-bench); models whose regressors and
design disagree are refused with a clear message."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest
from _user_models import near_far_pd_module

from hasa_cli.bench import main as bench_main
from hasa_cli.drive import main as drive_main
from hasa_cli.replay import main as replay_main
from hasa_env.drivers import SyntheticDriver, population, run_driver, save_runs
from hasa_env.steering import ModelFileError, SteeringModel
from hasa_env.steering.base import ModelDefinitionError
from hasa_env.steering.loading import ModelLoadError, load_model, load_model_file

MODULE = "cli_user_models"
SOURCE = (
    near_far_pd_module("A user's steering models (for the CLI tests).", "cli_test_near_far_pd")
    + '''

class WrongRegressors(NearFarPD):
    """Says it uses phi(k-2) but its design uses phi(k-1) and Omega(k)."""

    model_type = "cli_test_wrong_regressors"

    @property
    def regressors(self):
        return (Regressor("delta", 1), Regressor("phi", 0), Regressor("phi", 2))


class Chatty(NearFarPD):
    """Prints while it is designed (in the fit and every scoring)."""

    model_type = "cli_test_chatty"

    def design(self, features):
        print("CHATTY MODEL OUTPUT")
        return super().design(features)
'''
)


@pytest.fixture(scope="module")
def user(tmp_path_factory: pytest.TempPathFactory):
    """The user's module on sys.path, two recordings, and the model fitted and saved."""
    folder = tmp_path_factory.mktemp("user")
    (folder / f"{MODULE}.py").write_text(textwrap.dedent(SOURCE))
    sys.path.insert(0, str(folder))
    try:
        recordings = folder / "recordings"
        params = population("paper", seed=0)[0]
        frames = run_driver(SyntheticDriver(params), runs=3, seed=0,
                            config={"time_limit": 4.0})  # fmt: skip
        save_runs(frames, recordings / "Ill")
        module = __import__(MODULE)
        model = module.NearFarPD().fit(frames[0])
        path = folder / "near_far_pd.json"
        model.save(path)
        yield {"folder": folder, "recordings": recordings, "model": path, "fitted": model,
               "frames": frames}  # fmt: skip
    finally:
        sys.path.remove(str(folder))


def test_hasa_bench_scores_saved_models_without_speeds_and_checks_only_fitted_predictions(
    user, tmp_path, capsys
):
    from benchmarks.schema import folder_problems
    from hasa_env.steering import GeneralizedModel

    preset = GeneralizedModel.paper()  # records its roads, not its speeds: no upper limit
    preset.save(tmp_path / "preset.json")
    arx = preset.arx()  # a spoiled copy: its own past predicted with the wrong memory
    spoiled = preset.with_parameters([-0.5, 0.2, *arx.b, *arx.c, *arx.d])
    spoiled.save(tmp_path / "spoiled.json")
    out = tmp_path / "bench"
    code = bench_main(["score", str(tmp_path / "preset.json"), str(tmp_path / "spoiled.json"),
                       "--recordings", str(user["recordings"]), "--out", str(out),
                       "--no-plots", "--workers", "1", "--quiet", "--min-duration", "1"])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    assert folder_problems(out) == []  # (a null upper speed limit broke the schema)
    models = {m["spec"]: m for m in json.loads((out / "results.json").read_text())["models"]
              if m["kind"] == "user"}  # fmt: skip
    preset_info = models[str(tmp_path / "preset.json")]
    assert preset_info["steering_speed_limits"][1] is None
    # the prediction check needs the data a model was fitted on: a saved model's levels on
    # this training run are reported, not held against it (design §8.13.1)
    spoiled_info = models[str(tmp_path / "spoiled.json")]
    assert spoiled_info["prediction_residual_std"] > spoiled_info["lane_free_residual_std"]
    assert not any("its own past" in r for r in spoiled_info["steering_trust"])


def test_load_model_takes_import_paths_and_model_files(user):
    imported = load_model(f"{MODULE}:NearFarPD")
    assert type(imported).__name__ == "NearFarPD" and not imported.is_fitted
    loaded = load_model(str(user["model"]))
    assert loaded == user["fitted"] and loaded.is_fitted
    document = json.loads(user["model"].read_text())
    assert document["class"] == f"{MODULE}:NearFarPD" and document["type"] == "cli_test_near_far_pd"
    with pytest.raises(ModelLoadError, match="unknown model; use 'two-point' or 'generalized'"):
        load_model("best-model")
    with pytest.raises(ModelLoadError, match="cannot import module 'no_such_pkg_xyz'"):
        load_model("no_such_pkg_xyz:Model")
    with pytest.raises(ModelLoadError, match=f"module '{MODULE}' has no attribute 'Missing'"):
        load_model(f"{MODULE}:Missing")
    with pytest.raises(ModelFileError, match="no such model file"):
        load_model(str(user["folder"] / "missing.json"))


def test_a_model_whose_regressors_and_design_disagree_is_refused(user):
    message = (r"WrongRegressors \(model_type 'cli_test_wrong_regressors'\): regressors and "
               r"design\(\) disagree: design\(\) uses phi\(k-1\), which regressors does not list; "
               r"regressors lists phi\(k-2\), which design\(\) does not use; design\(\) uses "
               r"omega\(k\)")  # fmt: skip
    with pytest.raises(ModelLoadError, match=message):
        load_model(f"{MODULE}:WrongRegressors")
    wrong = __import__(MODULE).WrongRegressors()
    with pytest.raises(ModelDefinitionError, match=message):
        wrong.fit(user["frames"][0])
    user["fitted"].check_regressors()  # the right one passes


def test_a_user_model_file_loads_in_a_fresh_process_through_its_class(user, tmp_path):
    """The file names its class: a program that never imported the module reads it when told
    to trust the module (--trust-model-module), from the file's folder, run from elsewhere as
    the console script runs (-P: the working directory is not on sys.path)."""
    recording = user["recordings"] / "Ill" / "run_001.csv"
    argv = [sys.executable, "-P", "-m", "hasa_cli.replay", str(recording), "--model",
            str(user["model"])]  # fmt: skip
    done = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "pass --trust-model-module" in done.stderr
    done = subprocess.run(
        [*argv, "--trust-model-module"], cwd=tmp_path, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert f"model {user['model']}: rmse" in done.stdout
    document = json.loads(user["model"].read_text())
    document["class"] = "no_such_module_abc:Model"
    document["type"] = "never_registered"
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps(document))
    with pytest.raises(ModelFileError, match="is not registered.*--trust-model-module"):
        load_model_file(broken)
    with pytest.raises(ModelFileError, match="'no_such_module_abc' .* cannot be imported"):
        load_model_file(broken, trust_module=True)
    del document["class"]
    broken.write_text(json.dumps(document))
    with pytest.raises(ModelFileError, match="'never_registered' is not allowed: one of"):
        SteeringModel.load(broken)


def test_hasa_replay_scores_and_estimates_with_a_user_model(user, capsys):
    folder = str(user["recordings"])
    spec = f"{MODULE}:NearFarPD"
    assert replay_main([folder, "--model", spec, "--fit", "--estimator"]) == 0
    out = capsys.readouterr().out
    assert f"model {spec}: fitted on" in out and f"model {spec}: rmse" in out
    assert out.count("estimator: lateral RMSE") == 3
    assert replay_main([folder, "--model", str(user["model"]), "--estimator"]) == 0
    assert capsys.readouterr().out.count("estimator: lateral RMSE") == 3
    assert replay_main([folder, "--model", spec]) == 2
    assert "has no parameters: add --fit" in capsys.readouterr().err
    assert replay_main([folder, "--model", f"{MODULE}:WrongRegressors", "--fit"]) == 2
    assert "regressors and design() disagree" in capsys.readouterr().err


def test_hasa_drive_estimator_takes_a_user_model(user, tmp_path, capsys):
    study = tmp_path / "s.toml"
    study.write_text('[study]\nname = "s"\nseed = 1\n[runs]\nseconds = 0.3\n[measured]\nruns = 1\n')
    args = ["study", str(study), "--output", str(tmp_path), "--synthetic", "2", "--estimator"]
    assert drive_main([*args, str(user["model"]), "--participant", "P01"]) == 0
    out = capsys.readouterr().out
    assert "weights +0.0: " in out  # the estimator ran with the user's model
    assert drive_main([*args, f"{MODULE}:NearFarPD", "--participant", "P02"]) == 2
    assert "the model has no parameters, and the estimator needs a fitted model" in (
        capsys.readouterr().err)  # fmt: skip
    assert drive_main([*args, f"{MODULE}:WrongRegressors", "--participant", "P03"]) == 2
    assert "regressors and design() disagree" in capsys.readouterr().err


def test_hasa_bench_scores_a_user_model_from_a_module_and_from_a_file(user, tmp_path, capsys):
    out = tmp_path / "bench"
    spec, path = f"{MODULE}:NearFarPD", str(user["model"])
    code = bench_main(["score", spec, path, "--recordings", str(user["recordings"]), "--out",
                       str(out), "--no-plots", "--workers", "1", "--quiet",
                       "--min-duration", "1"])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    result = json.loads((out / "results.json").read_text())
    models = {m["spec"]: m for m in result["models"] if m["kind"] == "user"}
    assert set(models) == {spec, path}
    assert models[spec]["refitted"] is True and models[path]["refitted"] is False
    assert "scored with the parameters of its file" in models[path]["note"]
    assert models[path]["parameters"] == user["fitted"].parameters  # not refitted
    estimated = {r["model"] for r in result["estimation"]}
    assert {models[spec]["name"], models[path]["name"]} <= estimated
    code = bench_main(["paper", "--model", f"{MODULE}:WrongRegressors", "--recordings",
                       str(user["recordings"]), "--out", str(tmp_path / "b2"), "--no-plots",
                       "--workers", "1", "--quiet", "--min-duration", "1"])  # fmt: skip
    assert code == 2  # a model that cannot be used is an input error: nothing is run
    assert "regressors and design() disagree" in capsys.readouterr().err


@pytest.mark.parametrize("limit", ["600", "0"])  # isolated in a child process, or in-process
def test_what_a_user_model_prints_goes_to_stderr_not_into_the_tables(user, tmp_path, capfd, limit):
    code = bench_main(["score", f"{MODULE}:Chatty", "--recordings", str(user["recordings"]),
                       "--out", str(tmp_path / "bench"), "--no-plots", "--workers", "1",
                       "--min-duration", "1", "--model-time-limit", limit])  # fmt: skip
    out, err = capfd.readouterr()
    assert code == 0, err
    assert "CHATTY MODEL OUTPUT" in err and "CHATTY MODEL OUTPUT" not in out
    assert "Verdict over" in out  # the tables are on stdout
