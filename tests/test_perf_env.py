"""The env performance benchmark runs and reports well-formed numbers (timing is not asserted)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.perf import env as perf_env

ENV_KEYS = ("hasa_env", "pendulum", "highway_env", "vector_1", "vector_64", "vector_1024")


def _positive(x: object) -> bool:
    return isinstance(x, float) and math.isfinite(x) and x > 0


@pytest.fixture(scope="module")
def results() -> dict:
    return perf_env.run(quick=True)


def test_every_env_is_measured(results):
    assert set(results["envs"]) == set(ENV_KEYS)
    for key in ENV_KEYS:
        r = results["envs"][key]
        if key == "highway_env" and r["status"] == "not installed":
            assert r["steps_per_second"] is None
            continue
        assert r["status"] == "ok", key
        for field in ("steps_per_second", "min_steps_per_second", "max_steps_per_second"):
            assert _positive(r[field]), (key, field, r[field])
        assert r["min_steps_per_second"] <= r["steps_per_second"] <= r["max_steps_per_second"]
        assert r["steps"] > 0 and r["repeats"] > 0 and r["episodes_ended"] >= 0
    for n in perf_env.VECTOR_SIZES:
        r = results["envs"][f"vector_{n}"]
        assert r["num_envs"] == n
        assert math.isclose(r["calls_per_second"] * n, r["steps_per_second"])


def test_ratios_and_targets(results):
    assert set(results["ratios"]) == {"hasa_over_pendulum", "hasa_over_highway"}
    assert _positive(results["ratios"]["hasa_over_pendulum"])
    highway_ok = results["envs"]["highway_env"]["status"] == "ok"
    assert _positive(results["ratios"]["hasa_over_highway"]) or not highway_ok
    assert set(results["targets"]) == set(perf_env.TARGETS)
    for key, t in results["targets"].items():
        assert t["minimum"] == perf_env.TARGETS[key][1]
        if t["value"] is None:
            assert t["passed"] is None
        else:
            assert _positive(t["value"]) and t["passed"] == (t["value"] >= t["minimum"])


def test_table_and_json_output(results, tmp_path):
    table = perf_env.format_table(results)
    assert "Pendulum-v1" in table and "N=1024" in table
    assert table.count("PASS") + table.count("FAIL") + table.count("n/a") == len(perf_env.TARGETS)
    json.dumps(results, allow_nan=False)  # JSON-serializable as written by --json


def test_cli_quick_writes_json(tmp_path, capsys):
    out = tmp_path / "perf.json"
    assert perf_env.main(["--quick", "--json", str(out)]) == 0
    assert "env-steps/s" in capsys.readouterr().out
    data = json.loads(out.read_text())
    assert set(data["envs"]) == set(ENV_KEYS) and data["quick"] is True


@pytest.mark.slow
def test_cli_output_is_clean_in_a_fresh_process():
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYGAME_", "SDL_"))}
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks.perf.env", "--quick"],
        capture_output=True,
        text=True,
        env=env,
        cwd=Path(__file__).resolve().parents[1],
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "pygame" not in proc.stdout.lower() and "warning" not in proc.stderr.lower()
    assert [ln for ln in proc.stderr.splitlines() if not ln.startswith("timing ")] == []
