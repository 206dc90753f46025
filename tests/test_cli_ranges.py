"""Out-of-range command-line values (issue 22, item 13): exit 2 with the option and its allowed
range, checked at argument parsing by the env config's own validator; no traceback."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from benchmarks.protocol import BenchmarkError, ProtocolConfig
from hasa_cli.bench import main as bench_main
from hasa_cli.drive import main as drive_main

SMALL = ["--seed", "0", "--population", "paper-pi", "--drivers", "1", "--runs", "1",
         "--ill-runs", "2", "--duration", "2", "--curved-runs", "0", "--no-plots"]  # fmt: skip


def test_hasa_bench_paper_refuses_an_out_of_range_noise_in_one_line(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "hasa_cli.bench", "paper", *SMALL, "--camera-noise", "11",
         "--out", str(tmp_path / "out")],
        env={**os.environ, "MPLBACKEND": "Agg"}, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines()[-1] == (
        "hasa-bench paper: error: argument --camera-noise: config key 'noise.camera' = 11.0 is "
        "out of range: allowed [0, 10] m"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("option", "value", "expected"),
    [
        ("--duration", "1000001", "argument --duration: config key 'time_limit' = 1000001.0 is "
                                  "out of range: allowed (0, 1e+06] s"),
        ("--camera-noise", "1e308", "argument --camera-noise: config key 'noise.camera' = 1e+308 "
                                    "is out of range: allowed [0, 10] m"),
        ("--imu-noise", "nan", "argument --imu-noise: config key 'noise.imu' must be a finite "
                               "number in [0, 50] m/s^2, got nan"),
        ("--steering-noise", "lots", "argument --steering-noise: expected a number, got 'lots'"),
        ("--equation-error-order", "11", "argument --equation-error-order: must be an integer "
                                         "in [0, 10] (0: white), got '11'"),
        ("--equation-error-order", "-1", "argument --equation-error-order: must be an integer "
                                         "in [0, 10] (0: white), got '-1'"),
    ],
)  # fmt: skip
def test_hasa_bench_range_errors_name_the_option(tmp_path, capsys, option, value, expected):
    with pytest.raises(SystemExit) as stop:
        bench_main(["paper", *SMALL, option, value, "--out", str(tmp_path / "out")])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1] == f"hasa-bench paper: error: {expected}"


def test_the_protocol_config_checks_the_env_ranges():
    with pytest.raises(BenchmarkError, match=r"'noise.camera' = 11.0 is out of range"):
        ProtocolConfig(noise={"camera": 11.0})
    with pytest.raises(BenchmarkError, match=r"'time_limit' = 2000000.0 is out of range"):
        ProtocolConfig(duration=2e6)


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--population", "nope"], "unknown population 'nope'; allowed: mixed, paper, paper-pi"),
        (["--population-seed", "-1"], "population seed must be a non-negative integer, got -1"),
    ],
)
def test_hasa_drive_synthetic_refuses_a_bad_population(tmp_path, capsys, args, expected):
    assert drive_main(["synthetic", *args, "--output", str(tmp_path)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f"hasa-drive: error: {expected}")
    assert not list(tmp_path.iterdir())
