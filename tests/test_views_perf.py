"""The rendering benchmark runs and reports well-formed numbers (timing is never asserted)."""

from __future__ import annotations

import math

import pytest

from benchmarks.perf import render as perf_render


@pytest.mark.slow
def test_render_benchmark_reports_every_measurement():
    report = perf_render.run(quick=True)
    assert report["size"] == [1280, 720] and report["target_fps"] == 60.0
    expected = {
        "driver_draw",
        "driver_rgb_array",
        "driver_window",
        "driver_with_physics",
        "participant_with_physics",
        "top_down_draw",
        "drive_loop",
    }
    assert set(report["results"]) == expected
    for key, r in report["results"].items():
        assert math.isfinite(r["frames_per_second"]) and r["frames_per_second"] > 0, key
        if key != "drive_loop":
            assert (
                r["min_frames_per_second"] <= r["frames_per_second"] <= r["max_frames_per_second"]
            )
    loop = report["results"]["drive_loop"]
    assert loop["sim_seconds"] == pytest.approx(1.5) and loop["frames"] > 1
    assert set(report["ratios_to_target"]) == set(perf_render.TARGETS)
    assert "participant_with_physics" in perf_render.TARGETS
    same_run = report["ratios"]["participant_over_developer"]
    assert same_run == pytest.approx(
        report["results"]["participant_with_physics"]["frames_per_second"]
        / report["results"]["driver_with_physics"]["frames_per_second"]
    )
    table = perf_render.format_table(report)
    assert "driver_with_physics" in table and "target" in table
