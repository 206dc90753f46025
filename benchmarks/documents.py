"""What every document a benchmark writes records, in plain JSON data: :func:`json_clean`
and :func:`versions` (``results.json`` of ``hasa-bench``, ``hasa-replay --json``).

Light on purpose: ``hasa-replay`` imports it without the protocol package.
"""

from __future__ import annotations

import contextlib
import math
import os
import platform
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from hasa_env._versions import installed_versions

__all__ = ["json_clean", "versions"]


def json_clean(value: Any) -> Any:
    """``value`` as plain JSON data: numpy scalars and arrays as Python values, NaN and
    infinities as None."""
    if isinstance(value, Mapping):
        return {str(k): json_clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_clean(value.tolist())
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    return value


def _git(root: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """``git -C root args`` (5 s at most), its output captured."""
    return subprocess.run(
        ["git", "-C", str(root), *args], capture_output=True, text=True, timeout=5, check=False
    )


def versions() -> dict[str, str]:
    names = ("hasa-env", "numpy", "scipy", "pandas", "gymnasium", "statsmodels", "matplotlib",
             "distributed")  # fmt: skip
    out = installed_versions({name: name for name in names}) | {"platform": platform.platform()}
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        root = Path(__file__).resolve().parent  # the package, in the checkout if any
        commit = _git(root, "rev-parse", "HEAD").stdout.strip()
        if commit:
            out["git_commit"] = commit
            changed = _git(root, "status", "--porcelain", "--untracked-files=no")
            if changed.returncode == 0:  # the commit alone does not say what ran
                out["git_tree"] = "modified" if changed.stdout.strip() else "clean"
    out["cpus"] = str(os.cpu_count())
    return out
