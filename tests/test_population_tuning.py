"""docs/population_tuning.md is what benchmarks.population_tuning writes.

The fast tests read the command in the report's header and check that the report has the
sections, tables and rows :func:`write_report` writes for that command; the slow ones rerun
the calibration on one seed (its numbers and its target), nothing is checked against numbers
pasted in the document alone.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from benchmarks.population_tuning import RANGE, command_parser, evaluate, read_report, write_report

DOC = Path(__file__).resolve().parent.parent / "docs" / "population_tuning.md"


def _command(text: str) -> list[str]:
    """The arguments of the ``python -m benchmarks.population_tuning`` command in the header."""
    match = re.search(r"Written by `python -m benchmarks\.population_tuning ([^`]*)`", text)
    assert match, "the report does not say which command wrote it"
    return shlex.split(match.group(1))


def _entry(population: str, seeds: list[int], command: float, pedal: float) -> dict:
    """An :func:`evaluate` result of the right shape (its numbers are placeholders)."""
    ratio = {"mean": 1.0, "ci_low": 0.5, "ci_high": 1.5}
    per_seed = [
        {"seed": s, "two_point": 1.0, "generalized": 1.0, "sdlp": 0.3,
         "max_abs_lateral_offset": 1.0, "left_road_runs": 0, "runs": 10, "flags": {}}
        for s in seeds
    ]  # fmt: skip
    return {
        "population": population, "command_scale": command, "pedal_scale": pedal,
        "seeds": seeds, "per_seed": per_seed, "two_point": ratio, "generalized": ratio,
        "sdlp": 0.3, "max_abs_lateral_offset": 1.0, "left_road_runs": 0,
        "within_range": True, "within_range_unflagged": True,
    }  # fmt: skip


def _skeleton(text: str) -> list[str]:
    """The headings, table headers and row labels of a report (no numbers of its own)."""
    out = []
    for line in text.splitlines():
        if line.startswith("#") or line.startswith("| |") or line.startswith("|---"):
            out.append(line)
        elif line.startswith("| "):
            out.append(line.split("|")[1].strip())
    return out


def test_the_report_names_the_command_that_wrote_it():
    args = command_parser().parse_args(_command(DOC.read_text(encoding="utf-8")))
    assert args.write == "docs/population_tuning.md"
    assert [int(s) for s in args.seeds.split(",")]


def test_the_report_has_what_write_report_writes_for_its_command(tmp_path):
    text = DOC.read_text(encoding="utf-8")
    args = command_parser().parse_args(_command(text))
    seeds = [int(s) for s in args.seeds.split(",")]
    chosen = _entry(args.population, seeds, 1.0, 1.0)
    grid = [_entry(args.population, seeds, float(g), 1.0) for g in args.grid.split(",") if g]
    pedal = [_entry(args.population, seeds, 1.0, float(g)) for g in args.pedal_grid.split(",") if g]
    written = tmp_path / "report.md"
    write_report(chosen, grid, written, pedal)
    assert _skeleton(text) == _skeleton(written.read_text(encoding="utf-8"))
    assert read_report(DOC)["chosen"]["seeds"] == seeds  # the JSON block is of the same run


@pytest.fixture(scope="module")
def rerun() -> tuple[dict, dict]:
    """(the report's first seed as documented, the same seed rerun)."""
    chosen = read_report(DOC)["chosen"]
    seed = chosen["seeds"][0]
    documented = next(e for e in chosen["per_seed"] if e["seed"] == seed)
    return documented, evaluate(chosen["population"], (seed,), workers=1)


@pytest.mark.slow
def test_the_documented_calibration_reruns_to_the_same_numbers(rerun):
    documented, result = rerun
    again = result["per_seed"][0]
    for key in ("two_point", "generalized", "sdlp", "max_abs_lateral_offset"):
        assert again[key] == pytest.approx(documented[key], rel=1e-6), key
    for key in ("left_road_runs", "runs", "flags"):
        assert again[key] == documented[key], key


@pytest.mark.slow
def test_the_rerun_calibration_meets_its_target(rerun):
    _, result = rerun
    entry = result["per_seed"][0]
    low, high = RANGE
    for model in ("two_point", "generalized"):
        if "collinear_features" not in entry["flags"].get(model, []):
            assert low <= entry[model] <= high, (model, entry[model])
    assert entry["left_road_runs"] == 0
