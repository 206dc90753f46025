"""``hasa-bench paper --recordings`` scores one scenario per folder: the training run's.

A folder with recordings of two scenarios (synthetic drivers saved as recordings, one of
them an old recording whose config has no ``scenario`` key) is not pooled: the runs of the
training run's scenario are scored, the others are listed as skipped with the reason, and
the results' config and notes name the scenario scored.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from benchmarks.protocol import ProtocolConfig, run_protocol
from benchmarks.protocol.plan import recording_plan
from benchmarks.report import format_tables
from hasa_env.drivers import population, run_population, save_runs
from hasa_env.recording import load_recording


@pytest.fixture(scope="module")
def mixed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Ill and 1: two paper runs each (Ill's first an old recording without the key) and
    one lane_shift run each, of 3 s."""
    root = tmp_path_factory.mktemp("mixed")
    drivers = population("paper-pi", seed=0, size=2)
    for scenario, runs, seed in (("paper", 2, 0), ("lane_shift", 1, 1)):
        config = {"time_limit": 3.0, "scenario": scenario}
        for name, frames in run_population(drivers, runs=runs, seed=seed, config=config).items():
            save_runs(frames, root / name, scenario)
    old = root / "Ill" / "paper_000.json"
    meta = json.loads(old.read_text())
    del meta["config"]["scenario"]  # written before scenarios existed
    old.write_text(json.dumps(meta))
    return root


def _names(paths) -> list[str]:
    return sorted(f"{Path(p).parent.name}/{Path(p).name}" for p in paths)


def test_the_training_runs_scenario_is_scored_and_the_others_are_skipped(mixed: Path) -> None:
    assert "scenario" not in json.loads((mixed / "Ill" / "paper_000.json").read_text())["config"]
    # by default the training run is Ill's first recording by name: lane_shift_000
    plan = recording_plan(ProtocolConfig(recordings=str(mixed), min_duration=1.0))
    assert plan.scenario == "lane_shift"
    assert _names(r.path for r in plan.main) == ["1/lane_shift_000.csv", "Ill/lane_shift_000.csv"]
    assert plan.training().path.endswith("Ill/lane_shift_000.csv")
    assert len(plan.skipped) == 4 and all(
        s["reason"] == "scenario paper, not the training run's lane_shift (score it with a "
        "folder of its own)" for s in plan.skipped
    )  # fmt: skip
    assert any("scenario 'lane_shift' (the training run's)" in n for n in plan.notes)
    assert any("4 recording(s) of other scenarios than 'lane_shift' not scored" in n
               for n in plan.notes)  # fmt: skip
    assert any("fitted on a run of 'lane_shift' itself" in n for n in plan.notes)
    # the old recording (no scenario key: paper) as the training file: paper is scored
    training = mixed / "Ill" / "paper_000.csv"
    assert load_recording(training).config["scenario"] == "paper"
    paper = recording_plan(
        ProtocolConfig(recordings=str(mixed), min_duration=1.0, training_file=str(training))
    )
    assert paper.scenario == "paper"
    assert _names(r.path for r in paper.main) == [
        "1/paper_000.csv", "1/paper_001.csv", "Ill/paper_000.csv", "Ill/paper_001.csv"]  # fmt: skip
    assert Path(paper.training().path).resolve() == training.resolve()
    skipped = {f"{Path(s['file']).parent.name}/{Path(s['file']).name}": s["reason"]
               for s in paper.skipped}  # fmt: skip
    reason = ("scenario lane_shift, not the training run's paper (score it with a folder of "
              "its own)")  # fmt: skip
    assert skipped == {"1/lane_shift_000.csv": reason, "Ill/lane_shift_000.csv": reason}
    assert not any("itself" in n for n in paper.notes)


def test_the_results_name_the_scenario_scored(mixed: Path) -> None:
    base = ProtocolConfig(recordings=str(mixed), min_duration=1.0, estimate=False)
    result = run_protocol(base, workers=1)
    assert result.config["scenario"] == "lane_shift"
    assert f"recordings in {mixed} (scenario 'lane_shift')" in format_tables(result)
    assert {Path(s["file"]).name for s in result.skipped} == {"paper_000.csv", "paper_001.csv"}
    scored = {(r["driver"], r["run"]) for r in result.runs_steering}
    assert scored == {("1", 0)}  # Ill's one lane_shift run trains, 1's is scored
    training = mixed / "Ill" / "paper_001.csv"
    paper = run_protocol(replace(base, training_file=str(training)), workers=1)
    assert paper.config["scenario"] == "paper"
    assert {(r["driver"], r["run"]) for r in paper.runs_steering} == {
        ("Ill", 0), ("1", 0), ("1", 1)}  # fmt: skip
