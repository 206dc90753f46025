"""The versions of Python and installed distributions, for sidecars and result files."""

from __future__ import annotations

import platform
from collections.abc import Mapping
from importlib.metadata import PackageNotFoundError, version

__all__ = ["installed_versions"]


def installed_versions(distributions: Mapping[str, str]) -> dict[str, str]:
    """``{"python": ..., key: version of distribution, ...}`` for ``{key: distribution}``
    (``"not installed"`` for a distribution that is not)."""
    out = {"python": platform.python_version()}
    for key, name in distributions.items():
        try:
            out[key] = version(name)
        except PackageNotFoundError:
            out[key] = "not installed"
    return out
