"""Model files are data, user models are code (issue 21.1, 22.1); bounded reads of model and
study files (22.2); what the isolation of user models promises (22.4); terminal control
characters from files escaped (22.5). Every test runs the console scripts as a user does:
a subprocess, from a fresh working directory, with the working directory not on
``sys.path`` (``python -P -m``, like the installed console scripts)."""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from _programs import program_command, program_env
from _user_models import near_far_pd_module

from hasa_env.drivers import SyntheticDriver, population, run_driver, save_runs
from hasa_env.session.study import Study, StudyError
from hasa_env.steering import ModelFileError, SteeringModel
from hasa_env.steering.loading import load_model_file

ROOT = Path(__file__).resolve().parents[1]
MODULE = "trust_user_models"
SOURCE = near_far_pd_module(
    "A user's steering model (tests/test_trust_and_isolation.py).", "trust_test_near_far_pd"
)
STUDY = '[study]\nname = "s"\nseed = 1\n[runs]\nseconds = 0.3\n[measured]\nruns = 1\n'


def cli(program: str, *args: str, cwd: Path, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """Run ``program`` (hasa-replay, ...) as its console script runs, from ``cwd``, this tree's
    code first; the child may use at most 3 GiB of address space (so that a regression to an
    unbounded read fails the test instead of filling the machine's memory)."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, resource.RLIM_INFINITY))

    return subprocess.run(
        program_command(program, *args),
        cwd=cwd, env=program_env(), capture_output=True, text=True, timeout=timeout,
        preexec_fn=limit,
        start_new_session=True,  # a signal to the program's group must not reach pytest
    )  # fmt: skip


@pytest.fixture(scope="module")
def user(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A user's folder: the module, a fitted model file, one short recording (the module is
    imported in this process only to fit and save; the programs run in fresh processes)."""
    folder = tmp_path_factory.mktemp("trust")
    (folder / f"{MODULE}.py").write_text(textwrap.dedent(SOURCE))
    frames = run_driver(SyntheticDriver(population("paper", seed=0)[0]), runs=1, seed=0,
                        config={"time_limit": 4.0})  # fmt: skip
    save_runs(frames, folder / "my_runs")
    sys.path.insert(0, str(folder))
    try:
        model = __import__(MODULE).NearFarPD().fit(frames[0])
    finally:
        sys.path.remove(str(folder))
        sys.modules.pop(MODULE, None)
    model.save(folder / "near_far_pd.json")
    (folder / "study.toml").write_text(STUDY)
    return {"folder": folder, "model": folder / "near_far_pd.json",
            "recording": folder / "my_runs" / "run_000.csv"}  # fmt: skip


def test_a_saved_model_file_is_used_from_the_working_directory_when_trusted(user):
    """(Without --trust-model-module it is refused: test_a_model_file_never_imports_...)"""
    folder = user["folder"]
    done = cli("hasa-replay", "my_runs", "--model", "near_far_pd.json", "--trust-model-module",
               cwd=folder)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "model near_far_pd.json: rmse" in done.stdout


def test_a_user_class_is_imported_from_the_working_directory(user):
    """README: ``hasa-replay my_runs/ --model my_models:NearFarPD --fit``, the module found in
    the working directory (the early check of the model, before any replay, once looked
    before the working directory was on sys.path)."""
    done = cli("hasa-replay", "my_runs", "--model", f"{MODULE}:NearFarPD", "--fit",
               cwd=user["folder"])  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert f"model {MODULE}:NearFarPD: rmse" in done.stdout


@pytest.mark.slow  # two programs, and the model's lane-keeping check
def test_hasa_drive_takes_a_trusted_model_file_for_the_estimator(user, tmp_path):
    """``hasa-drive study ... --estimator F.json`` drives with it; ``hasa-drive --estimator
    F.json`` loads and checks it before asking for a screen (none here: exit 3)."""
    model = str(user["model"])
    args = ["study", str(user["folder"] / "study.toml"), "--output", str(tmp_path), "--synthetic",
            "2", "--participant", "P01", "--estimator", model]  # fmt: skip
    done = cli("hasa-drive", *args, "--trust-model-module", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "weights +0.0: " in done.stdout  # the estimator ran with the user's model
    drive = cli("hasa-drive", "--estimator", model, "--trust-model-module", "--output",
                str(tmp_path), "--participant", "P02", cwd=tmp_path)  # fmt: skip
    assert "not registered" not in drive.stderr and "Traceback" not in drive.stderr
    assert drive.returncode == 3, drive.stderr  # got as far as asking for a screen


def test_a_model_file_never_imports_a_module_by_itself(user, tmp_path):
    """``"class": "this:x"`` once printed the Zen of Python through ``hasa-replay --model``."""
    document = json.loads(user["model"].read_text())
    document |= {"type": "not_a_registered_type", "class": "this:x"}
    (tmp_path / "evil.json").write_text(json.dumps(document))
    done = cli("hasa-replay", str(user["recording"]), "--model", "evil.json", cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "Beautiful is better" not in done.stdout + done.stderr
    assert "'not_a_registered_type' is not registered" in done.stderr
    assert "a user model is code" in done.stderr and "--trust-model-module" in done.stderr


def _special(tmp_path: Path, kind: str) -> tuple[str, str]:
    """A path that is a device, a FIFO or a sparse file of 16 MiB + 1 byte; what is said."""
    if kind == "device":
        return "/dev/zero", "is a device, not a regular file"
    path = tmp_path / f"{kind}.json"
    if kind == "fifo":
        os.mkfifo(path)
        return str(path), "is a FIFO (named pipe), not a regular file"
    with open(path, "wb") as f:
        f.truncate(16 * 2**20 + 1)  # sparse: costs no disk
    return str(path), "more than the 16 MiB read"


def _blocked(signum: int, frame: object) -> None:
    raise TimeoutError("the reader blocked")


@pytest.mark.parametrize("kind", ["fifo", "huge"])  # (/dev/zero: in a subprocess, below)
def test_model_and_study_files_are_read_bounded_by_the_library(tmp_path, kind):
    path, said = _special(tmp_path, kind)
    previous = signal.signal(signal.SIGALRM, _blocked)
    signal.alarm(10)  # a reader that blocks on the FIFO fails instead of hanging the suite
    try:
        with pytest.raises(ModelFileError, match=said.replace("(", r"\(").replace(")", r"\)")):
            load_model_file(path)
        with pytest.raises(ModelFileError, match="cannot read it"):
            SteeringModel.load(path)
        with pytest.raises(StudyError, match="cannot read the study file"):
            Study.load(path)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@pytest.mark.slow  # three programs
def test_model_and_study_files_are_read_bounded_by_the_programs(user, tmp_path):
    """/dev/zero once made the reader read until the out-of-memory killer fired, a FIFO hung
    for ever; each is refused at once with one line, before a byte is read."""
    fifo, fifo_said = _special(tmp_path, "fifo")
    zero, zero_said = _special(tmp_path, "device")
    runs = [
        (("hasa-replay", str(user["recording"]), "--model", fifo), fifo_said),
        (("hasa-bench", "score", zero, "--out", str(tmp_path / "out")), zero_said),
        (("hasa-drive", "study", zero, "--participant", "P01", "--check"), zero_said),
    ]
    for (program, *args), said in runs:
        done = cli(program, *args, cwd=tmp_path, timeout=30)
        assert done.returncode == 2, (program, done.stderr)
        assert said in done.stderr and "Traceback" not in done.stderr, (program, done.stderr)


HOSTILE = '''
"""Models whose import misbehaves (run by hasa-bench in its isolated child)."""
import os, signal, sys, time
from pathlib import Path

from hasa_env.steering import GeneralizedModel

HERE = Path(__file__).parent
what = os.environ.get("HOSTILE", "")
'''
HOSTILE_MODULES = {
    "kills_its_group": "os.kill(0, signal.SIGTERM)\ntime.sleep(30)\n",
    "allocates_6_gib": "hog = bytearray(6 * 2**30)\n",
    "forks_and_exits": (
        "pid = os.fork()\n"
        "if pid == 0:\n"
        "    time.sleep(120)\n"
        "    os._exit(0)\n"
        "(HERE / 'grandchild.pid').write_text(str(pid))\n"
        "os._exit(3)\n"
    ),
    "hangs_when_imported_again": (
        "marker = HERE / 'imported_once'\n"
        "if marker.exists():  # the second import: in hasa-bench's own process\n"
        "    time.sleep(120)\n"
        "marker.write_text('')\n"
    ),
}


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:  # a zombie is not alive
        return f.read().rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.slow  # hasa-bench's start-up
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux process limits")
def test_isolation_survives_signals_memory_hogs_and_forks(tmp_path):
    """A model that SIGTERMs its process group, one that allocates 6 GiB, one that forks a
    sleeping grandchild and exits, one whose second import (in hasa-bench itself) hangs: each
    fails alone with its real reason, hasa-bench lives, does not wait for the grandchild, and
    the grandchild does not outlive the call."""
    for name, body in HOSTILE_MODULES.items():
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(HOSTILE) + body)
    specs = [f"{name}:GeneralizedModel" for name in HOSTILE_MODULES]
    done = cli("hasa-bench", "score", *specs, "--model-time-limit", "8", "--out",
               str(tmp_path / "out"), cwd=tmp_path, timeout=100)  # fmt: skip
    assert done.returncode == 2, (done.returncode, done.stderr)  # not -15: it was not killed
    err = done.stderr
    assert "4 of 4 user model(s) cannot be used" in err, err
    assert (
        "kills_its_group:GeneralizedModel' failed (import): its process ended without a "
        "result (killed by signal 15, SIGTERM)" in err
    ), err
    assert (
        "allocates_6_gib:GeneralizedModel' failed (import): exceeded the memory limit of "
        "4 GiB (cannot import module 'allocates_6_gib': MemoryError" in err
    ), err
    assert (
        "forks_and_exits:GeneralizedModel' failed (import): its process ended without a "
        "result (exit status 3" in err
    ), err
    # (not "took longer than the time limit": it did not wait for the grandchild)
    assert (
        "hangs_when_imported_again:GeneralizedModel' failed (import): took longer than the "
        "time limit of 8 s in hasa-bench's own process" in err
    ), err
    grandchild = int((tmp_path / "grandchild.pid").read_text())
    deadline = time.monotonic() + 5
    while _alive(grandchild) and time.monotonic() < deadline:
        time.sleep(0.05)
    alive = _alive(grandchild)
    if alive:  # pragma: no cover - the regression: clean up
        os.kill(grandchild, signal.SIGKILL)
    assert not alive, "the model's grandchild outlived the call"


ESCAPE = "\x1b[2J\x1b[31mRED"
FORGED = "\nhasa-replay: error: forged"


@pytest.mark.slow  # three programs
def test_control_characters_from_files_are_escaped(user, tmp_path):
    """A file name holding an escape sequence and a newline is printed escaped by hasa-replay,
    hasa-rec and hasa-bench: no raw control character, no forged ``prog: error:`` line."""
    evil = tmp_path / f"runs{ESCAPE}{FORGED}"
    evil.mkdir()
    for suffix in (".csv", ".json"):
        shutil.copy(user["recording"].with_suffix(suffix), evil / f"run_000{suffix}")
    checks = [
        ("hasa-replay", str(evil)),
        ("hasa-rec", "info", str(evil / "run_000.csv")),
        ("hasa-bench", "paper", "--recordings", str(evil), "--min-duration", "100", "--out",
         str(tmp_path / "out")),
    ]  # fmt: skip
    for program, *args in checks:
        done = cli(program, *args, cwd=tmp_path)
        text = done.stdout + done.stderr
        assert "\\x1b[2J\\x1b[31mRED\\nhasa-replay: error: forged" in text, (program, text)
        assert "\x1b" not in text, program
        assert not any(line.startswith("hasa-replay: error: forged") for line in
                       text.splitlines()), program  # fmt: skip
