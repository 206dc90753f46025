"""Recordings as Parquet files: :func:`to_parquet` / :func:`read_parquet` convert a
recording to one self-contained Parquet file (the sidecar travels in the
file's schema metadata). pyarrow is an optional extra (``hasa-env[parquet]``),
imported when used.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from hasa_env.recording.format import (
    Recording,
    RecordingError,
    _validate_meta,
)
from hasa_env.recording.reader import load_recording
from hasa_env.sim.setup import RECORDING_COLUMNS

__all__ = ["PARQUET_METADATA_KEY", "read_parquet", "require_pyarrow", "to_parquet"]

PARQUET_METADATA_KEY = b"hasa_env.recording"
"""Key of the sidecar JSON in a converted Parquet file's schema metadata."""


def require_pyarrow() -> Any:
    """Import and return ``pyarrow.parquet``, or raise ImportError saying how to install it."""
    try:
        import pyarrow.parquet as pq  # optional extra 'parquet'
    except ImportError as exc:
        raise ImportError(
            "pyarrow is not installed; install the Parquet extra: pip install 'hasa-env[parquet]'"
        ) from exc
    return pq


def to_parquet(
    recording: Recording | str | os.PathLike[str], path: str | os.PathLike[str] | None = None
) -> Path:
    """Write one recording as a Parquet file; returns its path.

    Columns and dtypes are the recording's (:data:`hasa_env.sim.setup.RECORDING_COLUMNS`:
    int64 ``step``/``bias_index``, bool flags, float64 values, bit-exact);
    the sidecar JSON is stored in the schema metadata under
    ``hasa_env.recording`` (read it back with :func:`read_parquet`). ``path``
    defaults to the CSV's path with ``.parquet``; an existing file is replaced.

    Raises:
        ImportError: pyarrow is not installed.
        RecordingError: the recording is corrupt (file, line, column).
    """
    pq = require_pyarrow()
    import pyarrow as pa  # optional extra 'parquet'

    if not isinstance(recording, Recording):
        recording = load_recording(recording)
    if path is None:
        if recording.path is None:
            raise ValueError("give a path for a recording that has no file")
        path = recording.path.with_suffix(".parquet")
    path = Path(path)
    table = pa.Table.from_pandas(recording.data[list(RECORDING_COLUMNS)], preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[PARQUET_METADATA_KEY] = json.dumps(recording.meta, allow_nan=False).encode("utf-8")
    table = table.replace_schema_metadata(meta)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)
    return path


def read_parquet(path: str | os.PathLike[str]) -> Recording:
    """Read a recording written by :func:`to_parquet` (validated like a CSV recording).

    Raises:
        ImportError: pyarrow is not installed.
        RecordingError: not a hasa_env recording, or invalid columns or values.
    """
    pq = require_pyarrow()
    path = Path(path)
    try:
        table = pq.read_table(path)
    except FileNotFoundError:
        raise RecordingError("no such Parquet file", path) from None
    except OSError as exc:  # pyarrow raises ArrowInvalid (an OSError subclass) on bad files
        raise RecordingError(f"unreadable Parquet file: {exc}", path) from None
    raw = (table.schema.metadata or {}).get(PARQUET_METADATA_KEY)
    if raw is None:
        raise RecordingError(
            "not a hasa_env recording: no 'hasa_env.recording' sidecar in the Parquet metadata",
            path,
        )
    try:
        meta = _validate_meta(json.loads(raw.decode("utf-8")), path)
    except json.JSONDecodeError as exc:
        raise RecordingError(f"sidecar metadata is not valid JSON: {exc.msg}", path) from None
    names = list(table.column_names)
    if names != list(RECORDING_COLUMNS):
        missing = [c for c in RECORDING_COLUMNS if c not in names]
        extra = [c for c in names if c not in RECORDING_COLUMNS]
        raise RecordingError(
            f"columns differ from the schema (missing {missing}, unknown {extra})",
            path,
            column=(missing or extra or [None])[0],
        )
    frame = table.to_pandas()
    for column in RECORDING_COLUMNS:
        expected = (
            np.int64
            if column in ("step", "bias_index")
            else (np.bool_ if column in ("terminated", "truncated") else np.float64)
        )
        if frame[column].dtype != expected:
            raise RecordingError(
                f"dtype {frame[column].dtype} instead of {np.dtype(expected)}", path, column=column
            )
        if expected is np.float64:
            bad = np.flatnonzero(~np.isfinite(frame[column].to_numpy()))
            if bad.size:
                raise RecordingError(f"row {int(bad[0])}: non-finite value", path, column=column)
    step = frame["step"].to_numpy()
    bad = np.flatnonzero(step != np.arange(len(step)))
    if bad.size:
        i = int(bad[0])
        raise RecordingError(f"row {i}: step = {int(step[i])}, expected {i}", path, column="step")
    config = meta["config"]
    expected = step * config["action_repeat"] * (1.0 / config["sim_frequency"])
    time = frame["time"].to_numpy()
    bad = np.flatnonzero(np.abs(time - expected) > 1e-9 * np.maximum(1.0, np.abs(expected)))
    if bad.size:
        i = int(bad[0])
        raise RecordingError(
            f"row {i}: time = {time[i]!r} s, expected {expected[i]!r} s", path, column="time"
        )
    return Recording(frame, meta, path)
