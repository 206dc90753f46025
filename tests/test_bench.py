"""hasa-bench: the paper's protocol on a reduced population, user models, executors, CLI.

The reduced protocol (3 drivers, 2 runs of 4 s each, "Ill" 3 runs, one curved
run) keeps every test fast; the numbers are checked for structure and for
what the code must show on any population (the oracle beats everything, the
no-steering filter cannot tell two lanes 1.8 m apart, ...).
"""

from __future__ import annotations

import json
import math
import sys
import textwrap
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pandas as pd
import pytest
from _user_models import near_far_pd_module

from benchmarks.figures import FIGURES
from benchmarks.perf import format_perf_table, perf_rows
from benchmarks.protocol import (
    BenchmarkError,
    ModelError,
    ProtocolConfig,
    load_user_model,
    run_protocol,
)
from benchmarks.report import CSV_TABLES, _unsafe_estimators, format_tables, write_outputs
from benchmarks.schema import folder_problems
from hasa_cli.bench import main

# the all-PI drivers without remnant ("paper-pi") until the default population is calibrated
SMALL = {"seeds": (0,), "drivers": 3, "runs": 2, "ill_runs": 3, "duration": 4.0, "curved_runs": 1,
         "population": "paper-pi"}  # fmt: skip
SMALL_ARGS = ["--seeds", "0", "--population", "paper-pi", "--drivers", "3", "--runs", "2",
              "--ill-runs", "3", "--duration", "4"]  # fmt: skip
TABLES = ("steering", "curved", "estimation", "runs_steering", "runs_estimation")

USER_MODULE = (
    near_far_pd_module(
        "Steering models for the hasa-bench tests: one good, several broken.",
        "bench_test_near_far_pd",
        default_name="near_far_pd",
    )
    + '''

class NaNModel(NearFarPD):
    """Fits fine, then predicts NaN."""

    model_type = "bench_test_nan"

    def __init__(self, **kwargs):
        kwargs.setdefault("name", "nan_model")
        super().__init__(**kwargs)

    def predict_features(self, features):
        return np.full(len(features), np.nan)


class FitRaises(NearFarPD):
    model_type = "bench_test_fit_raises"

    def __init__(self, **kwargs):
        kwargs.setdefault("name", "fit_raises")
        super().__init__(**kwargs)

    def fit(self, runs, road=None):
        raise RuntimeError("cannot fit this")


class NoARX(NearFarPD):
    """A good model without an ARX form: steering scores only."""

    model_type = "bench_test_no_arx"

    def __init__(self, **kwargs):
        kwargs.setdefault("name", "no_arx")
        super().__init__(**kwargs)

    def arx(self):
        return None


class NotAModel:
    """Has predict and fit but is no SteeringModel."""

    def fit(self, runs):
        return self

    def predict(self, run):
        return np.zeros(len(run))
'''
)


@pytest.fixture(scope="module")
def user_module(tmp_path_factory: pytest.TempPathFactory) -> str:
    """A module with test steering models on sys.path; returns its name."""
    folder = tmp_path_factory.mktemp("user_models")
    (folder / "bench_user_models.py").write_text(textwrap.dedent(USER_MODULE))
    sys.path.insert(0, str(folder))
    yield "bench_user_models"
    sys.path.remove(str(folder))
    sys.modules.pop("bench_user_models", None)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory: pytest.TempPathFactory, user_module: str):
    """The reduced protocol with a good user model, in this process, written to a folder."""
    result = run_protocol(ProtocolConfig(**SMALL), [f"{user_module}:NearFarPD"], workers=1)
    out = tmp_path_factory.mktemp("bench_out")
    written = write_outputs(result, out)
    return result, out, written


def _tables(result) -> dict:
    doc = result.to_json_dict()
    return {key: doc[key] for key in TABLES}


# ------------------------------------------------------------------- structure
def test_results_json_structure(outputs) -> None:
    result, out, _ = outputs
    doc = json.loads((out / "results.json").read_text())
    assert doc["format"] == "hasa_bench.results"
    for key in ("config", "versions", "models", "steering", "estimation", "curved", "summary"):
        assert key in doc
    assert doc["config"]["drivers"] == 3 and doc["config"]["duration"] == 4.0
    assert doc["versions"]["numpy"]
    drivers = ["Ill", "1", "2"]
    models = ["two_point", "generalized", "near_far_pd"]
    steering = doc["steering"]
    with_baseline = ["two_point", "generalized", "road_blind", "near_far_pd"]
    assert [(r["driver"], r["model"]) for r in steering] == [
        (d, m) for d in drivers for m in with_baseline
    ]
    for row in steering:
        for key in ("rmse", "r2", "r2_increments"):
            assert isinstance(row[key], float) and math.isfinite(row[key])
        assert row["n_runs"] == 2  # "Ill": 3 runs minus the training run
        assert row["rmse"] > 0 and row["r2"] <= 1.0 and row["r2_increments"] <= 1.0
    estimation = doc["estimation"]
    expected = models + ["no_steering", "lane_centring", "oracle"]
    assert [(r["driver"], r["model"]) for r in estimation] == [
        (d, m) for d in drivers for m in expected
    ]
    for row in estimation:
        assert row["lateral_rmse_mean"] >= 0 and row["lateral_rmse_std"] >= 0
        assert row["n_runs"] == 2
    assert [(r["driver"], r["model"]) for r in doc["curved"]] == [("Ill", m) for m in with_baseline]
    assert len(doc["runs_steering"]) == (6 + 1) * 4
    main_rows = [r for r in doc["runs_estimation"] if r["track"] == "straight"]
    curved_rows = [r for r in doc["runs_estimation"] if r["track"] == "curved"]
    assert len(main_rows) == 6 * 6 and len(curved_rows) == 1 * 6
    assert [(r["driver"], r["model"]) for r in doc["curved_estimation"]] == [
        ("Ill", m) for m in expected
    ]
    for row in doc["runs_estimation"]:  # the safety metrics of every run
        assert row["final_decision"] in ("undecided", "decided", "model_mismatch")
        assert isinstance(row["wrong_lane_confident"], bool)
        assert row["lateral_nees"] >= 0
    assert {"wrong_lane_confident_runs", "undecided_runs", "model_mismatch_runs",
            "lateral_nees", "curved_lateral_rmse"} <= set(doc["summary"][0])  # fmt: skip
    assert doc["errors"] == []
    # the paper's values sit beside ours
    ill = {r["model"]: r for r in steering if r["driver"] == "Ill"}
    # in road-wheel rad: the paper's steering-wheel value over the steering ratio 15
    assert ill["generalized"]["paper_rmse_steering_wheel"] == 7e-4
    assert ill["generalized"]["paper_rmse"] == pytest.approx(7e-4 / 15)
    assert ill["generalized"]["rmse_over_paper"] == pytest.approx(
        ill["generalized"]["rmse"] / (7e-4 / 15)
    )
    assert ill["near_far_pd"]["paper_rmse"] is None
    assert all(r["seed"] == 0 for r in steering + doc["runs_steering"] + doc["runs_estimation"])
    assert all(0.0 <= r["final_true_lane_weight"] <= 1.0 for r in doc["runs_estimation"])
    for info in doc["models"]:
        assert info["seed"] == 0
        assert {"condition_number", "ar_poles_max_abs", "stable", "identifiable",
                "ridge_lambda"} <= set(info["checks"])  # fmt: skip
    assert doc["paper"]["table_2"]["Ill"]["generalized_mean"] == 0.22
    # the steering-free lane-centring baseline: fitted on the seed's training run
    [fitted] = doc["baselines"]
    assert fitted["name"] == "lane_centring" and fitted["seed"] == 0 and fitted["error"] is None
    assert {"autoregression", "innovation_variance", "decimation_time"} <= set(fitted["params"])
    assert fitted["params"]["innovation_variance"] > 0


def test_results_sanity(outputs) -> None:
    """What any population must show."""
    result, _, _ = outputs
    est = {(r["driver"], r["model"]): r for r in result.estimation}
    for driver in ("Ill", "1", "2"):
        oracle = est[(driver, "oracle")]["lateral_rmse_mean"]
        blind = est[(driver, "no_steering")]["lateral_rmse_mean"]
        # two lanes 1.8 m apart and no steering: the mixture mean sits ~0.9 m from the truth
        assert 0.8 < blind < 1.0
        assert est[(driver, "no_steering")]["decided_runs"] == 0
        assert oracle < 0.05
        assert est[(driver, "oracle")]["steps_to_decide_median"] == 0
        # drivers who keep their lane: the lane-centring prior tells the lanes apart
        centring = est[(driver, "lane_centring")]
        assert oracle <= centring["lateral_rmse_mean"] < blind
        assert centring["wrong_lane_confident_runs"] == 0
        for model in ("two_point", "generalized", "near_far_pd"):
            assert oracle <= est[(driver, model)]["lateral_rmse_mean"]
    steer = {(r["driver"], r["model"]): r for r in result.steering}
    for driver in ("Ill", "1", "2"):
        two_point, general = steer[(driver, "two_point")], steer[(driver, "generalized")]
        # the generalized model nests more dynamics than the two-point model
        assert general["rmse"] < two_point["rmse"]
        assert general["rmse_decrease_vs_two_point"] == pytest.approx(
            1 - general["rmse"] / two_point["rmse"]
        )
        assert two_point["rmse_decrease_vs_two_point"] is None
    runs = pd.DataFrame(result.runs_steering)
    mean = runs[(runs.driver == "1") & (runs.model == "two_point") & (runs.track == "straight")]
    assert steer[("1", "two_point")]["rmse"] == pytest.approx(mean["rmse"].mean())
    ranks = {r["model"]: r["rank_steering"] for r in result.summary}
    # ranked against every steering model: two built-ins, the user model, road_blind
    assert sorted(v for v in ranks.values() if v is not None) == [1, 2, 3, 4]


def test_road_information_is_measured_against_the_road_blind_baseline(outputs) -> None:
    """1 - SSE / SSE of road_blind per run, its means per driver, its interval over them."""
    result, out, _ = outputs
    runs = pd.DataFrame(result.runs_steering)
    keys = ["seed", "driver", "track", "run"]
    blind = runs[runs.model == "road_blind"]
    assert (blind["road_information"] == 0.0).all()
    both = runs.merge(blind[[*keys, "rmse", "n"]], on=keys, suffixes=("", "_blind"))
    # on the samples both predict: the model's (its history is as long as the road-blind
    # model's or longer), so against the baseline's whole SSE the ratio can only be smaller,
    # and by little: a few samples of the start's transient out of ~400
    sse_ratio = both["rmse"] ** 2 * both["n"] / (both["rmse_blind"] ** 2 * both["n_blind"])
    ratio = 1.0 - both["road_information"].to_numpy()
    assert np.all(ratio >= sse_ratio * (1 - 1e-9))
    assert ratio == pytest.approx(sse_ratio, rel=0.05)
    assert (both["road_information"] <= 1.0).all()
    steer = {(r["driver"], r["model"]): r for r in result.steering}
    generalized = runs[(runs.driver == "1") & (runs.model == "generalized")]
    assert generalized["road_information"].mean() == pytest.approx(
        steer[("1", "generalized")]["road_information"]
    )
    summary = {r["model"]: r for r in result.summary}
    assert summary["road_blind"]["road_information"] == 0.0
    for row in summary.values():
        if row["road_information"] is None:
            assert row["kind"] == "baseline" and row["model"] != "road_blind"
            continue
        low, high = row["road_information_ci_low"], row["road_information_ci_high"]
        assert low <= row["road_information"] <= high <= 1.0
    assert "road info [95% CI]" in (out / "report.md").read_text()
    assert "road info" in (out / "report.html").read_text()


def test_output_files(outputs) -> None:
    result, out, written = outputs
    for name in [
        "results.json",
        "report.md",
        "report.html",
        *CSV_TABLES.values(),
        *FIGURES.values(),
    ]:
        assert (out / name).is_file(), name
        assert name in written
    for name in FIGURES.values():
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    csv = pd.read_csv(out / "estimation.csv")
    first = result.estimation[0]
    assert csv.loc[0, "model"] == first["model"]
    assert csv.loc[0, "lateral_rmse_mean"] == pytest.approx(first["lateral_rmse_mean"], rel=1e-12)
    report = (out / "report.md").read_text()
    assert "| Driver | Model |" in report and "![lateral_error](lateral_error.png)" in report
    assert "![reliability](reliability.png)" in report  # every seed: the table drawn
    assert "the reliability diagram shows every seed" in report
    assert "drivers (seed, name) that hold the most of each steering model's time" in report
    text = format_tables(result)
    assert "paper RMSE" in text and "near_far_pd" in text and "no_steering" in text


# ------------------------------------------------------------------ user models
def test_user_model_is_scored_and_ranked(outputs) -> None:
    result, _, _ = outputs
    info = {m["name"]: m for m in result.models}
    assert info["near_far_pd"]["kind"] == "user"
    assert info["near_far_pd"]["spec"] == "bench_user_models:NearFarPD"
    assert set(info["near_far_pd"]["parameters"]) == {"memory", "proportional", "derivative", "far"}
    assert info["near_far_pd"]["arx"] is True
    summary = {r["model"]: r for r in result.summary}
    assert summary["oracle"]["rank_lateral"] == 1  # ranked against every estimator
    assert summary["near_far_pd"]["rank_lateral"] in (2, 3, 4)
    assert summary["near_far_pd"]["rank_lateral_models"] == 6  # with the 3 baselines
    assert summary["near_far_pd"]["lateral_rmse"] < summary["no_steering"]["lateral_rmse"]


def test_load_user_model_errors(user_module: str) -> None:
    with pytest.raises(ModelError, match="no_such_module_xyz.*cannot import module") as info:
        load_user_model("no_such_module_xyz:Model")
    assert info.value.stage == "import"
    with pytest.raises(ModelError, match="has no attribute 'Missing'"):
        load_user_model(f"{user_module}:Missing")
    with pytest.raises(ModelError, match="NotAModel is not a SteeringModel") as info:
        load_user_model(f"{user_module}:NotAModel")
    assert info.value.stage == "interface"
    with pytest.raises(ModelError, match="package.module:ClassName"):
        load_user_model("no_colon_here")
    model = load_user_model(f"{user_module}:NearFarPD")
    assert model.name == "near_far_pd" and not model.is_fitted


def test_a_model_that_cannot_be_used_stops_the_bench_before_any_run(
    user_module: str, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.json").write_text('{"format": "hasa_bench.results"}')
    specs = ["no_such_module_xyz:Model", f"{user_module}:NotAModel", f"{user_module}:NearFarPD"]
    started = time.perf_counter()
    code = main(["score", *specs, *SMALL_ARGS, "--out", str(out), "--overwrite", "--quiet"])
    assert code == 2 and time.perf_counter() - started < 10  # no run was generated
    err = capsys.readouterr().err
    assert err.startswith("hasa-bench: error: 2 of 3 user model(s) cannot be used")
    assert "no_such_module_xyz" in err and "(import)" in err and "NotAModel" in err
    assert "(interface)" in err and "near_far_pd" not in err
    assert (out / "results.json").read_text() == '{"format": "hasa_bench.results"}'


@pytest.mark.slow
def test_broken_user_models_do_not_stop_the_others(user_module: str, tmp_path: Path) -> None:
    specs = [
        f"{user_module}:NaNModel",
        f"{user_module}:FitRaises",
        f"{user_module}:NearFarPD",
        f"{user_module}:NoARX",
    ]
    args = [
        "score",
        *specs,
        *SMALL_ARGS,
        "--curved-runs",
        "0",
        "--workers",
        "2",
        "--batch-size",
        "3",
    ]
    code = main([*args, "--out", str(tmp_path), "--quiet", "--no-plots"])
    assert code == 1
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["executor"]["tasks"] == 2  # the NaN model failed in worker processes
    errors = {e["model"]: e for e in doc["errors"]}
    assert set(errors) == {"nan_model", "fit_raises"}
    assert errors["nan_model"]["stage"] == "predict"
    assert "'nan_model'" in errors["nan_model"]["message"]
    assert "NaN" in errors["nan_model"]["message"]
    assert errors["fit_raises"]["stage"] == "fit"
    assert "cannot fit this" in errors["fit_raises"]["message"]
    scored = {r["model"] for r in doc["steering"]}
    assert scored == {"two_point", "generalized", "road_blind", "near_far_pd", "no_arx"}
    estimated = {"two_point", "generalized", "near_far_pd", "no_steering", "lane_centring",
                 "oracle"}  # fmt: skip
    assert {r["model"] for r in doc["estimation"]} == estimated
    no_arx = next(m for m in doc["models"] if m["name"] == "no_arx")
    assert no_arx["arx"] is False and "not an ARX model" in no_arx["note"]
    assert "no rows in the lateral-estimation table" in no_arx["note"]  # and why
    report = (tmp_path / "report.md").read_text()
    assert "it has no rows in the lateral-estimation table" in report
    ranks = {r["model"]: (r["rank_steering"], r["rank_lateral"]) for r in doc["summary"]}
    assert ranks["no_arx"][0] is not None and ranks["no_arx"][1] is None
    assert all(r["driver"] in ("Ill", "1", "2") for r in doc["steering"])
    assert (tmp_path / "report.md").read_text().count("fit_raises") >= 1


@pytest.mark.slow
def test_several_seeds_give_a_verdict_with_intervals(user_module: str) -> None:
    config = ProtocolConfig(**(SMALL | {"seeds": (3, 4), "curved_runs": 0}))
    calls: list[tuple[str, int, int]] = []
    result = run_protocol(
        config, [f"{user_module}:NearFarPD"], workers=1, progress=lambda *c: calls.append(c)
    )
    # every long stage reports done/total, so the command line shows an estimate for each
    assert [c for c in calls if c[0] == "fits"] == [("fits", 0, 2), ("fits", 1, 2), ("fits", 2, 2)]
    runs = [c for c in calls if c[0] == "runs"]
    assert runs[0][1] == 0 and runs[-1][1] == runs[-1][2] > 0
    doc = result.to_json_dict()
    assert doc["config"]["seeds"] == [3, 4]
    assert {r["seed"] for r in doc["steering"]} == {3, 4} == {r["seed"] for r in doc["estimation"]}
    assert len(doc["models"]) == 2 * 4  # every model fitted on each seed's own training run
    per_seed = [r for r in doc["seed_summary"] if r["model"] == "generalized"]
    assert [r["seed"] for r in per_seed] == [3, 4]
    summary = {r["model"]: r for r in doc["summary"]}
    gen = summary["generalized"]
    assert gen["seeds"] == 2
    values = [r["lateral_rmse"] for r in per_seed]
    assert gen["lateral_rmse"] == pytest.approx(np.mean(values))
    # the hierarchical bootstrap's interval lies within the per-driver values it resamples
    per_driver = [r["lateral_rmse_mean"] for r in doc["estimation"] if r["model"] == "generalized"]
    assert min(per_driver) <= gen["lateral_rmse_ci_low"] <= gen["lateral_rmse_ci_high"]
    assert gen["lateral_rmse_ci_high"] <= max(per_driver)
    for row in summary.values():
        if row["kind"] in ("builtin", "user", "baseline") and row["lateral_rmse"] is not None:
            assert 0.0 <= row["rank_lateral_stability"] <= 1.0
        if row["estimated_runs"]:
            assert (
                row["wrong_lane_confident_runs_share_ci_low"]
                <= row["wrong_lane_confident_runs_share"]
                <= row["wrong_lane_confident_runs_share_ci_high"]
            )
    text = format_tables(result)
    assert "Verdict over 2 population seeds [3, 4]" in text and "95% CI" in text


@pytest.mark.slow
def test_stress_set_and_unchecked_estimators_are_scored(tmp_path: Path) -> None:
    config = ProtocolConfig(**(SMALL | {"curved_runs": 0}), stress=True, compare_checks=True)
    result = run_protocol(config, workers=1)
    write_outputs(result, tmp_path, figures=False)  # the schema knows the stress rows
    assert folder_problems(tmp_path) == []
    assert "stress_sign_flipped (no checks)" in (tmp_path / "report.html").read_text()
    summary = {r["model"]: r for r in result.summary}
    stress = ["stress_no_lane_info", "stress_sign_flipped", "stress_random_arx",
              "stress_unregularized"]  # fmt: skip
    for name in stress:
        assert summary[name]["kind"] == "stress"
        assert summary[f"{name} (no checks)"]["kind"] == "unchecked"
        assert summary[name]["rank_lateral"] is None  # not ranked against real models
    assert summary["generalized (no checks)"]["estimated_runs"] == 6
    # the constant-speed least-squares fit is the collinear one of issue 10
    fit = next(m for m in result.models if m["name"] == "stress_unregularized")
    assert fit["checks"]["ridge_lambda"] == 0.0
    assert fit["checks"]["condition_number"] > 1e6 and "ill_conditioned" in fit["checks"]["flags"]
    # no lane information: the filter stays at the prior and says so
    rows = [r for r in result.runs_estimation if r["model"] == "stress_no_lane_info"]
    assert all(r["final_decision"] == "undecided" and not r["wrong_lane_confident"] for r in rows)
    text = format_tables(result)
    assert "Lane decisions" in text and "stress_sign_flipped (no checks)" in text
    # a model that drives off the road gives no lane evidence (with the checks), on this
    # 4 s training run the random ARX and the unregularized fit
    described = {m["name"]: m for m in result.models}
    assert described["generalized"]["lane_keeping"]["passed"]
    assert "lane_keeping" not in described["road_blind"]
    failed = [n for n in stress if not described[n]["lane_keeping"]["passed"]]
    assert failed
    for name in failed:
        checked = [r for r in result.runs_estimation if r["model"] == name]
        unchecked = [r for r in result.runs_estimation if r["model"] == f"{name} (no checks)"]
        assert checked and all(r["final_decision"] == "undecided" for r in checked)
        assert any(r["final_decision"] != "undecided" for r in unchecked)
        # its channel is off at every step (refused), not "unused" (missing or gated)
        assert all(r["steering_off_share"] > 0.99 and r["steering_unused_share"] == 0
                   and r["steering_live_share"] == 0 for r in checked)  # fmt: skip
    assert "off road 4/4" in text  # the Checks table says so
    assert "predicts (vs own past)" in text and " x: no better" in text  # and this one
    # nor does one that predicts the steering no better than its own past (design §8.13.1)
    level = {n: m["prediction_residual_std"] / m["lane_free_residual_std"] for n, m in
             described.items() if m.get("lane_free_residual_std")}  # fmt: skip
    assert level["generalized"] < 1 < 10 < level["stress_random_arx"]
    assert not described["generalized"]["steering_trust"][0].startswith("steering off:")
    for name in stress:
        if level[name] >= 1 and described[name]["lane_keeping"]["passed"]:
            assert described[name]["steering_trust"] == [
                r for r in described[name]["steering_trust"] if "its own past" in r
            ]
            rows = [r for r in result.runs_estimation if r["model"] == name]
            assert rows and all(r["final_decision"] == "undecided" for r in rows)


# --------------------------------------------------------------- determinism
@pytest.mark.slow
def test_same_results_with_one_and_two_workers(outputs) -> None:
    config = ProtocolConfig(**SMALL, batch_size=2)
    one = run_protocol(config, ["bench_user_models:NearFarPD"], workers=1)
    two = run_protocol(config, ["bench_user_models:NearFarPD"], workers=2)
    assert one.executor["tasks"] == two.executor["tasks"] == 4
    assert _tables(two) == _tables(one)
    # another batch size: the same runs and the same numbers up to rounding
    other = _tables(outputs[0])
    for key, rows in _tables(one).items():
        assert len(rows) == len(other[key])
        for mine, theirs in zip(rows, other[key], strict=True):
            assert mine.keys() == theirs.keys()
            for field, value in mine.items():
                if isinstance(value, float):
                    assert value == pytest.approx(theirs[field], rel=1e-9, abs=1e-15), field
                else:
                    assert value == theirs[field], field


@pytest.mark.slow
@pytest.mark.parametrize(("n_workers", "processes"), [(2, False), (1, True)])
def test_same_results_through_dask(outputs, n_workers: int, processes: bool) -> None:
    distributed = pytest.importorskip("distributed")
    reference = outputs[0]
    config = ProtocolConfig(**SMALL)
    with distributed.LocalCluster(
        n_workers=n_workers,
        threads_per_worker=1,
        processes=processes,
        dashboard_address=None,
    ) as cluster:
        result = run_protocol(config, workers=None, scheduler=cluster.scheduler_address)
    assert result.executor["kind"] == "dask"
    user = "near_far_pd"
    expected = {
        key: [r for r in rows if r["model"] != user] for key, rows in _tables(reference).items()
    }
    assert _tables(result) == expected


def test_unreachable_scheduler_is_a_clear_error(tmp_path: Path) -> None:
    dask = pytest.importorskip("dask")
    pytest.importorskip("distributed")
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        with pytest.raises(BenchmarkError, match="cannot run the tasks on the Dask scheduler"):
            run_protocol(ProtocolConfig(**SMALL), scheduler="tcp://127.0.0.1:9")


# ------------------------------------------------------------------ recordings
@pytest.mark.slow
def test_recordings_give_the_same_numbers_as_the_synthetic_runs(tmp_path: Path) -> None:
    """Saved runs (the recording format writes floats exactly) score exactly as generated."""
    from hasa_env.drivers import population, run_population, save_runs

    config = ProtocolConfig(
        seeds=(0,), drivers=2, runs=2, ill_runs=3, duration=3.0, curved_runs=1, training_drivers=0
    )  # recordings train on the illustrative driver's runs only
    synthetic = run_protocol(config, workers=1)
    drivers = population("paper", seed=0, size=2)
    env = config.env_config()  # the population's study conditions and the run length
    straight = run_population(drivers, runs=2, seed=0, config=env, runs_by_name={"Ill": 3})
    curved = run_population(
        drivers[:1], runs=1, seed=0, env_id="hasa_env/LaneKeepingCurved-v0", config=env
    )
    for name, frames in straight.items():
        save_runs(frames, tmp_path / name, prefix="straight")
    save_runs(curved["Ill"], tmp_path / "Ill", prefix="curved")
    recorded = run_protocol(replace_recordings(config, tmp_path), workers=1)
    assert recorded.config["illustrative"] == "Ill"

    def unseeded(tables: dict) -> dict:  # recordings have no population seed
        return {k: [{f: v for f, v in r.items() if f != "seed"} for r in rows]
                for k, rows in tables.items()}  # fmt: skip

    assert all(r["seed"] is None for r in recorded.runs_estimation)
    assert unseeded(_tables(recorded)) == unseeded(_tables(synthetic))


def replace_recordings(config: ProtocolConfig, folder: Path) -> ProtocolConfig:
    from dataclasses import replace

    return replace(config, recordings=str(folder), min_duration=1.0)  # 3 s runs


def test_recordings_errors(tmp_path: Path) -> None:
    with pytest.raises(BenchmarkError, match="does not exist"):
        run_protocol(ProtocolConfig(recordings=str(tmp_path / "nope")))
    with pytest.raises(BenchmarkError, match="no recordings"):
        run_protocol(ProtocolConfig(recordings=str(tmp_path)))


# -------------------------------------------------------------------------- CLI
def test_cli_paper_writes_everything(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    args = ["paper", *SMALL_ARGS, "--drivers", "2", "--curved-runs", "0", "--workers", "1"]
    code = main([*args, "--out", str(tmp_path / "out"), "--camera-noise", "0.1"])
    assert code == 0
    shown = capsys.readouterr().out
    assert "Steering prediction (paper table 1)" in shown and "Lateral estimation" in shown
    doc = json.loads((tmp_path / "out" / "results.json").read_text())
    assert doc["config"]["noise"] == {"camera": 0.1}
    assert doc["curved"] == []
    assert {r["driver"] for r in doc["steering"]} == {"Ill", "1"}


@pytest.mark.parametrize(
    "args",
    [
        ["paper", "--runs", "0"],
        ["paper", "--track", "none"],
        ["paper", "--workers", "0"],
        ["paper", "--population", "nobody"],
        ["perf", "--only", "nothing"],
    ],  # fmt: skip
)
def test_cli_rejects_bad_arguments(args: list[str], tmp_path: Path) -> None:
    try:
        code = main([*args, *(["--out", str(tmp_path / "o")] if args[0] == "paper" else [])])
    except SystemExit as exc:  # argparse
        code = exc.code
    assert code == 2
    assert not (tmp_path / "o" / "results.json").exists()


def test_protocol_config_validation() -> None:
    with pytest.raises(
        BenchmarkError, match="'training_run' = 3 and 'training_runs' = 1 need at least 4 runs"
    ):
        ProtocolConfig(ill_runs=3, training_run=3)
    with pytest.raises(
        BenchmarkError, match=r"unknown protocol setting 'noise.lidar' \(allowed keys here: camera,"
    ):
        ProtocolConfig(noise={"lidar": 0.1})
    with pytest.raises(BenchmarkError, match=r"'duration' must be a finite number >= 1 s, got 0.1"):
        ProtocolConfig(duration=0.1)


# ------------------------------------------------------------------------- perf
def test_perf_rows_read_every_benchmark_layout() -> None:
    env_like = {
        "ratios": {"hasa_over_pendulum": 3.0, "hasa_over_highway": None},
        "targets": {
            "hasa_over_pendulum": {
                "description": "hasa / Pendulum",
                "value": 3.0,
                "minimum": 2.0,
                "passed": True,
            },  # fmt: skip
            "hasa_over_highway": {
                "description": "hasa / highway",
                "value": None,
                "minimum": 10.0,
                "passed": None,
            },  # fmt: skip
        },
    }
    est_like = {
        "ratios": {"filterpy_over_ours_2": 4.0, "filterpy_over_ours_8": 9.0},
        "targets": {
            "filterpy_over_ours_2": {
                "description": "filterpy / ours",
                "value": 4.0,
                "minimum": 5.0,
                "passed": False,
            },  # fmt: skip
        },
    }

    class Render:
        TARGETS = {"driver_draw": ("60 fps", 60.0)}

    render_like = {
        "ratios_to_target": {"driver_draw": 2.5},
        "results": {"driver_draw": {"frames_per_second": 150.0}},
        "ratios": {"participant_over_developer": 0.9},
    }
    rows = (
        perf_rows("perf_env", env_like)
        + perf_rows("perf_estimators", est_like)
        + perf_rows("perf_render", render_like, Render)
    )
    assert [r["passed"] for r in rows] == [True, None, False, None, True, None]
    assert rows[0]["ratio_to_target"] == pytest.approx(1.5)
    assert rows[3]["measure"] == "filterpy over ours 8" and rows[3]["target"] is None
    assert rows[4]["value"] == 150.0 and rows[4]["target"] == 60.0
    assert rows[5]["measure"] == "participant over developer (ratio, same run)"
    assert rows[5]["value"] == 0.9 and rows[5]["target"] is None
    table = format_perf_table(rows)
    assert "FAIL" in table and "PASS" in table and "2.50x" in table


@pytest.mark.slow
def test_cli_perf_quick_runs_a_real_benchmark(
    capsys: pytest.CaptureFixture, tmp_path: Path
) -> None:
    path = tmp_path / "perf.json"
    code = main(["perf", "--quick", "--only", "estimators", "--json", str(path)])
    assert code == 0
    shown = capsys.readouterr().out
    assert "perf_estimators" in shown and "filterpy" in shown
    doc = json.loads(path.read_text())
    assert doc["rows"] and all(r["benchmark"] == "perf_estimators" for r in doc["rows"])


def test_cli_perf_refuses_an_unwritable_json_before_measuring(
    capsys: pytest.CaptureFixture, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A --json whose folder is missing is named at once (exit 2), not after minutes of
    measuring with a traceback; the file is written atomically when it can be."""
    import benchmarks.perf

    def measured(*_: object) -> None:
        raise AssertionError("measured before the output was checked")

    monkeypatch.setattr(benchmarks.perf, "run_benchmarks", measured)
    target = tmp_path / "missing" / "perf.json"
    assert main(["perf", "--quick", "--json", str(target)]) == 2
    assert f"--json {target}: directory {target.parent} does not exist" in capsys.readouterr().err
    assert main(["perf", "--quick", "--json", "-"]) == 2
    assert not target.parent.exists()


def test_python_dash_m_benchmarks_is_the_cli() -> None:
    import subprocess

    done = subprocess.run(
        [sys.executable, "-m", "hasa_cli.bench", "score", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=Path(__file__).resolve().parent.parent,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    for option in ("--recordings", "--scheduler", "--workers", "--population", "--quiet"):
        assert option in done.stdout


def test_findings_name_estimators_confidently_wrong_in_more_than_one_percent() -> None:
    rows = [
        # 4 + 1 of 485 runs: 1.03 % (straight and curved together)
        {"model": "bad", "estimated_runs": 465.0, "wrong_lane_confident_runs": 4.0,
         "curved_estimated_runs": 20.0, "curved_wrong_lane_confident_runs": 1.0},
        # 4 of 485: 0.82 %, under the bound
        {"model": "ok", "estimated_runs": 465.0, "wrong_lane_confident_runs": 4.0,
         "curved_estimated_runs": 20.0, "curved_wrong_lane_confident_runs": 0.0},
        # no curved track: 2 of 100
        {"model": "straight_only", "estimated_runs": 100.0, "wrong_lane_confident_runs": 2.0},
        # a model without estimation rows
        {"model": "road_blind", "estimated_runs": None, "wrong_lane_confident_runs": None},
    ]  # fmt: skip
    result: Any = SimpleNamespace(summary=rows)
    assert _unsafe_estimators(result) == [
        "bad 5/485 (1.0%)",
        "straight_only 2/100 (2.0%)",
    ]


def test_versions_say_whether_the_tree_had_changes(tmp_path: Path, monkeypatch) -> None:
    """results.json's versions: git_commit alone does not say what ran; git_tree does."""
    import subprocess

    from benchmarks import documents

    out = documents.versions()
    if "git_commit" in out:  # a git checkout (CI: a clean clone)
        assert out["git_tree"] in ("clean", "modified")
    calls = []

    def fake_run(argv, **_):
        calls.append(argv)
        text = "abc123\n" if "rev-parse" in argv else " M benchmarks/report.py\n"
        return subprocess.CompletedProcess(argv, 0, stdout=text, stderr="")

    monkeypatch.setattr(documents.subprocess, "run", fake_run)
    faked = documents.versions()
    assert faked["git_commit"] == "abc123" and faked["git_tree"] == "modified"
    assert any("--porcelain" in argv for argv in calls)
