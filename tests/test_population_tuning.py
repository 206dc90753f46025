"""The numbers in docs/population_tuning.md come from benchmarks.population_tuning (rerun here)."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.population_tuning import RANGE, evaluate, read_report

DOC = Path(__file__).resolve().parent.parent / "docs" / "population_tuning.md"

pytestmark = pytest.mark.slow


def test_the_documented_calibration_reruns_to_the_same_numbers():
    report = read_report(DOC)
    chosen = report["chosen"]
    seed = chosen["seeds"][0]
    documented = next(e for e in chosen["per_seed"] if e["seed"] == seed)
    rerun = evaluate(chosen["population"], (seed,), workers=1)["per_seed"][0]
    for key in ("two_point", "generalized", "sdlp", "max_abs_lateral_offset"):
        assert rerun[key] == pytest.approx(documented[key], rel=1e-6), key
    for key in ("left_road_runs", "runs", "flags"):
        assert rerun[key] == documented[key], key


def test_the_documented_calibration_meets_its_target():
    chosen = read_report(DOC)["chosen"]
    low, high = RANGE
    for entry in chosen["per_seed"]:
        for model in ("two_point", "generalized"):
            if "collinear_features" not in entry["flags"].get(model, []):
                assert low <= entry[model] <= high, (entry["seed"], model, entry[model])
        assert entry["left_road_runs"] == 0
    assert chosen["within_range_unflagged"] is True
    text = DOC.read_text(encoding="utf-8")
    assert "python -m benchmarks.population_tuning" in text  # how to rerun it
