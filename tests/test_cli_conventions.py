"""Every console script: --version, one error format, the exit codes, no traceback.

The conventions are those of :mod:`hasa_cli` (README "Exit codes"): ``prog: error:
message`` on stderr; 0 ok, 1 partial, 2 usage or input error, 3 environment.
"""

from __future__ import annotations

import importlib
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

import hasa_env
from hasa_cli import EXIT_INTERRUPTED, console_script
from hasa_cli.bench import main as bench_main
from hasa_cli.demo import demo_main
from hasa_cli.drive import main as drive_main
from hasa_cli.rec import main as rec_main
from hasa_cli.replay import main as replay_main

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "recordings" / "sample" / "run_000.csv"
SCRIPTS = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
MAINS = {"hasa-bench": bench_main, "hasa-drive": drive_main, "hasa-replay": replay_main,
         "hasa-rec": rec_main, "hasa-demo": demo_main}  # fmt: skip


def test_every_console_script_points_at_a_main_that_exists():
    assert set(SCRIPTS) == set(MAINS)
    for name, target in SCRIPTS.items():
        module, attribute = target.split(":")
        assert getattr(importlib.import_module(module), attribute) is MAINS[name], name


@pytest.mark.parametrize("name", sorted(MAINS))
def test_version(name, capsys):
    with pytest.raises(SystemExit) as info:
        MAINS[name](["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"{name} {hasa_env.__version__}"


@pytest.mark.parametrize(
    ("name", "argv"),
    [
        ("hasa-bench", ["paper", "--runs", "zero"]),
        ("hasa-bench", ["paper", "--model-time-limit", "-1"]),
        ("hasa-drive", ["--participant"]),
        ("hasa-drive", ["synthetic", "--runs", "x"]),
        ("hasa-replay", []),
        ("hasa-replay", [str(SAMPLE), "--atol", "nan"]),
        ("hasa-rec", ["convert"]),
        ("hasa-demo", ["--seconds", "0"]),
        ("hasa-demo", ["--seconds", "inf"]),
        ("hasa-demo", ["--seed", "-1"]),
    ],
)
def test_usage_errors_are_one_format_and_exit_2(name, argv, capsys):
    with pytest.raises(SystemExit) as info:
        MAINS[name](argv)
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"{name}") and ": error: " in err[-1]


def test_input_errors_exit_2_in_one_line(tmp_path, capsys):
    assert demo_main(["--seconds", "2e6"]) == 2
    assert capsys.readouterr().err.startswith("hasa-demo: error: --seconds: config key")
    assert replay_main([str(tmp_path / "no_such_folder")]) == 2
    err = capsys.readouterr().err
    assert "no_such_folder: no such file or directory" in err and "json" not in err
    long_id = "P" * 300
    assert drive_main(["synthetic", "--participant", long_id, "--output", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "at most 64 characters" in err


def test_an_output_folder_that_cannot_be_written_is_said_before_driving(tmp_path, capsys):
    blocked = tmp_path / "a_file"
    blocked.write_text("not a folder")
    code = drive_main(["synthetic", "--output", str(blocked / "sub"), "--seconds", "1"])
    assert code == 2
    assert capsys.readouterr().err.startswith("hasa-drive: error: cannot write recordings to")
    if os.geteuid() == 0:
        return  # root writes into read-only folders
    readonly = tmp_path / "readonly"
    readonly.mkdir(mode=0o555)
    assert drive_main(["synthetic", "--output", str(readonly), "--seconds", "1"]) == 2
    assert "Permission denied" in capsys.readouterr().err


def test_synthetic_help_shows_its_real_default(capsys):
    with pytest.raises(SystemExit):
        drive_main(["synthetic", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "number of runs (default 1)" in help_text


def test_ctrl_c_ends_a_program_with_one_line_and_130(capsys):
    @console_script("hasa-x")
    def main(argv=None):  # noqa: ANN001, ANN202
        raise KeyboardInterrupt

    assert main([]) == EXIT_INTERRUPTED == 130
    assert capsys.readouterr().err == "hasa-x: error: interrupted\n"


def test_hasa_rec_convert_never_replaces_a_file_without_overwrite(tmp_path, capsys):
    pytest.importorskip("pyarrow")
    csv = tmp_path / "run_000.csv"
    shutil.copyfile(SAMPLE, csv)
    shutil.copyfile(SAMPLE.with_suffix(".json"), csv.with_suffix(".json"))
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    assert rec_main(["convert", str(csv), "-o", str(notes)]) == 2
    assert "neither a folder nor a .parquet file" in capsys.readouterr().err
    assert notes.read_text() == "mine"
    target = tmp_path / "out.parquet"
    target.write_text("an older conversion")
    assert rec_main(["convert", str(csv), "-o", str(target)]) == 2
    assert "exists; --overwrite replaces it" in capsys.readouterr().err
    assert target.read_text() == "an older conversion"
    assert rec_main(["convert", str(csv), "-o", str(target), "--overwrite"]) == 0
    capsys.readouterr()
    assert replay_main([str(target)]) == 0  # hasa-replay reads what hasa-rec wrote
    assert "replay matches the recording bit for bit" in capsys.readouterr().out


def test_calibrate_ends_on_a_quit_event(pg, tmp_path):
    lines: list[str] = []
    pg.event.post(pg.event.Event(pg.QUIT))
    from hasa_env.devices.calibrator import calibrate

    code = calibrate(tmp_path / "cal.json", wheel_range_deg=900.0, steering_ratio=15.0,
                     timeout=30.0, log=lines.append, pygame_module=pg)  # fmt: skip
    assert code == 1 and "cancelled" in lines[-1] and not (tmp_path / "cal.json").exists()


def test_calibrate_without_a_wheel_ends_on_ctrl_c_and_sigterm(tmp_path):
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}
    procs = {}
    for signum in (signal.SIGINT, signal.SIGTERM):  # both at once: one start-up's wait
        out = tmp_path / f"cal_{signum}.json"
        procs[signum] = subprocess.Popen(
            [sys.executable, "-c", "import sys; from hasa_env.devices.calibrator import calibrate; "
             f"sys.exit(calibrate({str(out)!r}, wheel_range_deg=900.0, steering_ratio=15.0, "
             "timeout=60.0, log=lambda s: print(s, flush=True)))"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, text=True,
        )  # fmt: skip
    try:
        for proc in procs.values():
            assert proc.stdout is not None
            assert "waiting for a joystick" in proc.stdout.readline()
        time.sleep(0.3)
        for signum, proc in procs.items():
            sent = time.monotonic()
            proc.send_signal(signum)
            assert proc.wait(timeout=10) == 128 + signum
            assert time.monotonic() - sent < 5
            assert "stopped by" in proc.stdout.read()
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
    assert not list(tmp_path.glob("cal_*.json"))


def test_the_rl_extra_brings_what_the_ppo_example_needs():
    """examples/train_ppo.py trains with stable-baselines3's progress bar, which needs tqdm (a
    core dependency) and rich: `pip install ".[rl]"` alone must run it (README's RL section;
    rich had come only with the minari extra, so the test extra hid its absence)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]

    def names(requirements: list[str]) -> set[str]:
        return {re.split(r"[<>=!~\[; ]", r, maxsplit=1)[0].lower() for r in requirements}

    assert "progress_bar=True" in (ROOT / "examples" / "train_ppo.py").read_text()
    assert "tqdm" in names(project["dependencies"])
    assert {"stable-baselines3", "rich"} <= names(project["optional-dependencies"]["rl"])
