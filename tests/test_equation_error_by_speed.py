"""examples/equation_error_by_speed.py (docs/design.md §8.33): the generalized model's
equation error by start speed, the filter given it at the speed or on the run itself."""

from __future__ import annotations

import numpy as np
import pytest
from _programs import load_example


def test_residuals_shrink_with_speed_and_both_filters_are_scored() -> None:
    module = load_example("equation_error_by_speed")
    table = module.main(["--seeds", "8300", "--speeds", "15,45", "--runs", "1"])
    assert list(table["equation_error"]) == ["pooled", "at speed"] * 2
    assert list(table["start_speed"]) == [15.0, 15.0, 45.0, 45.0]
    slow, fast = table.iloc[0], table.iloc[2]
    # the population's command noise is scaled by (15 / v)^2 (docs/design.md §7.2)
    assert slow["residual_rms"] > 2 * fast["residual_rms"] and slow["acf1"] > fast["acf1"]
    pooled = table[table["equation_error"] == "pooled"]
    assert pooled["ar"].nunique() == 1 and pooled["pooled_level"].nunique() == 1
    assert table.iloc[1]["ar"] != table.iloc[0]["ar"]  # measured at that speed
    assert ((table["live"] >= 0) & (table["live"] <= 1)).all()
    assert (np.isfinite(table["lateral_rmse"]) & (table["lateral_rmse"] < 0.5)).all()


@pytest.mark.slow  # fits a scenario's models (about 15 s)
def test_own_run_equation_error_per_scenario() -> None:
    module = load_example("equation_error_by_speed")
    table = module.main(["--seeds", "8300", "--scenarios", "close_hypotheses", "--runs", "2"])
    assert list(table["equation_error"]) == ["pooled", "own run"]
    assert list(table["runs"]) == [2, 2] and set(table["scenario"]) == {"close_hypotheses"}
    assert ((table["lane_ece"] >= 0) & (table["lane_ece"] <= 1)).all()
    assert (table["ends_wrong"] <= 2).all()


@pytest.mark.slow  # fits the models (about 10 s)
def test_builtin_model_names_what_it_fits_when_asked_for_another() -> None:
    from benchmarks.protocol.run import builtin_model

    with pytest.raises(
        ValueError, match=r"no built-in model 'nope' \(the protocol fits: .*generalized"
    ):
        builtin_model(8300, "nope")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--runs", "0"], "--runs must be at least 1, got 0"),
        (["--speeds", "fast"], "speeds must be comma-separated distinct numbers in m/s"),
        (["--speeds", "-5"], "speeds must be comma-separated distinct numbers in m/s"),
        (["--scenarios", "paper,nowhere"], "unknown scenario(s) ['nowhere']"),
        (["--seeds", ""], "seeds must be integers >= 0"),
    ],
)
def test_bad_arguments_are_named(argv, message, capsys) -> None:
    module = load_example("equation_error_by_speed")
    with pytest.raises(SystemExit) as exit_info:
        module.main(argv)
    assert exit_info.value.code == 2 and message in capsys.readouterr().err
