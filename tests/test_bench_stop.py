"""Stopping hasa-bench (issue 22, items 16 and 17): SIGTERM / SIGHUP end the local worker pool
with the program (exit 143 / 129, one line); a Dask cluster that loses its scheduler or every
worker ends the run in one line with exit 3 instead of waiting for ever."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from benchmarks.executor import ClusterLost, check_scheduler, map_tasks
from hasa_cli.bench import main as bench_main

ROOT = Path(__file__).resolve().parents[1]
SMALL = ["--seed", "0", "--population", "paper-pi", "--drivers", "1", "--runs", "1",
         "--ill-runs", "2", "--duration", "2", "--curved-runs", "0", "--no-plots", "--quiet"]  # fmt: skip
HARNESS = """
import os, sys, time
from pathlib import Path
from benchmarks.executor import map_tasks
from hasa_cli import console_script, stop_on_signals

def task(path):
    Path(path).write_text(str(os.getpid()))
    time.sleep(120)

@console_script("harness")
def main(argv=None):
    with stop_on_signals():
        map_tasks(task, [os.path.join(sys.argv[1], f"w{i}") for i in range(2)], workers=2)
    return 0

if __name__ == "__main__":
    sys.exit(main())
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie is dead
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except OSError:
        return True


def _worker_pids(folder: Path, proc: subprocess.Popen, timeout: float = 60) -> list[int]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        files = sorted(folder.glob("w*"))
        if len(files) == 2 and all(f.read_text() for f in files):
            return [int(f.read_text()) for f in files]
        if proc.poll() is not None:
            pytest.fail(f"the harness ended early: {proc.stderr.read()}")
        time.sleep(0.05)
    pytest.fail("the pool workers never started")


def _gone_within(pids: list[int], seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if not any(_alive(p) for p in pids):
            return True
        time.sleep(0.05)
    for pid in pids:  # do not leave them behind (old behaviour): by their ids only
        if _alive(pid):
            os.kill(pid, signal.SIGKILL)
    return False


def _start_harness(tmp_path: Path) -> tuple[subprocess.Popen, list[int]]:
    script = tmp_path / "harness.py"
    script.write_text(HARNESS)
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    proc = subprocess.Popen([sys.executable, str(script), str(tmp_path)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    return proc, _worker_pids(tmp_path, proc)


# ------------------------------------------------------------ item 17: signals
@pytest.mark.parametrize("name", ["SIGTERM", "SIGHUP"])
def test_sigterm_and_sighup_stop_the_pool_workers(tmp_path, name):
    proc, pids = _start_harness(tmp_path)
    signum = getattr(signal, name)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signum, err
    assert err.strip() == (
        f"harness: error: stopped by {name} (what was written so far stays written)"
    )
    assert _gone_within(pids, 5.0), "pool workers outlived the program"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_pool_workers_end_with_a_killed_parent(tmp_path):
    proc, pids = _start_harness(tmp_path)
    proc.kill()
    proc.communicate(timeout=30)
    assert _gone_within(pids, 5.0), "pool workers outlived a SIGKILLed parent"


@pytest.mark.slow
def test_sigterm_to_hasa_bench_paper_stops_its_workers(tmp_path):
    psutil = pytest.importorskip("psutil")
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "hasa_cli.bench", "paper", "--seed", "0", "--population",
         "paper-pi", "--drivers", "3", "--runs", "4", "--duration", "30", "--curved-runs", "0",
         "--workers", "2", "--batch-size", "1", "--no-plots", "--out", str(out)],
        env={**os.environ, "MPLBACKEND": "Agg"}, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    children: list[int] = []
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(children) < 2 and proc.poll() is None:
        children = [c.pid for c in psutil.Process(proc.pid).children()]
        time.sleep(0.1)
    assert len(children) >= 2, "the pool workers never started"
    time.sleep(1.0)
    proc.terminate()
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert err.strip().splitlines()[-1] == (
        "hasa-bench: error: stopped by SIGTERM (what was written so far stays written)"
    )
    assert _gone_within(children, 5.0)


# --------------------------------------------------------------- item 16: Dask
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_a_cluster_without_workers_ends_the_run_in_one_line(tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=0, processes=False, dashboard_address=None, protocol="tcp", host="127.0.0.1"
    ) as cluster:
        started = time.monotonic()
        status = bench_main(["paper", *SMALL, "--scheduler", cluster.scheduler_address,
                             "--worker-timeout", "1", "--out", str(tmp_path / "out")])  # fmt: skip
        took = time.monotonic() - started
    err = capsys.readouterr().err
    assert status == 3, err
    (line,) = err.strip().splitlines()
    assert line.startswith(f"hasa-bench: error: the Dask cluster at {cluster.scheduler_address} "
                           "has had no worker for 1 s (0 of ")  # fmt: skip
    assert line.endswith("tasks finished); start workers and run again; nothing was written")
    assert took < 30 and not (tmp_path / "out" / "results.json").exists()


def test_map_tasks_gives_up_on_a_cluster_without_workers():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=0, processes=False, dashboard_address=None, protocol="tcp", host="127.0.0.1"
    ) as cluster:
        with pytest.raises(ClusterLost, match=r"has had no worker for 0.5 s \(0 of 2 tasks"):
            map_tasks(abs, [-1, -2], scheduler=cluster.scheduler_address, no_worker_timeout=0.5)


def test_map_tasks_names_a_lost_scheduler_and_keeps_what_finished():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(
        n_workers=0, processes=False, dashboard_address=None, protocol="tcp", host="127.0.0.1"
    )
    closer = threading.Timer(1.5, cluster.close)
    closer.start()
    try:
        with pytest.raises(ClusterLost, match="went away") as info:
            map_tasks(abs, [-1, -2], scheduler=cluster.scheduler_address, no_worker_timeout=60)
    finally:
        closer.join()
        cluster.close()
    assert info.value.kind == "lost" and info.value.done == {}


@pytest.mark.slow
def test_a_killed_scheduler_ends_hasa_bench_with_exit_3(tmp_path):
    pytest.importorskip("distributed")
    address = f"tcp://127.0.0.1:{_free_port()}"
    scheduler = subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
         "--port", address.rsplit(":", 1)[1], "--no-dashboard"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                check_scheduler(address, timeout=2)
                break
            except OSError:
                if time.monotonic() > deadline:
                    pytest.fail("the scheduler did not start")
                time.sleep(0.2)
        small = [a for a in SMALL if a != "--quiet"]  # the progress says when tasks are out
        bench = subprocess.Popen(
            [sys.executable, "-m", "hasa_cli.bench", "paper", *small, "--scheduler", address,
             "--out", str(tmp_path / "out")],
            env={**os.environ, "MPLBACKEND": "Agg"}, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        chunks: list[str] = []
        reader = threading.Thread(
            target=lambda: chunks.extend(iter(lambda: bench.stderr.read(1), ""))
        )
        reader.start()
        deadline = time.monotonic() + 120
        while "scoring runs" not in "".join(chunks) and time.monotonic() < deadline:
            time.sleep(0.1)  # tasks submitted: they wait for a worker (there is none)
        time.sleep(1.0)
        scheduler.kill()
        bench.wait(timeout=60)
        reader.join(timeout=10)
        err = "".join(chunks)
    finally:
        scheduler.kill()
        scheduler.wait()
    assert bench.returncode == 3, err
    assert "Traceback" not in err
    line = err.strip().splitlines()[-1]
    assert line.startswith(f"hasa-bench: error: the Dask scheduler at {address} went away")
