"""``hasa-drive study`` end to end: a scripted study (virtual G29, synthetic participants),
a session killed with SIGKILL and resumed, then ``hasa-bench paper --recordings`` on it;
under a real X window (Xvfb) where available."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from benchmarks.protocol.config import ProtocolConfig
from benchmarks.protocol.plan import recording_plan
from hasa_cli.bench import main as bench_main
from hasa_cli.drive import EXIT_NO_SCREEN
from hasa_cli.drive import main as drive_main
from hasa_cli.study import StatusLine
from hasa_env.drivers import population
from hasa_env.recording import load_recording
from hasa_env.scenarios import scenario_drivers

STUDY = """
format_version = 1
[study]
name = "scripted"
seed = 11
[participant.age_band]
choices = ["18-24", "25-34"]
[runs]
seconds = {seconds}
countdown = 0.2
min_speed = 12.0
[practice]
runs = 1
[measured]
runs = 3
break_every = 2
break_seconds = 0.3
[schedule]
kind = "latin_square"
[env]
markings.hypotheses = [0.0, -1.8]
"""
HEADLESS = {**os.environ, "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}


def _study(tmp_path: Path, seconds: float) -> Path:
    path = tmp_path / "study.toml"
    path.write_text(STUDY.format(seconds=seconds))
    return path


def _digests(folder: Path) -> dict[str, str]:
    return {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest()
        for p in folder.iterdir()
        if p.name not in ("session.json", "session.lock")
    }


def _command(study: Path, out: Path, participant: str, *extra: str) -> list[str]:
    return [sys.executable, "-m", "hasa_cli.drive", "study", str(study), "--participant",
            participant, "--output", str(out), "--synthetic", "2", "--meta", "age_band=25-34",
            *extra]  # fmt: skip


@pytest.mark.slow
def test_a_killed_study_resumes_at_the_next_run_and_the_benchmark_reads_it(tmp_path, capsys):
    study = _study(tmp_path, seconds=4.0)
    out = tmp_path / "rec"
    folder = out / "P01"
    proc = subprocess.Popen(_command(study, out, "P01"), env=HEADLESS,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
    target = folder / "measured_02_000.csv"
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            if target.exists() and target.stat().st_size > 30_000:  # about 100 rows
                break
            if proc.poll() is not None:
                pytest.fail(f"the study ended early: {proc.stderr.read().decode()}")
            time.sleep(0.02)
        else:
            pytest.fail("measured run 2 never started")
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    before = _digests(folder)
    doc = json.loads((folder / "session.json").read_text())
    assert doc["attempts"][-1]["status"] == "started"  # the kill left it mid-run
    assert doc["attempts"][-1]["file"] == "measured_02_000.csv"
    # resume: the same command
    done = subprocess.run(_command(study, out, "P01"), env=HEADLESS, capture_output=True,
                          text=True, timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "measured run 2 (attempt 0) was interrupted after" in done.stdout
    assert "resuming P01 at measured run 2" in done.stdout
    for name, digest in before.items():  # nothing lost or overwritten
        assert hashlib.sha256((folder / name).read_bytes()).hexdigest() == digest, name
    killed = load_recording(target)
    assert not killed.complete and 50 < killed.steps < 400
    doc = json.loads((folder / "session.json").read_text())
    attempts = [(a["block"], a["number"], a["attempt"], a["status"], a["end_reason"], a["file"])
                for a in doc["attempts"]]  # fmt: skip
    assert attempts == [
        ("practice", 1, 0, "completed", "truncated", "practice_01_000.csv"),
        ("measured", 1, 0, "completed", "truncated", "measured_01_000.csv"),
        ("measured", 2, 0, "aborted", "interrupted", "measured_02_000.csv"),
        ("measured", 2, 1, "completed", "truncated", "measured_02_001.csv"),
        ("measured", 3, 0, "completed", "truncated", "measured_03_000.csv"),
    ]
    assert doc["attempts"][2]["steps"] == killed.steps  # counted from what the file kept
    assert doc["state"] == "complete" and doc["participant"]["metadata"] == {"age_band": "25-34"}
    assert [s["ended"] for s in doc["sessions"]] == ["interrupted", "complete"]
    assert load_recording(folder / "measured_01_000.csv").meta["metadata"]["synthetic"] is True
    # a second participant, in this process
    assert drive_main(["study", str(study), "--participant", "P02", "--output", str(out),
                       "--synthetic", "3", "--meta", "age_band=18-24"]) == 0  # fmt: skip
    capsys.readouterr()
    # the benchmark on the study: participants, measured runs only, the aborted one reported
    report = tmp_path / "bench"
    code = bench_main(["paper", "--recordings", str(out), "--out", str(report), "--no-plots",
                       "--workers", "1", "--min-duration", "1"])  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0
    result = json.loads((report / "results.json").read_text())
    drivers = {d["driver"]: d for d in result["drivers"]}
    assert set(drivers) == {"P01", "P02"}
    assert drivers["P01"]["runs"] == 3 and drivers["P02"]["runs"] == 3  # no practice runs
    assert drivers["P01"]["study_session"]["aborted_runs"] == 1
    assert drivers["P01"]["study_session"]["practice_runs_excluded"] == 1
    assert drivers["P02"]["study_session"]["participant_metadata"] == {"age_band": "18-24"}
    analysed = sorted(Path(p).name for p in drivers["P01"]["recordings"])
    assert analysed == ["measured_01_000.csv", "measured_02_001.csv", "measured_03_000.csv"]
    assert any("aborted run not analysed: P01 measured run 2 attempt 0 (interrupted" in n
               for n in result["notes"])  # fmt: skip
    assert "aborted run not analysed" in text  # also in the printed report
    estimated = {r["driver"] for r in result["estimation"]}
    assert estimated == {"P01", "P02"}  # the paper's table 2 for the study's participants


def test_the_benchmark_names_a_missing_measured_run_and_pools_no_two_protocols(tmp_path, capsys):
    """A completed measured run whose recording is gone is a skipped file (the verdict lacks
    it), not a silent 3/3; sessions of a study file whose runs differ are not pooled with
    the training participant's (they were scored as one verdict)."""
    out = tmp_path / "rec"
    study = _study(tmp_path, seconds=1.5)
    other = tmp_path / "other.toml"
    other.write_text(STUDY.format(seconds=2.5))  # same name, other run length
    for who, path, driver in (("P01", study, "2"), ("P02", study, "3"), ("P03", other, "4")):
        args = ["study", str(path), "--participant", who, "--output", str(out),
                "--synthetic", driver, "--meta", "age_band=25-34"]  # fmt: skip
        assert drive_main(args) == 0
    capsys.readouterr()
    gone = out / "P02" / "measured_02_000.csv"
    gone.unlink()
    gone.with_suffix(".json").unlink()
    session = out / "P01" / "session.json"  # as if killed in its practice run, not resumed
    doc = json.loads(session.read_text())
    doc["attempts"][0].update(status="started", end_reason=None, steps=0)
    session.write_text(json.dumps(doc))
    config = ProtocolConfig(recordings=str(out), min_duration=0.5, illustrative="P01")
    plan = recording_plan(config)
    skipped = {Path(s["file"]).parent.name + "/" + Path(s["file"]).name: s["reason"]
               for s in plan.skipped}  # fmt: skip
    assert skipped["P02/measured_02_000.csv"].endswith("of its session file, missing")
    p03 = [name for name in skipped if name.startswith("P03/")]
    assert len(p03) == 3, skipped
    assert "not of the training run's study 'scripted' of study.toml" in skipped[p03[0]]
    assert {d["driver"] for d in plan.drivers} == {"P01", "P02"}
    # the same protocol under another file name is one protocol (a study file renamed)
    shutil.copy(study, tmp_path / "renamed.toml")
    args = ["study", str(tmp_path / "renamed.toml"), "--participant", "P04", "--output",
            str(out), "--synthetic", "2", "--meta", "age_band=25-34"]  # fmt: skip
    assert drive_main(args) == 0
    plan = recording_plan(config)
    assert {d["driver"] for d in plan.drivers} == {"P01", "P02", "P04"}
    assert any("P02 (scripted, complete): 3/3 measured runs" in n and "1 of its measured "
               "recordings missing" in n for n in plan.notes)  # fmt: skip
    assert any(
        "P01 practice run 1 attempt 0 (its session stopped in it and was not resumed)" in n
        for n in plan.notes
    ), plan.notes  # not "(None, 0 steps)"


def test_hasa_replay_says_what_each_run_was_and_fits_on_measured_runs_only(tmp_path, capsys):
    """In a study's folder hasa-replay labels practice and aborted runs and --fit leaves them
    out, as hasa-bench does (it fitted on an aborted run before)."""
    from hasa_cli.replay import main as replay_main

    out = tmp_path / "rec"
    args = ["study", str(_study(tmp_path, seconds=1.5)), "--participant", "P01", "--output",
            str(out), "--synthetic", "2", "--meta", "age_band=25-34"]  # fmt: skip
    assert drive_main(args) == 0
    folder = out / "P01"
    doc = json.loads((folder / "session.json").read_text())
    first = next(a for a in doc["attempts"] if a["file"] == "measured_01_000.csv")
    first.update(status="aborted", end_reason="interrupted")  # as if Ctrl-C had stopped it
    (folder / "session.json").write_text(json.dumps(doc))
    capsys.readouterr()
    report = tmp_path / "replay.json"
    code = replay_main([str(folder), "--model", "generalized", "--fit", "--fit-on", "2",
                        "--json", str(report)])  # fmt: skip
    printed = capsys.readouterr().out
    assert code == 0
    assert "measured_01_000.csv: synthetic" in printed
    assert "[study: aborted measured run 1 (interrupted)]" in printed
    assert "practice_01_000.csv" in printed and "[study: practice run 1]" in printed
    assert "[study: measured run 2]" in printed
    result = json.loads(report.read_text())
    fitted = [Path(p).name for p in result["model"]["fitted_on_recordings"]]
    assert fitted == ["measured_02_000.csv", "measured_03_000.csv"]
    roles = {Path(r["path"]).name: r["study_role"] for r in result["recordings"]}
    assert roles["practice_01_000.csv"] == "practice run 1"


def test_an_output_that_cannot_be_written_records_nothing_and_says_so(tmp_path, capsys):
    (tmp_path / "a_file").write_text("not a folder")
    args = ["study", str(_study(tmp_path, seconds=0.5)), "--participant", "P01", "--output",
            str(tmp_path / "a_file" / "sub"), "--synthetic", "2", "--meta", "age_band=25-34"]  # fmt: skip
    assert drive_main(args) == 2  # nothing done: not "partial" (1)
    err = capsys.readouterr().err
    assert err.startswith("hasa-drive study: error: cannot write to ") and err.rstrip().endswith(
        "; nothing was recorded"), err  # fmt: skip


@pytest.mark.slow
def test_sigterm_in_a_run_says_what_is_kept_and_records_it_as_interrupted(tmp_path):
    study = _study(tmp_path, seconds=4.0)
    out = tmp_path / "rec"
    proc = subprocess.Popen(_command(study, out, "P01"), env=HEADLESS,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)  # fmt: skip
    target = out / "P01" / "measured_01_000.csv"
    try:
        deadline = time.monotonic() + 90
        while not (target.exists() and target.stat().st_size > 30_000):
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"measured run 1 never got going: {proc.stderr.read()}")
            time.sleep(0.02)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM
    assert "hasa-drive study: error: stopped by a signal; the run in progress is kept as " \
        "aborted" in err, err  # fmt: skip
    doc = json.loads((out / "P01" / "session.json").read_text())
    last = doc["attempts"][-1]
    assert (last["file"], last["status"], last["end_reason"]) == (
        "measured_01_000.csv", "aborted", "interrupted")  # fmt: skip
    assert load_recording(target).steps > 50  # what it recorded is kept


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs Xvfb (xvfb-run)")
def test_a_scripted_study_in_a_real_x_window(tmp_path):
    """Under Xvfb: a real window, real time, every screen confirmed with the wheel's button."""
    study = _study(tmp_path, seconds=0.5)
    out = tmp_path / "rec"
    env = {k: v for k, v in os.environ.items() if k != "SDL_VIDEODRIVER"}
    env["SDL_AUDIODRIVER"] = "dummy"
    start = time.monotonic()
    done = subprocess.run(
        ["xvfb-run", "-a", "-s", "-screen 0 1280x720x24",
         *_command(study, out, "P05", "--realtime", "--width", "640", "--height", "360")],
        env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    wall = time.monotonic() - start
    assert done.returncode == 0, done.stderr
    doc = json.loads((out / "P05" / "session.json").read_text())
    assert doc["state"] == "complete" and len(doc["attempts"]) == 4
    # four runs of 0.5 s, each after a 0.2 s countdown, and a break of at least 0.3 s
    assert wall >= 4 * (0.5 + 0.2) + 0.3
    rec = load_recording(out / "P05" / "measured_01_000.csv")
    assert rec.complete and rec.steps == 50 and rec.meta["metadata"]["realtime"] is True


def test_study_check_prints_the_schedule_and_bad_input_exits_2(tmp_path, capsys):
    study = _study(tmp_path, seconds=1.0)
    assert drive_main(["study", str(study), "--participant", "P02", "--check"]) == 0
    shown = capsys.readouterr().out
    assert "measured   1  straight  b = -1.80 m" in shown  # P02 starts with the other lane
    bad = tmp_path / "bad.toml"
    bad.write_text(study.read_text().replace("seconds = 1.0", "seconds = 0"))
    assert drive_main(["study", str(bad), "--participant", "P02", "--check"]) == 2
    assert "bad.toml, line 9: key 'runs.seconds' = 0 is out of range" in capsys.readouterr().err
    args = ["study", str(study), "--participant", "P02", "--output", str(tmp_path), "--synthetic"]
    assert drive_main([*args, "2", "--meta", "age_band=99"]) == 2
    assert "'age_band' = '99' is not allowed: one of '18-24', '25-34'" in capsys.readouterr().err
    assert drive_main([*args, "2"]) == 2  # no terminal to ask in: the answer is required
    assert "participant field 'age_band' is required" in capsys.readouterr().err
    assert drive_main(["study", str(study), "--participant", "P02", "--output", str(tmp_path)],
                      ) == EXIT_NO_SCREEN  # fmt: skip
    assert "no screen to drive on" in capsys.readouterr().err
    assert not (tmp_path / "P02").exists()


def test_the_status_line_shows_run_bias_time_speed_and_weights(tmp_path, capsys):
    study = _study(tmp_path, seconds=0.3)
    out = tmp_path / "rec"
    code = drive_main(["study", str(study), "--participant", "P01", "--output", str(out),
                       "--synthetic", "2", "--meta", "age_band=18-24", "--estimator"])  # fmt: skip
    assert code == 0
    lines = capsys.readouterr().out.splitlines()
    driving = [line for line in lines if " | t " in line]
    assert driving and driving[0].startswith("P01 | practice run 1/1 | true b +0.00 m | t ")
    assert any("measured run 1/3 | true b +0.00 m" in line for line in driving)
    assert all(" | v " in line and " | y " in line and "weights +0.0: " in line
               for line in driving)  # fmt: skip
    assert any(line.endswith("| break") for line in lines)
    (trust,) = [line for line in lines if line.startswith("hasa-drive: --estimator generalized: ")]
    assert "steering" in trust, trust  # where the filter does not listen, as hasa-drive says
    assert StatusLine().tty is False  # captured: plain lines, no carriage returns


def test_study_check_shows_the_scenario_and_what_the_file_overrides(tmp_path, capsys):
    shipped = Path(__file__).resolve().parents[1] / "studies" / "lane_shift.toml"
    assert drive_main(["study", str(shipped), "--participant", "P01", "--check"]) == 0
    shown = capsys.readouterr().out
    assert "scenario 'lane_shift': construction zone" in shown
    assert (
        "the driven lane moves: [{'station': 150.0, 'length': 65.0, 'offset': 1.8, "
        "'toward': 'other_hypothesis'}]" in shown
    )
    assert "drawn in yellow over the white markings" in shown
    assert "overrides" not in shown  # lane_shift.toml keeps every key of the scenario
    late = tmp_path / "late.toml"
    late.write_text(_study(tmp_path, 1.0).read_text().replace(
        "[runs]\n", '[runs]\nscenario = "late_ambiguity"\nspeed = 15.0\n'))  # fmt: skip
    assert drive_main(["study", str(late), "--participant", "P01", "--check"]) == 0
    shown = capsys.readouterr().out
    assert "start: 15 m/s, halfway between the true lane's centre and the nearest other" in shown
    assert "the study file's runs.speed = 15.0 overrides the scenario's 25.0" in shown


def test_a_synthetic_participant_drives_the_studys_scenario(tmp_path, capsys):
    study = tmp_path / "off.toml"
    study.write_text(_study(tmp_path, 0.3).read_text().replace(
        "[runs]\n", '[runs]\nscenario = "off_centre_drivers"\n').replace(
        "markings.hypotheses = [0.0, -1.8]\n", ""))  # fmt: skip
    out = tmp_path / "rec"
    code = drive_main(["study", str(study), "--participant", "P01", "--output", str(out),
                       "--synthetic", "2", "--meta", "age_band=18-24"])  # fmt: skip
    assert code == 0
    capsys.readouterr()
    rec = load_recording(out / "P01" / "measured_01_000.csv")
    assert rec.config["scenario"] == "off_centre_drivers"
    assert rec.config["markings"]["hypotheses"] == [0.0, -0.8]
    assert rec.meta["metadata"]["study"]["scenario"] == "off_centre_drivers"
    # the synthetic participant keeps the scenario's preferred offset (a human their own)
    expected = {p.name: p for p in scenario_drivers(population("paper", seed=0),
                                                   "off_centre_drivers", 0)}["2"]  # fmt: skip
    offset = rec.meta["metadata"]["synthetic_driver"]["params"]["preferred_offset"]
    assert offset == expected.preferred_offset and 0.2 <= abs(offset) <= 0.5
