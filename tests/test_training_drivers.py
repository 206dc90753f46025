"""Training on several drivers (issue 25 item 1, docs/design.md §8.20, §8.21):
``--training-drivers N`` adds one run each of N drivers drawn from the same population, scored
nowhere; 8 by default for synthetic runs, 0 (the paper's protocol) on request and with
recordings."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest

from benchmarks.protocol import BenchmarkError, ProtocolConfig
from benchmarks.protocol.plan import TRAINING_DRIVER_PREFIX, make_plan, training_population
from benchmarks.protocol.suite import fit_key
from hasa_cli.bench import main

TINY = ["--seed", "0", "--population", "paper-pi", "--drivers", "2", "--runs", "1",
        "--ill-runs", "2", "--duration", "4", "--curved-runs", "0", "--no-plots", "--quiet"]  # fmt: skip
CONFIG = ProtocolConfig(seeds=(0,), population="paper-pi", drivers=2, runs=1, ill_runs=2,
                        duration=4.0, curved_runs=0, training_drivers=0)  # fmt: skip


def test_the_training_drivers_are_a_draw_of_their_own_named_apart_and_reproducible() -> None:
    config = replace(CONFIG, training_drivers=3)
    drawn = training_population(config, 0)
    assert [p.name for p in drawn] == ["train-Ill", "train-1", "train-2"]
    assert [p.to_dict() for p in drawn] == [p.to_dict() for p in training_population(config, 0)]
    other = training_population(config, 1)
    assert [p.to_dict() for p in drawn] != [p.to_dict() for p in other]
    plan = make_plan(config, 0)
    assert not any(name.startswith(TRAINING_DRIVER_PREFIX) for name in plan.params)
    runs = plan.driver_trainings()
    assert [r.driver for r in runs] == ["train-Ill", "train-1", "train-2"]
    main_seeds = {(r.env_seed, r.driver_seed) for r in plan.main}
    assert not {(r.env_seed, r.driver_seed) for r in runs} & main_seeds
    assert not {r.driver for r in runs} & {r.driver for r in plan.validation()}
    # a suite refits when the training drivers change, and only then
    assert fit_key(plan) != fit_key(make_plan(CONFIG, 0))
    assert fit_key(plan) == fit_key(make_plan(config, 0))


def test_the_default_trains_on_eight_more_drivers_and_zero_is_the_papers_protocol() -> None:
    assert ProtocolConfig().training_drivers == 8
    assert ProtocolConfig(recordings="r").training_drivers == 0  # no population to draw from
    default = make_plan(replace(CONFIG, training_drivers=None), 0)
    assert len(default.driver_trainings()) == 8
    plan = make_plan(CONFIG, 0)
    assert plan.driver_trainings() == [] and plan.training_drivers == ()


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"training_drivers": -1}, "training_drivers"),
        ({"training_drivers": 2, "recordings": "r"}, "must be 0"),
    ],
)
def test_training_drivers_out_of_range_are_refused(settings: dict, message: str) -> None:
    with pytest.raises(BenchmarkError, match=message):
        ProtocolConfig(**settings)


def test_the_training_drivers_train_the_models_and_are_scored_nowhere(tmp_path: Path) -> None:
    plain, more = tmp_path / "plain", tmp_path / "more"
    assert main(["paper", *TINY, "--training-drivers", "0", "--out", str(plain)]) == 0
    assert main(["paper", *TINY, "--training-drivers", "2", "--out", str(more)]) == 0
    doc = json.loads((more / "results.json").read_text())
    assert doc["config"]["training_drivers"] == 2
    assert json.loads((plain / "results.json").read_text())["config"]["training_drivers"] == 0
    assert (
        "models fitted on run 0 of Ill (each seed's) and one run each of 2 more drivers of the "
        "population." in (more / "report.md").read_text()
    )
    scored = pd.read_csv(more / "runs_estimation.csv")
    assert not scored["driver"].astype(str).str.startswith(TRAINING_DRIVER_PREFIX).any()
    before = pd.read_csv(plain / "runs_estimation.csv")
    assert sorted(map(tuple, scored[["driver", "run"]].drop_duplicates().to_numpy())) == sorted(
        map(tuple, before[["driver", "run"]].drop_duplicates().to_numpy())
    )  # the same runs are scored
    fitted = {m["name"]: m for m in doc["models"]}
    alone = {m["name"]: m for m in json.loads((plain / "results.json").read_text())["models"]}
    assert fitted["generalized"]["parameters"] != alone["generalized"]["parameters"]
    assert (
        fitted["generalized"]["filter_residual_std"] != alone["generalized"]["filter_residual_std"]
    )


def test_a_negative_training_drivers_option_is_refused_by_name(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code = main(["paper", *TINY, "--training-drivers", "-1"])
    assert code != 0
    assert "training_drivers" in capsys.readouterr().err
