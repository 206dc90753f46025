"""The estimator performance benchmark runs and reports well-formed numbers (no timing asserts)."""

from __future__ import annotations

import json
import math

import pytest

from benchmarks.perf import estimators as perf_estimators


def _positive(x: object) -> bool:
    return isinstance(x, float) and math.isfinite(x) and x > 0


@pytest.fixture(scope="module")
def results() -> dict:
    return perf_estimators.run(quick=True)


def test_every_filter_is_measured(results):
    assert set(results["filters"]) == set(perf_estimators.FILTERS)
    for key, r in results["filters"].items():
        for field in ("seconds_per_step", "min_seconds_per_step", "max_seconds_per_step"):
            assert _positive(r[field]), (key, field)
        assert r["min_seconds_per_step"] <= r["seconds_per_step"] <= r["max_seconds_per_step"]
        assert r["steps"] > 0 and r["repeats"] > 0 and r["runs"] >= 1
        assert r["hypotheses"] == (8 if key.endswith("_8") else 2)
    batch = results["filters"]["batched_1000x2"]
    assert math.isclose(batch["seconds_per_run_step"] * batch["runs"], batch["seconds_per_step"])


def test_ratios_targets_and_cross_check(results):
    assert set(results["ratios"]) == {
        "filterpy_over_ours_2",
        "filterpy_over_ours_8",
        "filterpy_over_batched",
    }
    assert all(_positive(v) for v in results["ratios"].values())
    assert set(results["targets"]) == set(perf_estimators.TARGETS)
    for key, t in results["targets"].items():
        assert t["minimum"] == perf_estimators.TARGETS[key][1]
        assert t["value"] == results["ratios"][key]
        assert t["passed"] == (t["value"] >= t["minimum"])
    # the two implementations compute the same estimates
    assert set(results["cross_check_max_abs_difference"]) == {"2_hypotheses", "8_hypotheses"}
    assert all(v < 1e-9 for v in results["cross_check_max_abs_difference"].values())


def test_table_json_and_cli(results, tmp_path, capsys, monkeypatch):
    table = perf_estimators.format_table(results)
    assert table.count("PASS") + table.count("FAIL") == len(perf_estimators.TARGETS)
    json.dumps(results, allow_nan=False)
    out = tmp_path / "perf.json"
    calls = []
    monkeypatch.setattr(perf_estimators, "run", lambda quick: calls.append(quick) or results)
    assert perf_estimators.main(["--quick", "--json", str(out)]) == 0
    assert calls == [True]
    assert "filterpy" in capsys.readouterr().out
    assert json.loads(out.read_text())["quick"] is True
