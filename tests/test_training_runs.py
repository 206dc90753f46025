"""Several training runs (issue 25 item 1): ``--training-runs N`` fits the models on the
illustrative driver's runs ``training_run`` .. ``training_run + N - 1`` and scores the rest."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest

from benchmarks.protocol import BenchmarkError, ProtocolConfig
from benchmarks.protocol.plan import make_plan
from hasa_cli.bench import main

TINY = ["--seed", "0", "--population", "paper-pi", "--drivers", "2", "--runs", "1",
        "--ill-runs", "4", "--duration", "4", "--curved-runs", "0", "--no-plots", "--quiet"]  # fmt: skip


def test_the_training_runs_are_fitted_on_and_left_out_of_the_scores(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert main(["paper", *TINY, "--training-runs", "3", "--out", str(out)]) == 0
    doc = json.loads((out / "results.json").read_text())
    assert doc["config"]["training_runs"] == 3
    runs = pd.read_csv(out / "runs_estimation.csv")
    assert sorted(runs.loc[runs["driver"] == "Ill", "run"].unique()) == [3]  # 0-2 trained
    assert "models fitted on runs 0-2 of Ill" in (out / "report.md").read_text()
    # the speed range the models are trusted at is that of all three runs
    config = ProtocolConfig(seeds=(0,), population="paper-pi", drivers=2, runs=1, ill_runs=4,
                            duration=4.0, curved_runs=0)  # fmt: skip
    plan = make_plan(replace(config, training_runs=3), 0)
    trainings = plan.trainings()
    assert [r.index for r in trainings] == [0, 1, 2]
    assert all(r.driver == "Ill" for r in trainings)
    assert not {r.key for r in trainings} & {r.key for r in plan.validation()}
    generalized = next(m for m in doc["models"] if m["name"] == "generalized")
    low, high = generalized["steering_speed_limits"]
    assert low <= 14.1 and high >= 15.9  # 15 m/s held, +- the 1 m/s margin


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"ill_runs": 3, "training_runs": 4}, "need at least 4 runs of the illustrative driver"),
        ({"training_run": 2, "training_runs": 2, "ill_runs": 3}, "need at least 4 runs"),
        ({"training_runs": 0}, "training_runs"),
        ({"training_runs": 2, "training_file": "x.csv", "recordings": "r"}, "must be 1"),
    ],
)
def test_training_runs_out_of_range_are_refused(settings: dict, message: str) -> None:
    with pytest.raises(BenchmarkError, match=message):
        ProtocolConfig(**settings)


def test_the_default_is_the_papers_one_run_protocol(tmp_path: Path) -> None:
    assert ProtocolConfig().training_runs == 1
    out = tmp_path / "out"
    assert main(["paper", *TINY, "--out", str(out)]) == 0
    runs = pd.read_csv(out / "runs_estimation.csv")
    assert sorted(runs.loc[runs["driver"] == "Ill", "run"].unique()) == [1, 2, 3]


@pytest.mark.slow
def test_training_speeds_add_runs_at_those_speeds_and_widen_the_trusted_range(
    tmp_path: Path,
) -> None:
    out = tmp_path / "out"
    assert main(["paper", *TINY, "--training-speeds", "25", "--out", str(out)]) == 0
    doc = json.loads((out / "results.json").read_text())
    assert doc["config"]["training_speeds"] == [25.0]
    runs = pd.read_csv(out / "runs_estimation.csv")
    # the extra run is scored nowhere; Ill's main runs are scored as without it
    assert sorted(runs.loc[runs["driver"] == "Ill", "run"].unique()) == [1, 2, 3]
    generalized = next(m for m in doc["models"] if m["name"] == "generalized")
    low, high = generalized["steering_speed_limits"]
    assert low <= 14.1 and 25.9 <= high < 30.0  # 15 and 25 m/s, +- the 1 m/s margin
    assert "runs started at 25 m/s" in (out / "report.md").read_text()
    config = ProtocolConfig(seeds=(0,), population="paper-pi", drivers=2, runs=1, ill_runs=4,
                            duration=4.0, curved_runs=0, training_speeds=(25.0, 35.0))  # fmt: skip
    plan = make_plan(config, 0)
    extra = plan.speed_trainings()
    assert [(r.driver, r.index, v) for r, v in extra] == [("Ill", -1, 25.0), ("Ill", -2, 35.0)]
    main_seeds = {(r.env_seed, r.driver_seed) for r in plan.main}
    assert not {(r.env_seed, r.driver_seed) for r, _ in extra} & main_seeds


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"training_speeds": (0.5,)}, "training_speeds"),
        ({"training_speeds": (25.0, 25.0)}, "training_speeds"),
        ({"training_speeds": (70.0,)}, "'training_speeds': 70 m/s"),  # above vehicle.max_speed
        ({"training_speeds": (25.0,), "recordings": "r"}, "must be empty"),
    ],
)
def test_training_speeds_out_of_range_are_refused(settings: dict, message: str) -> None:
    with pytest.raises(BenchmarkError, match=message):
        ProtocolConfig(**settings)


@pytest.mark.parametrize("value", ["0", "nan", "15,15", "fast", ""])
def test_a_bad_training_speeds_option_is_a_usage_error(
    value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["paper", *TINY, "--training-speeds", value])
    assert stop.value.code == 2
    assert "--training-speeds" in capsys.readouterr().err
