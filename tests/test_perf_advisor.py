"""The advisor-task performance benchmark runs and reports well-formed numbers (no timing asserts)."""

from __future__ import annotations

import json
import math

import pytest

from benchmarks.perf import advisor as perf_advisor


@pytest.fixture(scope="module")
def results() -> dict:
    return perf_advisor.run(quick=True)


def test_every_env_is_measured_and_the_ratios_are_of_the_same_run(results):
    assert set(results["envs"]) == set(perf_advisor.MEASURES)
    for key, r in results["envs"].items():
        assert math.isfinite(r["steps_per_second"]) and r["steps_per_second"] > 0, key
        assert r["min_steps_per_second"] <= r["steps_per_second"] <= r["max_steps_per_second"]
    assert results["envs"]["advisor_vector_1024"]["num_envs"] == 1024
    rate = {k: v["steps_per_second"] for k, v in results["envs"].items()}
    assert results["ratios"]["advisor_over_plain_single"] == (
        rate["advisor_single"] / rate["plain_single"]
    )
    # real time: simulated seconds (one 100 Hz sample per step by default) per wall second
    assert results["envs"]["advisor_single"]["env_step_seconds"] == 0.01
    assert results["ratios"]["advisor_single_real_time_factor"] == pytest.approx(
        rate["advisor_single"] * 0.01
    )
    for key, t in results["targets"].items():
        assert t["minimum"] == perf_advisor.TARGETS[key][1]
        assert t["passed"] == (t["value"] >= t["minimum"])
    table = perf_advisor.format_table(results)
    assert table.count("PASS") + table.count("FAIL") == len(perf_advisor.TARGETS)
    assert "(target >= 20x)" in table and "(target >= 1/20)" in table
    json.dumps(results, allow_nan=False)
