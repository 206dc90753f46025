"""The scenario suite in one pass (benchmarks.protocol.suite): the same results as each
scenario alone, with one fit per distinct training run."""

from __future__ import annotations

import dataclasses

import pandas as pd
import pytest

from benchmarks.protocol import BenchmarkError, ProtocolConfig, run_protocol
from benchmarks.protocol import run as protocol_run
from benchmarks.protocol.plan import make_plan
from benchmarks.protocol.suite import fit_key, run_suite
from benchmarks.report import format_tables

SMALL = {"seeds": (3710, 3711), "drivers": 2, "runs": 1, "ill_runs": 2, "duration": 3.0,
         "curved_runs": 1}  # fmt: skip
SCENARIOS = ("paper", "lane_shift", "off_centre_drivers")


def test_fits_are_shared_where_the_training_runs_are_the_same() -> None:
    keys = {
        name: fit_key(make_plan(ProtocolConfig(**SMALL, scenario=name), 3710)) for name in SCENARIOS
    }
    # the training run is driven in "paper" whatever the scenario, by the same drivers
    assert keys["paper"] == keys["lane_shift"]
    # unless the scenario changes the drivers (their preferred offsets)
    assert keys["off_centre_drivers"] != keys["paper"]
    other_seed = fit_key(make_plan(ProtocolConfig(**SMALL), 3711))
    assert other_seed != keys["paper"]


@pytest.mark.slow
def test_the_suite_gives_each_scenario_the_result_it_gets_alone(monkeypatch) -> None:
    configs = {name: ProtocolConfig(**SMALL, scenario=name) for name in SCENARIOS}
    fitted: list[tuple[str, int | None]] = []
    real_fit = protocol_run.fit_and_check

    def counting_fit(config, plan, *args, **kwargs):
        fitted.append((config.scenario, plan.seed))
        return real_fit(config, plan, *args, **kwargs)

    monkeypatch.setattr("benchmarks.protocol.run.fit_and_check", counting_fit)
    suite = run_suite(configs, workers=1)
    # 2 seeds x (paper, whose fits lane_shift reuses, + off_centre_drivers)
    assert sorted(fitted) == sorted(
        [("paper", 3710), ("paper", 3711), ("off_centre_drivers", 3710),
         ("off_centre_drivers", 3711)]
    )  # fmt: skip
    assert list(suite) == list(SCENARIOS)
    assert suite["lane_shift"].timing["fit"] == 0.0 < suite["paper"].timing["fit"]
    for name, config in configs.items():
        alone = run_protocol(config, workers=1)
        together = suite[name]
        assert together.config == alone.config
        assert together.models == alone.models
        assert together.baselines == alone.baselines
        for table in ("runs_steering", "runs_estimation", "estimation", "summary"):
            pd.testing.assert_frame_equal(  # (NaN equal to NaN)
                pd.DataFrame(getattr(together, table)), pd.DataFrame(getattr(alone, table))
            )
        assert together.executor["tasks"] == alone.executor["tasks"] == 2
        # the tables' header (and the report's "Data:" line) say which scenario they are
        assert f"scenario {name!r}, seeds " in format_tables(together).splitlines()[0]


def test_a_suite_of_configs_that_differ_in_more_than_the_scenario_is_refused() -> None:
    paper = ProtocolConfig(**SMALL)
    with pytest.raises(BenchmarkError, match="differ in more than their scenario .'shift'."):
        run_suite({"paper": paper, "shift": dataclasses.replace(paper, scenario="lane_shift",
                                                               drivers=3)})  # fmt: skip
    with pytest.raises(BenchmarkError, match="no scenario"):
        run_suite({})
