"""Ctrl-C stops hasa-bench at once, in whatever stage, and keeps what is written."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time

import pytest
from _programs import program_command, program_env

from benchmarks.executor import map_tasks


def _slow_square(x: float) -> float:
    time.sleep(x)
    return x * x


def test_an_interrupted_map_stops_its_workers_at_once():
    def interrupt(done: int) -> None:
        raise KeyboardInterrupt

    started = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        # 24 tasks of 0.5 s on 2 workers: 6 s to drain the queue after the first result
        map_tasks(_slow_square, [0.5] * 24, workers=2, progress=interrupt)
    assert time.monotonic() - started < 3.0


class _Reader(threading.Thread):
    """Collects a pipe's text as it comes (tqdm writes its bar without newlines)."""

    def __init__(self, stream) -> None:
        super().__init__(daemon=True)
        self.stream, self.text = stream, ""

    def run(self) -> None:
        for chunk in iter(lambda: self.stream.read1(4096), b""):
            self.text += chunk.decode(errors="replace")


@pytest.mark.slow
def test_ctrl_c_while_scoring_exits_130_within_seconds_and_keeps_the_old_result(tmp_path):
    out = tmp_path / "results"
    out.mkdir()
    (out / "results.json").write_text('{"format": "hasa_bench.results"}')  # a previous result
    args = ["paper", "--seed", "0", "--drivers", "1", "--ill-runs", "40", "--duration", "15",
            "--curved-runs", "0", "--workers", "2", "--batch-size", "1", "--no-plots",
            "--out", str(out), "--overwrite"]  # fmt: skip
    proc = subprocess.Popen(
        program_command("hasa-bench", *args),
        cwd=tmp_path,
        env=program_env(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,  # its own process group, as a terminal's job
        # as a shell starts it: Ctrl-C not ignored (a pytest-xdist worker ignores SIGINT,
        # and an ignored signal stays ignored in the programs it starts)
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    reader = _Reader(proc.stderr)
    reader.start()
    try:
        deadline = time.monotonic() + 120
        while "scoring runs" not in reader.text and time.monotonic() < deadline:
            assert proc.poll() is None, reader.text
            time.sleep(0.1)
        assert "scoring runs" in reader.text
        time.sleep(0.5)
        sent = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
        code = proc.wait(timeout=60)
        took = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    reader.join(5)
    assert code == 130, reader.text
    assert took < 5.0, f"{took:.1f} s after Ctrl-C"
    assert "hasa-bench: error: interrupted" in reader.text
    assert "Traceback" not in reader.text
    assert (out / "results.json").read_text() == '{"format": "hasa_bench.results"}'
