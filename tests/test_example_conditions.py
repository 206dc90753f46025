"""examples/fit_steering_model.py drives the population in its study conditions, as
hasa-bench does (issue 21: the same drivers gave other numbers through the API)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from _programs import ROOT, program_env

from benchmarks.protocol import ProtocolConfig
from hasa_env.drivers import POPULATIONS


@pytest.mark.slow
def test_the_example_drives_in_the_conditions_hasa_bench_drives_in(tmp_path):
    conditions = dict(POPULATIONS["paper"].env_config)
    assert conditions and ProtocolConfig().env_config().items() >= conditions.items()
    done = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "fit_steering_model.py"), "--runs", "1"],
        cwd=tmp_path,
        env=program_env(),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    assert f"population 'paper', seed 0, in its study conditions {conditions}" in done.stdout
