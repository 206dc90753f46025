"""How to install the optional extras, said the same way by every message that needs one."""

from __future__ import annotations

__all__ = ["install_hint"]


def install_hint(extra: str) -> str:
    """The pip command that installs the optional ``extra`` (``rl``, ``parquet``, ``minari``,
    ``dask``, ``compare``), for an installed distribution and for a clone of the repository:
    ``pip install 'hasa-env[parquet]' (in a clone: pip install '.[parquet]')``."""
    return (
        f"pip install 'hasa-env[{extra}]' (in a clone of the repository: pip install '.[{extra}]')"
    )
