"""Writing files safely (issue 22, items 3, 11, 12): no fixed temporary names followed through
symlinks, a full disk gives one line and keeps what was written, a participant folder is
locked against a second program."""

from __future__ import annotations

import errno
import fcntl
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from hasa_cli.drive import main as drive_main
from hasa_env.atomic import write_atomic
from hasa_env.devices.calibration import load_calibration, save_calibration, shipped_calibration
from hasa_env.recording import load_recording
from hasa_env.session.session_file import SessionError, SessionLock

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "recordings" / "sample" / "run_000.csv"
HEADLESS = {**os.environ, "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}
STUDY = """
format_version = 1
[study]
name = "tiny"
seed = 11
[runs]
seconds = {seconds}
countdown = 0.0
[practice]
runs = 0
[measured]
runs = 1
[env]
markings.hypotheses = [0.0, -1.8]
"""


def _study(tmp_path: Path, seconds: float = 0.3) -> Path:
    path = tmp_path / "study.toml"
    path.write_text(STUDY.format(seconds=seconds))
    return path


def _study_args(study: Path, out: Path, participant: str = "X1") -> list[str]:
    return ["study", str(study), "--participant", participant, "--output", str(out),
            "--synthetic", "2", "--no-status"]  # fmt: skip


def _victim(tmp_path: Path) -> Path:
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    return victim


# ------------------------------------------------------------- item 3: symlinks
def test_write_atomic_never_writes_through_a_symlink(tmp_path):
    victim = _victim(tmp_path)
    target = tmp_path / "out.json"
    (tmp_path / "out.json.tmp").symlink_to(victim)  # the old fixed temporary name
    write_atomic(target, "new\n")
    assert target.read_text() == "new\n" and victim.read_text() == "precious\n"
    target.unlink()
    target.symlink_to(victim)  # a symlink at the target itself is replaced, not followed
    write_atomic(target, b"bytes\n")
    assert not target.is_symlink() and target.read_bytes() == b"bytes\n"
    assert victim.read_text() == "precious\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json", "out.json.tmp", "victim.txt"]


def test_write_atomic_on_a_full_disk_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / "session.json"
    target.write_text("old\n")

    def full(fd, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "write", full)
    with pytest.raises(OSError, match="No space left"):
        write_atomic(target, "new\n")
    monkeypatch.undo()
    assert target.read_text() == "old\n" and [p.name for p in tmp_path.iterdir()] == [target.name]


def test_a_calibration_file_is_not_written_through_a_symlink(tmp_path):
    victim = _victim(tmp_path)
    target = tmp_path / "calibration.json"
    (tmp_path / "calibration.json.tmp").symlink_to(victim)
    save_calibration(shipped_calibration("g29"), target)
    assert victim.read_text() == "precious\n"
    assert load_calibration(target).to_dict() == shipped_calibration("g29").to_dict()


def test_hasa_drive_study_does_not_write_session_json_through_a_symlink(tmp_path):
    victim = _victim(tmp_path)
    folder = tmp_path / "rec" / "X1"
    folder.mkdir(parents=True)
    (folder / "session.json.tmp").symlink_to(victim)
    assert drive_main(_study_args(_study(tmp_path), tmp_path / "rec")) == 0
    assert victim.read_text() == "precious\n"
    assert json.loads((folder / "session.json").read_text())["state"] == "complete"


def test_hasa_replay_frames_replace_preplaced_symlinks(tmp_path):
    victim = _victim(tmp_path)
    frames = tmp_path / "frames"
    frames.mkdir()
    (frames / "frame_00000.png").symlink_to(victim)
    done = subprocess.run(
        [sys.executable, "-m", "hasa_cli.replay", str(SAMPLE), "--frames", str(frames),
         "--frame-every", "3000", "--size", "64x64"],
        env=HEADLESS, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert victim.read_text() == "precious\n"
    first = frames / "frame_00000.png"
    assert not first.is_symlink() and first.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in frames.iterdir()) == ["frame_00000.png", "frame_03000.png"]


# ------------------------------------------------------------ item 11: full disk
def _limit_file_size(limit: int):
    def apply() -> None:  # a file past `limit` bytes fails to grow (EFBIG), like a full disk
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return apply


@pytest.mark.skipif(not hasattr(resource, "RLIMIT_FSIZE"), reason="no RLIMIT_FSIZE")
def test_hasa_drive_synthetic_on_a_full_disk_says_so_in_one_line(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "hasa_cli.drive", "synthetic", "--seconds", "2", "--driver", "2",
         "--participant", "P1", "--output", str(tmp_path)],
        env=HEADLESS, capture_output=True, text=True, timeout=120,
        preexec_fn=_limit_file_size(20_000),
    )  # fmt: skip
    assert done.returncode == 3, done.stderr
    assert "Traceback" not in done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith(f"hasa-drive: error: cannot write to {tmp_path / 'P1'}: File too large")
    assert "what was written before is kept" in line
    recording = load_recording(tmp_path / "P1" / "run_000.csv")  # the rows before the error
    assert 10 < recording.steps < 200 and not list(tmp_path.rglob("*.tmp"))


def test_hasa_drive_study_on_a_full_disk_keeps_the_session_and_resumes(
    tmp_path, monkeypatch, capsys
):
    study, out = _study(tmp_path, seconds=1.0), tmp_path / "rec"
    real_write = os.write
    budget = {"bytes": 32_000}  # the disk fills up during the measured run

    def filling(fd: int, data) -> int:
        if fd > 2:
            budget["bytes"] -= len(data)
            if budget["bytes"] < 0:
                raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(fd, data)

    monkeypatch.setattr(os, "write", filling)
    status = drive_main(_study_args(study, out))
    monkeypatch.undo()
    err = capsys.readouterr().err
    assert status == 3, err
    (line,) = err.strip().splitlines()
    assert line.startswith(f"hasa-drive study: error: cannot write to {out / 'X1'}: No space left")
    folder = out / "X1"
    assert not list(folder.glob("*.tmp")) and not (folder / "session.lock").exists()
    doc = json.loads((folder / "session.json").read_text())  # the last state written, whole
    assert doc["attempts"][-1]["status"] == "started"
    partial = load_recording(folder / "measured_01_000.csv")
    assert 0 < partial.steps < 100
    before = (folder / "measured_01_000.csv").read_bytes()
    assert drive_main(_study_args(study, out)) == 0  # space again: the same command resumes
    assert (folder / "measured_01_000.csv").read_bytes() == before  # nothing lost
    doc = json.loads((folder / "session.json").read_text())
    assert [(a["status"], a["file"]) for a in doc["attempts"]] == [
        ("aborted", "measured_01_000.csv"),
        ("completed", "measured_01_001.csv"),
    ]


# ---------------------------------------------------------------- item 12: lock
def test_a_second_study_program_for_one_participant_is_refused(tmp_path):
    study, out = _study(tmp_path), tmp_path / "rec"
    folder = out / "X1"
    folder.mkdir(parents=True)
    # as a first hasa-drive study holds the participant's folder (here: this process)
    fd = os.open(folder / "session.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.write(fd, f"{os.getpid()} host time\n".encode())
        done = subprocess.run(
            [sys.executable, "-m", "hasa_cli.drive", *_study_args(study, out)],
            env=HEADLESS, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    finally:
        os.close(fd)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line == (
        f"hasa-drive study: error: {folder / 'session.lock'}: another program (process "
        f"{os.getpid()}) is running this participant's session; wait for it to end or stop it "
        "first"
    )
    assert [p.name for p in folder.iterdir()] == ["session.lock"]  # no session.json created
    assert drive_main(_study_args(study, out)) == 0  # the lock released, it runs
    assert not (folder / "session.lock").exists()


def test_the_folder_lock_is_per_open_file_and_survives_a_stale_file(tmp_path):
    first, second = SessionLock(tmp_path / "P1"), SessionLock(tmp_path / "P1")
    first.acquire()
    with pytest.raises(SessionError, match=rf"another program \(process {os.getpid()}\)"):
        second.acquire()
    first.release()
    second.path.write_text("1 gone\n")  # left by a killed program: locks nothing
    second.acquire()
    assert second.path.read_text().split()[0] == str(os.getpid())
    second.release()
