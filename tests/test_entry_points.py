"""``hasa-demo`` drives every registered id and ``python -m hasa_env`` says what is installed,
each run as a user would (a fresh process in a folder of its own)."""

from __future__ import annotations

import os
import subprocess

import pytest
from _programs import program_command, program_env, run_program

import advisor_tasks
import hasa_env


def test_hasa_demo_drives_every_id_of_both_packages(tmp_path):
    done = run_program("hasa-demo", "--seconds", "0.5", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    ids = (*hasa_env.ENV_IDS, *advisor_tasks.ADVISOR_ENV_IDS)
    assert len(ids) == 4
    for env_id in ids:
        (line,) = [ln for ln in done.stdout.splitlines() if ln.startswith(env_id + " ")]
        assert "steps    50" in line
    assert done.stdout.count("true lane's weight") == 2


def test_python_m_hasa_env_lists_the_ids_and_programs(tmp_path):
    done = run_program("python -m hasa_env", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    for env_id in hasa_env.ENV_IDS:
        assert f"{env_id}" in done.stdout and "ok (action Box(2,), observation Box(6,))" in (
            done.stdout
        )
    assert "hasa-bench" in done.stdout and "hasa-demo" in done.stdout
    done = run_program("python -m hasa_env", "--config", cwd=tmp_path)
    assert done.returncode == 0 and "time_limit = 30.0" in done.stdout


@pytest.mark.parametrize("args", [(), ("--config",)])
def test_python_m_hasa_env_ends_quietly_when_the_reader_closes_the_pipe(tmp_path, args):
    """``python -m hasa_env | head -1``: the reader gone, no BrokenPipeError traceback."""
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader has gone before the first line: every write fails
    try:
        done = subprocess.run(
            program_command("python -m hasa_env", *args),
            cwd=tmp_path,
            env=program_env(),
            stdout=write_end,
            stderr=subprocess.PIPE,
            text=True,
            timeout=120,
        )
    finally:
        os.close(write_end)
    assert done.stderr == ""
    assert done.returncode == 0
