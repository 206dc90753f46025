"""Recordings as Parquet files: :func:`to_parquet` / :func:`read_parquet` convert a
recording to one self-contained Parquet file (the sidecar travels in the
file's schema metadata). pyarrow is an optional extra (``hasa-env[parquet]``),
imported when used.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

from hasa_env.atomic import new_temporary_file
from hasa_env.recording.format import Recording
from hasa_env.recording.reader import (
    PARQUET_METADATA_KEY,
    load_recording,
    read_parquet,
    require_pyarrow,
)
from hasa_env.sim.setup import RECORDING_COLUMNS

__all__ = ["PARQUET_METADATA_KEY", "read_parquet", "require_pyarrow", "to_parquet"]


def to_parquet(
    recording: Recording | str | os.PathLike[str],
    path: str | os.PathLike[str] | None = None,
    *,
    overwrite: bool = True,
) -> Path:
    """Write one recording as a Parquet file; returns its path.

    Columns and dtypes are the recording's (:data:`hasa_env.sim.setup.RECORDING_COLUMNS`:
    int64 ``step``/``bias_index``, bool flags, float64 values, bit-exact);
    the sidecar JSON is stored in the schema metadata under
    ``hasa_env.recording`` (read it back with :func:`read_parquet`). ``path``
    defaults to the CSV's path with ``.parquet``; an existing file is replaced
    unless ``overwrite=False``. The file is written to a fresh temporary file
    and renamed, so a failure leaves any previous file as it was.

    Raises:
        ImportError: pyarrow is not installed.
        RecordingError: the recording is corrupt (file, line, column).
        FileExistsError: ``path`` exists and ``overwrite`` is False.
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
    if not overwrite and path.exists():
        raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = new_temporary_file(path)  # O_EXCL: no pre-placed file or symlink is followed
    try:
        with open(fd, "wb") as f:
            pq.write_table(table, f)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path
