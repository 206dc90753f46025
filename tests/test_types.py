"""The four packages type-check: mypy (configured in pyproject.toml [tool.mypy]) finds nothing.

mypy runs through its API on the packages the configuration lists, so a new module
is checked without editing this test; the first run in a fresh clone takes about
20 s (later runs use ``.mypy_cache``).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

api = pytest.importorskip("mypy.api", reason="mypy is in the test extra: pip install -e .[test]")

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_mypy_finds_no_error() -> None:
    cwd = os.getcwd()
    os.chdir(ROOT)  # the configuration's package list and cache are relative to the root
    try:
        stdout, stderr, status = api.run(["--config-file", str(ROOT / "pyproject.toml")])
    finally:
        os.chdir(cwd)
    assert status == 0, f"mypy found errors:\n{stdout}{stderr}"
    assert "Success: no issues found" in stdout


def test_mypy_configuration_lists_every_package() -> None:
    """Every top-level package the distribution ships is type-checked."""
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    checked = set(config["tool"]["mypy"]["packages"])
    shipped = {
        pattern.rstrip("*")
        for pattern in config["tool"]["setuptools"]["packages"]["find"]["include"]
    }
    assert shipped == checked
