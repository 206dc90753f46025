"""examples/live_share_by_driver.py (issue 25's live share per driver; docs/design.md §8.35)
groups a hasa-bench output's runs by driver, joins the drivers' traits and says how
concentrated the time not live is."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _programs import load_example


def _results(tmp_path):
    """A results.json as hasa-bench writes it, cut to the fields the example reads: three
    drivers of seed 7, two runs each of "generalized" on the straight track, one of another
    model and one curved run that must not count."""
    shares = {"A": (0.1, 0.9), "B": (0.8, 0.0), "C": (1.0, 0.0)}  # live, tempered by lambda
    runs = []
    for driver, (live, by_lambda) in shares.items():
        for run in range(2):
            runs.append(
                {
                    "seed": 7,
                    "driver": driver,
                    "track": "straight",
                    "run": run,
                    "model": "generalized",
                    "lateral_rmse": 0.1 + run,
                    "steering_live_share": live,
                    "steering_tempered_model_error_share": by_lambda,
                    "steering_tempered_autocorrelation_share": 1.0 - live - by_lambda,
                    "steering_mismatch_share": 0.0,
                    "steering_off_share": 0.0,
                    "steering_unused_share": 0.0,
                    "model_error_median": 3.0 - live - run,
                }
            )
    runs.append(runs[0] | {"model": "two_point", "steering_live_share": 0.0})
    runs.append(runs[0] | {"track": "curved", "steering_live_share": 0.0})
    drivers = [
        {
            "seed": 7,
            "driver": name,
            "parameters": {
                "archetype": "preview",
                "delay": 0.2,
                "neuromuscular_frequency": 10.0 + i,
                "neuromuscular_damping": 0.7,
                "speed": {"target_speed": None if name == "A" else 45.0},
                "motor": {"command_std": 0.012 - 0.003 * i},
            },
        }
        for i, name in enumerate(shares)
    ]
    path = tmp_path / "results.json"
    path.write_text(json.dumps({"runs_estimation": runs, "drivers": drivers}))
    return path


def test_per_driver_shares_traits_and_concentration(tmp_path, capsys) -> None:
    module = load_example("live_share_by_driver")
    table = module.main([str(_results(tmp_path).parent)]).set_index("driver")
    assert list(table["runs"]) == [2, 2, 2]  # the other model's and the curved runs left out
    np.testing.assert_allclose(table["steering_live_share"], [0.1, 0.8, 1.0])
    np.testing.assert_allclose(table["model_error"], [2.4, 1.7, 1.5])  # median of 2.9, 1.9 ...
    assert table.loc["A", "speed"] == "holds" and table.loc["B", "speed"] == "to 45 m/s"
    out = capsys.readouterr().out
    assert "steering live 63.3% of the time" in out
    # not live: A 0.9 x 2 runs, B 0.2 x 2, C 0: the least-live driver holds 0.9 / 1.1
    runs = module.model_runs(json.loads(_results(tmp_path).read_text()), "generalized", "straight")
    assert module.concentration(runs, (1, 2)) == pytest.approx({1: 0.9 / 1.1, 2: 1.0})
    ranks = module.correlations(table.reset_index())
    assert ranks.loc["model_error", "command_std"] == pytest.approx(1.0)
    assert ranks.loc["steering_live_share", "command_std"] == pytest.approx(-1.0)


def test_names_what_it_cannot_find(tmp_path) -> None:
    module = load_example("live_share_by_driver")
    path = _results(tmp_path)
    with pytest.raises(SystemExit, match="no runs of model 'nope'.*models: generalized"):
        module.main([str(path), "--model", "nope"])
    with pytest.raises(SystemExit, match="cannot read hasa-bench results"):
        module.main([str(tmp_path / "missing.json")])


def test_the_report_lists_each_models_least_live_drivers(tmp_path) -> None:
    # benchmarks.live_by_driver (the example's grouping, in the library) on the same rows:
    # per steering model the drivers with the most time not live, most first; none for a
    # driver always live, nothing for a baseline or a stress model
    from types import SimpleNamespace

    from benchmarks.live_by_driver import least_live_drivers

    doc = json.loads(_results(tmp_path).read_text())
    models = [{"name": "generalized", "kind": "builtin"}, {"name": "two_point", "kind": "stress"}]
    result = SimpleNamespace(
        runs_estimation=doc["runs_estimation"],
        drivers=doc["drivers"],
        models=models,
        config={"track": "straight"},
    )
    rows = least_live_drivers(result, count=5)
    assert [(r["model"], r["driver"]) for r in rows] == [("generalized", "A"), ("generalized", "B")]
    assert rows[0]["not_live_runs"] == pytest.approx(1.8)
    assert rows[0]["steering_tempered_model_error_share"] == pytest.approx(0.9)
    assert rows[0]["command_std"] == pytest.approx(0.012) and rows[0]["archetype"] == "preview"
    assert least_live_drivers(result, count=1) == rows[:1]
    assert least_live_drivers(SimpleNamespace(**{**vars(result), "runs_estimation": []})) == []
