"""Run a console script as a user would: a fresh process in a working directory of its own.

``python -P -m hasa_cli.<module>`` is what the installed ``hasa-bench`` etc. run, without
the working directory on ``sys.path`` (``-P``), as a console script has it; ``PYTHONPATH``
points at this tree so the code under test is the one that runs.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]
MODULES = {
    "hasa-bench": "hasa_cli.bench",
    "hasa-drive": "hasa_cli.drive",
    "hasa-replay": "hasa_cli.replay",
    "hasa-rec": "hasa_cli.rec",
    "hasa-demo": "hasa_cli.demo",
    "python -m hasa_env": "hasa_env",
}
HEADLESS = {"SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy", "MPLBACKEND": "Agg"}


def program_env(**extra: str) -> dict[str, str]:
    """The environment of a program run by a test: headless, this tree first on the path."""
    env = {**os.environ, **HEADLESS, **extra}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    return env


def program_command(program: str, *args: str) -> list[str]:
    """The command line that runs ``program`` (a key of :data:`MODULES`) with ``args``."""
    return [sys.executable, "-P", "-m", MODULES[program], *map(str, args)]


def run_program(
    program: str, *args: str, cwd: Path, timeout: float = 120.0, **env: str
) -> subprocess.CompletedProcess[str]:
    """Run ``program args`` in ``cwd`` to its end; stdout and stderr captured as text."""
    return subprocess.run(
        program_command(program, *args),
        cwd=cwd,
        env=program_env(**env),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def load_example(name: str) -> ModuleType:
    """``examples/<name>.py``, imported afresh from its file (examples/ is no package)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
