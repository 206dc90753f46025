"""benchmarks.population_check: its measurements on signals with known answers, a reduced
run end to end, and docs/population.md being what the code writes (its command and tables)."""

from __future__ import annotations

import math
import re
import shlex
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from benchmarks.population_check import (
    ROW_COLUMNS,
    RUN_COLUMNS,
    Injection,
    LoopScales,
    check_population,
    command_parser,
    loop_response,
    main,
    population_variant,
    read_rows,
    reversal_rate,
    summarize,
    time_to_line_crossing,
)
from benchmarks.population_document import (
    HUMAN_REFERENCES,
    INJECTION_HARMONICS,
    STATISTICS,
    TITLE,
)
from hasa_env.drivers import POPULATIONS, population

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "population.md"
DT = 0.01


def test_reversals_of_a_slow_sine_are_two_per_period_when_the_gap_is_below_its_swing():
    t = np.arange(0.0, 60.0, DT)
    wheel = 2.0 * np.sin(2.0 * np.pi * 0.2 * t)  # deg, 4 deg peak to peak, 12 periods a minute
    assert reversal_rate(wheel, DT, 3.0) == pytest.approx(24.0, abs=1.5)
    assert reversal_rate(wheel, DT, 5.0) == 0.0
    with pytest.raises(ValueError, match="gap"):
        reversal_rate(wheel, DT, 0.0)


def test_time_to_line_crossing_is_the_distance_to_the_line_it_moves_towards_over_its_speed():
    tlc = time_to_line_crossing(np.array([0.0, 0.0, 0.5]), np.array([0.9, -0.9, 0.0]), 3.6)
    # edge of a 1.8 m car at 0.9 m from a 3.6 m lane's line
    assert tlc[0] == pytest.approx(1.0) and tlc[1] == pytest.approx(1.0)
    assert math.isinf(tlc[2])


def test_the_injection_has_the_size_of_the_study_crosswind_in_lateral_acceleration():
    inj = Injection.draw(25.0, 100.0, 2.8, np.random.default_rng(0))
    w = inj(np.arange(0.0, 100.0, DT))
    assert np.std(w) * 25.0**2 / 2.8 == pytest.approx(0.1, rel=0.02)


def _identification_frame(inj: Injection, omega_c: float, tau: float, noise: float, seed: int):
    """A run whose driver answers the multisine through the loop L = w_c e^(-j w tau)/(j w)
    (U_driver = -L / (1 + L) W at each sine) plus white noise of std ``noise``."""
    n = int(round(100.0 / DT))
    t = np.arange(n) * DT + 20.0 + DT
    chosen_at = t - DT
    w_freq = np.asarray(inj.frequencies)
    loop = omega_c * np.exp(-1j * w_freq * tau) / (1j * w_freq)
    gain = -loop / (1.0 + loop)
    phases = np.asarray(inj.phases)[None, :] + np.angle(gain)[None, :]
    own = (inj.amplitude * np.abs(gain) * np.sin(w_freq * chosen_at[:, None] + phases)).sum(1)
    own = own + np.random.default_rng(seed).normal(0.0, noise, n)
    return pd.DataFrame({"time": t, "steering": own + inj(chosen_at)})


def test_the_loop_identification_finds_a_known_crossover_model():
    rng = np.random.default_rng(1)
    injections = [Injection.draw(25.0, 100.0, 2.8, rng) for _ in range(2)]
    frames = [_identification_frame(inj, 2.0, 0.3, 0.0, k) for k, inj in enumerate(injections)]
    out = loop_response(frames, injections, 100.0, DT)
    assert out["crossover"] == pytest.approx(2.0, rel=0.1)
    assert out["phase_margin"] == pytest.approx(90.0 - math.degrees(0.6), abs=6.0)
    assert out["effective_delay"] == pytest.approx(0.3, abs=0.06)
    assert out["remnant_share"] < 0.02
    linear = np.mean(
        [
            np.var(f["steering"] - inj(f["time"] - DT))
            for f, inj in zip(frames, injections, strict=True)
        ]
    )
    noisy = [_identification_frame(inj, 2.0, 0.3, 2e-4, k) for k, inj in enumerate(injections)]
    expected = 2e-4**2 / (linear + 2e-4**2)  # the white noise's share of the driver's steering
    share = loop_response(noisy, injections, 100.0, DT)["remnant_share"]
    assert share == pytest.approx(expected, abs=0.03)


def test_bad_sizes_are_refused_with_the_allowed_range():
    with pytest.raises(ValueError, match="unknown population"):
        check_population("nobody")
    with pytest.raises(ValueError, match="duration must be"):
        check_population(duration=30.0)


@pytest.mark.slow
def test_a_reduced_check_writes_the_document_with_its_command(tmp_path, capsys):
    out = tmp_path / "population.md"
    rows = tmp_path / "rows.csv"
    args = ["--seeds", "2990", "--drivers", "3", "--runs", "1", "--duration", "45"]
    assert main([*args, "--speeds", "25", "--rows", str(rows), "--write", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    assert text.splitlines()[0] == TITLE
    assert (
        "Written by `python -m benchmarks.population_check --population paper --seeds 2990" in text
    )
    frame = pd.read_csv(rows)
    assert len(frame) == 3 and set(ROW_COLUMNS) <= set(frame.columns)
    # 25 s windows: the multisine starts at 1.26 rad/s, a slower crossover is not found (NaN)
    assert frame["crossover"].notna().any()
    summary = summarize(frame)
    assert set(summary["group"]) >= {"mix"}
    # the saved rows write the same document again, without simulating
    again = tmp_path / "again.md"
    assert main(["--from-rows", str(rows), "--write", str(again)]) == 0
    assert again.read_text(encoding="utf-8") == text.replace(str(out), str(again))


def _command(text: str) -> list[str]:
    match = re.search(r"Written by `python -m benchmarks\.population_check ([^`]*)`", text)
    assert match, "docs/population.md does not say which command wrote it"
    return shlex.split(match.group(1))


def test_the_document_names_the_command_that_wrote_it_on_fresh_seeds():
    args = command_parser().parse_args(_command(DOC.read_text(encoding="utf-8")))
    assert args.write == "docs/population.md"
    seeds = [int(s) for s in args.seeds.split(",")]
    assert all(2000 <= s <= 2999 for s in seeds)  # seeds the benchmark never ran


def test_the_document_has_a_table_row_per_statistic_and_speed_column():
    text = DOC.read_text(encoding="utf-8")
    args = command_parser().parse_args(_command(text))
    speeds = [float(v) for v in args.speeds.split(",")]
    tables = [chunk for chunk in text.split("\n\n") if chunk.startswith("| statistic |")]
    assert len(tables) == 4  # the mix and three archetypes
    for table in tables:
        lines = table.splitlines()
        assert lines[0].count(" m/s") == len(speeds)
        assert [line.split(" | ")[0].lstrip("| ") for line in lines[2:]] == list(
            STATISTICS.values()
        )
    for ref in HUMAN_REFERENCES:
        assert f'<a id="{ref.statistic}"></a>' in text  # every statistic names its source


def test_the_document_is_what_the_code_writes_from_its_saved_rows(tmp_path, monkeypatch):
    """docs/population.md's header names the rows file its command saved; writing the document
    from those rows (no simulation) gives the committed document, so a change to the human
    references or the layout cannot leave it stale."""
    args = command_parser().parse_args(_command(DOC.read_text(encoding="utf-8")))
    assert args.rows, "the documented command saves no rows (--rows)"
    monkeypatch.chdir(ROOT)
    out = tmp_path / "population.md"
    assert main(["--from-rows", args.rows, "--write", str(out)]) == 0
    written = out.read_text(encoding="utf-8").replace(str(out), args.write)
    assert written == DOC.read_text(encoding="utf-8")


def _rows(seeds=(3100, 3101), drivers=3, speeds=(15.0, 25.0)) -> pd.DataFrame:
    """Per-driver rows as ``--rows`` saves them, with made-up statistics."""
    rng = np.random.default_rng(0)
    records = []
    for seed in seeds:
        for speed in speeds:
            for d in range(drivers):
                record = {
                    "seed": seed,
                    "driver": f"d{d}",
                    "archetype": ("two-point", "preview", "intermittent")[d % 3],
                    "speed": speed,
                }
                record.update({name: float(rng.uniform(0.1, 2.0)) for name in STATISTICS})
                record.update(population="paper", runs=1, duration=60.0)
                record.update({c: 1.0 for c in RUN_COLUMNS[3:]})
                records.append(record)
    return pd.DataFrame(records)


def test_rows_name_the_command_that_made_them(tmp_path):
    path = tmp_path / "rows.csv"
    _rows().to_csv(path, index=False)
    rows, made_by = read_rows(path)
    assert len(rows) == 12
    assert (made_by.seeds, made_by.speeds, made_by.drivers) == ("3100,3101", "15,25", 3)
    assert (made_by.runs, made_by.duration, made_by.population) == (1, 60.0, "paper")
    out = tmp_path / "population.md"
    assert main(["--from-rows", str(path), "--write", str(out)]) == 0
    header = out.read_text(encoding="utf-8").splitlines()[2]
    assert (
        "`python -m benchmarks.population_check --population paper --seeds 3100,3101 "
        f"--drivers 3 --runs 1 --duration 60 --speeds 15,25 --rows {path} --write {out}`"
    ) in header
    assert f"--from-rows {path} --write {out}" in header


def test_a_rows_file_without_a_column_is_refused_naming_the_file_and_the_column(tmp_path, capsys):
    path = tmp_path / "rows.csv"
    _rows().drop(columns=["srr_2", "duration"]).to_csv(path, index=False)
    with pytest.raises(ValueError, match=r"rows\.csv: missing column\(s\) srr_2, duration"):
        read_rows(path)
    assert main(["--from-rows", str(path), "--write", str(tmp_path / "out.md")]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "srr_2" in err and "duration" in err
    assert not (tmp_path / "out.md").exists()
    (tmp_path / "empty.csv").write_text("", encoding="utf-8")
    with pytest.raises(ValueError, match="empty.csv: cannot be read"):
        read_rows(tmp_path / "empty.csv")
    with pytest.raises(ValueError, match="nowhere.csv: cannot be read"):
        read_rows(tmp_path / "nowhere.csv")
    mixed = _rows()
    mixed.loc[0, "duration"] = 120.0
    mixed.to_csv(path, index=False)
    with pytest.raises(ValueError, match="column duration differs between rows"):
        read_rows(path)


def test_the_harmonics_are_distinct_and_increasing():
    assert list(INJECTION_HARMONICS) == sorted(set(INJECTION_HARMONICS))


def test_a_variant_has_the_same_drivers_with_the_scaled_ranges_and_is_removed_after():
    before = set(POPULATIONS)
    shipped = population("paper", 2000)
    with population_variant("paper", LoopScales(bandwidth=1.5, command=0.5)) as name:
        scaled = population(name, 2000)
    assert set(POPULATIONS) == before
    assert [type(p) for p in scaled] == [type(p) for p in shipped]
    assert [p.delay for p in scaled] == [p.delay for p in shipped]
    assert [p.motor.command_std for p in scaled] == pytest.approx(
        [0.5 * p.motor.command_std for p in shipped]
    )
    with pytest.raises(ValueError, match="bandwidth must be a finite factor > 0"):
        LoopScales(bandwidth=0.0)
    assert main(["--command-scale", "-1"]) == 2


def test_a_too_short_duration_is_refused_before_any_run(capsys):
    assert main(["--duration", "20"]) == 2
    assert "duration must be > 40 s" in capsys.readouterr().err
