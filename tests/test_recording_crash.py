"""The recorder under failure: a full disk, pre-placed files, and SIGKILL at random moments.

What must hold (recordings/README.md, "Crash safety"): whatever happens, every file
on disk loads (complete, or flagged incomplete) and holds every step that was
acknowledged, losing at most the step being written.
"""

from __future__ import annotations

import errno
import multiprocessing
import os
import signal
import time
import warnings

import gymnasium as gym
import numpy as np
import pytest

import hasa_env  # noqa: F401 - registers the ids
from hasa_env.recording import (
    RecordingError,
    RecordingWarning,
    RecordingWrapper,
    compare_recordings,
    load_recording,
    load_recordings,
    replay,
)
from hasa_env.recording import writer as writer_module

ENV_ID = "hasa_env/LaneKeeping-v0"


class _FullDiskOnce:
    """``os.write`` that fails with ENOSPC on the n-th call (after writing part of it)."""

    def __init__(self, fail_at: int, partial: int = 7) -> None:
        self.calls = 0
        self.fail_at = fail_at
        self.partial = partial
        self.real = os.write

    def __call__(self, fd: int, data) -> int:  # noqa: ANN001
        self.calls += 1
        if self.calls == self.fail_at:
            self.real(fd, bytes(data[: self.partial]))  # a part of the row reached the disk
            raise OSError(errno.ENOSPC, "No space left on device")
        return self.real(fd, data)


def test_a_failed_write_leaves_a_loadable_file_and_stops_that_recording(tmp_path, monkeypatch):
    env = RecordingWrapper(gym.make(ENV_ID), tmp_path)
    env.reset(seed=1)
    for _ in range(10):
        env.step(np.array([0.01, 0.0], dtype=np.float32))
    full = _FullDiskOnce(fail_at=1)
    monkeypatch.setattr(writer_module.os, "write", full)
    with pytest.raises(RecordingError, match="No space left on device") as info:
        env.step(np.array([0.01, 0.0], dtype=np.float32))
    assert info.value.path == tmp_path / "run_000.csv"
    monkeypatch.setattr(writer_module.os, "write", full.real)  # the disk has room again
    # the file holds rows 0..10 (the partial row was cut away) and loads as incomplete
    rec = load_recording(tmp_path / "run_000.csv")
    assert not rec.complete and rec.steps == 10
    assert compare_recordings(rec, replay(rec)) is None
    # no more steps into that file; the env is not stepped either
    before = env.unwrapped._car.sim_step
    with pytest.raises(RecordingError, match="call reset"):
        env.step(np.array([0.01, 0.0], dtype=np.float32))
    assert env.unwrapped._car.sim_step == before and not env.recording
    # a reset starts a clean new recording; the old one is left as it was
    env.reset(seed=2)
    for _ in range(5):
        env.step(np.array([0.0, 0.0], dtype=np.float32))
    env.close()
    assert load_recording(tmp_path / "run_000.csv").steps == 10
    new = load_recording(tmp_path / "run_001.csv")
    assert new.complete and new.steps == 5


def test_a_failed_header_write_leaves_no_half_made_recording(tmp_path, monkeypatch):
    env = RecordingWrapper(gym.make(ENV_ID), tmp_path)
    monkeypatch.setattr(writer_module.os, "write", _FullDiskOnce(fail_at=1))
    with pytest.raises(RecordingError, match="header"):
        env.reset(seed=0)
    assert list(tmp_path.iterdir()) == [] and env.paths == []


def test_a_failed_sidecar_update_keeps_the_recording_loadable_as_incomplete(tmp_path, monkeypatch):
    env = RecordingWrapper(gym.make(ENV_ID), tmp_path)
    env.reset(seed=0)
    for _ in range(4):
        env.step(np.zeros(2, dtype=np.float32))

    def full_disk(*args, **kwargs):  # noqa: ANN002, ANN003
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(writer_module, "write_atomic", full_disk)
    with pytest.raises(RecordingError, match="stays incomplete"):
        env.close()
    rec = load_recording(tmp_path / "run_000.csv")
    assert not rec.complete and rec.steps == 4
    assert [p.name for p in tmp_path.iterdir() if p.suffix == ".tmp"] == []


def test_a_pre_placed_symlink_at_the_temporary_name_is_never_followed(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    folder = tmp_path / "recs"
    folder.mkdir()
    for name in ("run_000.json.tmp", ".run_000.json.tmp", "run_000.csv.tmp"):
        (folder / name).symlink_to(victim)
    env = RecordingWrapper(gym.make(ENV_ID), folder)
    env.reset(seed=0)
    env.step(np.zeros(2, dtype=np.float32))
    env.close()
    assert victim.read_text() == "precious"
    assert load_recording(folder / "run_000.csv").complete
    assert not [p for p in folder.iterdir() if p.name.endswith(".tmp") and not p.is_symlink()]


# ------------------------------------------------------------------ SIGKILL
def _record_forever(folder: str, acked, seed: int) -> None:  # noqa: ANN001
    """Child process: record short episodes without end; ``acked`` counts finished steps."""
    env = RecordingWrapper(gym.make(ENV_ID, config={"time_limit": 0.3}), folder, seed=seed)
    rng = np.random.default_rng(seed)
    while True:
        env.reset()
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(rng.uniform(-0.2, 0.2, 2).astype(np.float32))
            acked.value += 1
            done = terminated or truncated


@pytest.mark.skipif(
    "fork" not in multiprocessing.get_all_start_methods(), reason="needs fork to be quick"
)
def test_sigkill_at_random_moments_loses_at_most_the_step_being_written(tmp_path):
    context = multiprocessing.get_context("fork")
    rng = np.random.default_rng(2024)
    kills = 20
    for k in range(kills):
        folder = tmp_path / f"kill_{k:02d}"
        folder.mkdir()
        acked = context.Value("q", 0, lock=False)
        child = context.Process(target=_record_forever, args=(str(folder), acked, k))
        child.start()
        deadline = time.monotonic() + 10.0
        while acked.value == 0 and time.monotonic() < deadline:  # recording has begun
            time.sleep(0.001)
        time.sleep(float(rng.uniform(0.0, 0.1)))
        os.kill(child.pid, signal.SIGKILL)
        child.join()
        assert child.exitcode == -signal.SIGKILL
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RecordingWarning)
            loaded = load_recordings(folder)
        # a kill while an episode was being started leaves its first row without a sidecar
        # (reset() had not returned): named as such, nothing acknowledged is in it
        started = [e for e in loaded.errors if e.reason.startswith("incomplete: its recorder")]
        assert len(started) == len(loaded.errors) <= 1, [str(e) for e in loaded.errors]
        *finished, last = loaded
        assert all(rec.complete for rec in finished)  # every finished episode was finalized
        total = sum(rec.steps for rec in loaded)
        # every acknowledged step is on disk; at most the one being written is extra
        assert acked.value <= total <= acked.value + 1, (k, acked.value, total, last.complete)
