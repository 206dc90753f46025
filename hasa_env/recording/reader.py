"""Reading recordings: :func:`load_recording` and :func:`load_recordings` validate
the files and name the file, line and column of every problem.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import stat
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hasa_env._walk import walk_files
from hasa_env.extras import install_hint
from hasa_env.files import file_kind
from hasa_env.recording.format import (
    BOOL_COLUMNS,
    INT_COLUMNS,
    Recording,
    RecordingError,
    RecordingList,
    RecordingWarning,
    check_header,
    check_table,
    columns_frame,
    magnitude_limit,
    parse_lines,
    read_regular_bytes,
    read_regular_file,
    read_sidecar,
    recording_paths,
    validate_sidecar,
)
from hasa_env.sim.setup import RECORDING_COLUMNS

__all__ = [
    "PARQUET_METADATA_KEY",
    "load_any",
    "load_notes",
    "load_paths",
    "load_recording",
    "load_recordings",
    "read_parquet",
    "require_pyarrow",
    "warn_load_notes",
]


MAX_REASON = 300
"""Most characters of an unexpected error's text a :class:`RecordingError` quotes."""


def load_recording(path: str | os.PathLike[str]) -> Recording:
    """Load and validate one recording (the CSV or its sidecar's path; ``.csv`` may be omitted).

    Checks the sidecar (present, valid JSON, known ``schema_version``, valid
    config, ``columns``) and every line of the CSV (header: no missing,
    unknown or duplicated columns; each line: the right number of fields,
    finite numbers, integer ``step`` / ``bias_index``, ``true``/``false``
    flags; ``step`` counting from 0; ``time`` = step x Ts x action_repeat;
    the sidecar's ``steps`` of a complete recording matches the rows).

    An incomplete recording (``"complete": false``, its writer crashed)
    loads; if its last line has no final newline it was being written when
    the process died and is dropped (with a :class:`RecordingWarning`).

    Raises:
        RecordingError: naming the file, the line (1 = header) and the column.
    """
    try:
        return _load_recording(path)
    except RecordingError:
        raise
    except (ValueError, TypeError, KeyError, AttributeError, OverflowError, RecursionError) as exc:
        # the checks above name every problem they know; anything else a file can
        # cause is still this file's error, never a crash of the caller's batch
        text = str(exc)
        if len(text) > MAX_REASON:  # never quote a whole file in one line
            text = f"{text[:MAX_REASON]}... ({len(text) - MAX_REASON} more characters)"
        raise RecordingError(
            f"invalid recording ({type(exc).__name__}: {text})", recording_paths(path)[0]
        ) from exc


def _load_recording(path: str | os.PathLike[str]) -> Recording:
    csv_path, json_path = recording_paths(path)
    for p in (csv_path, json_path):
        try:
            os.lstat(p)
        except (FileNotFoundError, NotADirectoryError):
            continue
        except OSError as exc:  # e.g. a folder that can be listed but not searched
            raise RecordingError(f"cannot reach the file: {exc.strerror or exc}", p) from None
    if not os.path.lexists(csv_path) and not os.path.lexists(json_path):
        raise RecordingError(
            f"no such recording (neither it nor {json_path.name} exists)", csv_path
        )
    try:
        meta = read_sidecar(json_path)
    except RecordingError as exc:
        if exc.reason.startswith("missing sidecar") and _is_started_episode(csv_path):
            raise RecordingError(
                "incomplete: its recorder stopped while starting the episode (no sidecar yet, "
                "at most the reset row written); nothing of it can be used",
                csv_path,
            ) from None
        if exc.reason.startswith("missing sidecar"):  # named by the CSV the user has
            raise RecordingError(
                f"missing sidecar {json_path.name} (the JSON file next to the CSV; a CSV "
                "without one is not a recording)",
                csv_path,
            ) from None
        raise
    try:
        data = read_regular_bytes(csv_path, "the CSV")
    except FileNotFoundError:
        raise RecordingError("missing CSV file (the sidecar exists)", csv_path) from None
    except OSError as exc:
        raise RecordingError(f"unreadable CSV: {exc}", csv_path) from None
    frame = _fast_frame(data, csv_path)
    notes: list[str] = []
    if frame is None:  # anything unusual: the exact parser names the line and the column
        frame = _exact_frame(data, meta, csv_path, notes)
    del data
    check_table(frame, meta["config"], csv_path, 2)
    if meta["complete"]:
        steps = meta.get("steps")
        if steps != len(frame) - 1:
            raise RecordingError(
                f"sidecar says steps = {steps!r} but the CSV has {len(frame) - 1} rows after row 0 "
                "(truncated or appended file?)",
                json_path,
                column="steps",
            )
    # the same attrs as the drivers' runner gives its frames, so downstream code
    # (road of the track, lane hypotheses) treats loaded and generated runs alike
    frame.attrs = {
        "env_id": meta.get("env_id"),
        "config": meta["config"],
        "track": meta["config"]["track"],
        "seed": meta.get("seed"),
        "reset_options": dict(meta.get("reset_options") or {}),
        "metadata": dict(meta.get("metadata") or {}),
        "path": str(csv_path),
    }
    return Recording(frame, meta, csv_path, notes)


def _exact_frame(
    data: bytes, meta: dict[str, Any], csv_path: Path, notes: list[str]
) -> pd.DataFrame:
    """The rows of the CSV ``data``, parsed line by line and field by field (each problem
    named by line and column); a partly written last line of an incomplete recording is
    dropped with a note in ``notes``."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RecordingError(f"unreadable CSV: {exc}", csv_path) from None
    lines = text.split("\n")
    if lines[-1] == "":
        lines.pop()
    elif meta["complete"] and len(lines) > 1:
        raise RecordingError(
            "the last line has no final newline: the file was cut inside it (a complete "
            "recording ends with a newline)",
            csv_path,
            len(lines),
        )
    elif not meta["complete"]:
        partial = lines.pop()
        note = (
            f"{csv_path}: dropped the partly written line {len(lines) + 1} of this incomplete "
            f"recording ({len(partial)} characters, no final newline)"
        )
        notes.append(note)
        warnings.warn(note, RecordingWarning, stacklevel=2)
    lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    return columns_frame(parse_lines(lines, csv_path))


_PLAIN = b"0123456789.eE+-,\r\ntrufalsTRUFALS"
"""The bytes of an ordinary recording's rows (no spaces, quotes, nor letters of nan or inf)."""


def _plain(data: bytes, start: int, end: int, block: int = 1 << 24) -> bool:
    """Whether ``data[start:end]`` holds :data:`_PLAIN` bytes only (read in 16 MB blocks)."""
    view = memoryview(data)
    return not any(
        bytes(view[i : min(i + block, end)]).translate(None, _PLAIN)
        for i in range(start, end, block)
    )


def _fast_frame(data: bytes, source: Path) -> pd.DataFrame | None:
    """The rows of the CSV ``data`` read by pandas' C parser (bit-exact floats, memory about
    half the file's size on top of it), or None when the file is anything but an ordinary,
    complete CSV of plain numbers and flags: the exact parser then reads it and names the
    problem. What this accepts, the exact parser accepts with the same values.
    """
    header_end = data.find(b"\n")
    if not data.endswith(b"\n") or header_end < 0:
        return None
    try:
        names = data[:header_end].decode("ascii").removesuffix("\r").split(",")
        check_header(names, source)
    except (UnicodeDecodeError, RecordingError):
        return None
    rows = data.count(b"\n") - 1
    start, end = header_end + 1, len(data)
    if (
        rows < 1
        or not _plain(data, start, end)
        or data.count(b"\r", start, end) != data.count(b"\r\n", start, end)
        or data.find(b"\n\n", header_end, end) >= 0
        or data.find(b"\n\r\n", header_end, end) >= 0
        or data.count(b",", start, end) != rows * (len(names) - 1)
    ):
        return None
    dtypes = {c: ("int64" if c in INT_COLUMNS else "category" if c in BOOL_COLUMNS else "float64")
              for c in names}  # fmt: skip
    options = {"header": 0, "engine": "c", "quoting": csv.QUOTE_NONE, "na_filter": False,
               "skip_blank_lines": False, **_ROUND_TRIP}  # fmt: skip
    try:
        raw = pd.read_csv(io.BytesIO(data), dtype=dtypes, **options)  # type: ignore[call-overload]
        if len(raw) != rows or list(raw.columns) != names or not _plain_integers(data, options):
            return None
    except (ValueError, OverflowError, TypeError):  # ParserError is a ValueError
        return None
    return _checked_columns(raw)


_ROUND_TRIP = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
"""pandas' option for floats read bit-exactly (its default from pandas 3 on)."""


def _plain_integers(data: bytes, options: dict[str, Any], chunk: int = 1 << 16) -> bool:
    """Whether every integer cell (``step``, ``bias_index``) is written as an integer: pandas
    reads ``1.0`` and ``1e0`` as 1, which the format refuses. Read as text in chunks of
    ``chunk`` rows (memory bounded)."""
    with pd.read_csv(io.BytesIO(data), usecols=sorted(INT_COLUMNS), dtype=str,
                     chunksize=chunk, **options) as reader:  # fmt: skip
        for part in reader:
            for column in INT_COLUMNS:
                if part[column].str.contains(r"[.eE]", regex=True).any():
                    return False
    return True


def _checked_columns(raw: pd.DataFrame) -> pd.DataFrame | None:
    """``raw``'s columns in :data:`RECORDING_COLUMNS` order with the recording's dtypes, or
    None if a value is one the exact parser refuses (non-finite, implausible, an integer of
    more than 18 digits, a flag other than true/false in any case)."""
    out: dict[str, np.ndarray] = {}
    for c in RECORDING_COLUMNS:
        column = raw[c]
        if c in BOOL_COLUMNS:
            words = [str(w).lower() for w in column.cat.categories]
            if not set(words) <= {"true", "false"}:
                return None
            truth = np.asarray([w == "true" for w in words], dtype=bool)
            out[c] = truth[column.cat.codes.to_numpy()]
            continue
        values = column.to_numpy()
        limit = 10**18 - 1 if c in INT_COLUMNS else magnitude_limit(c)
        if not np.all(np.abs(values) <= limit):  # NaN too
            return None
        out[c] = values
    return pd.DataFrame(out, copy=False)


def _other_document(path: Path) -> bool:
    """A JSON file that says it is something else than a recording's sidecar (a study's
    session file, a calibration, a model file: its ``format`` names another document)."""
    try:
        text = read_regular_file(path, "the file")
    except (OSError, ValueError):
        return False
    try:
        doc = json.loads(text)
    except (ValueError, RecursionError):  # an invalid one still says what it is, near its top
        named = _FORMAT_RE.search(text[:4096])
        return named is not None and named.group(1) != "hasa_env recording"
    fmt = doc.get("format") if isinstance(doc, dict) else None
    return isinstance(fmt, str) and fmt != "hasa_env recording"


_FORMAT_RE = re.compile(r'^\s*\{\s*"format"\s*:\s*"([^"\\]*)"')


def _is_started_episode(csv_path: Path) -> bool:
    """A CSV that a recorder had only begun: empty, or at most the header and row 0."""
    try:
        text = read_regular_file(csv_path, "the CSV")
    except (OSError, UnicodeDecodeError):
        return False
    return text.count("\n") <= 2 and (not text or text.startswith(RECORDING_COLUMNS[0] + ","))


def load_recordings(directory: str | os.PathLike[str], *, strict: bool = False) -> RecordingList:
    """Load every recording (``*.csv`` with its ``.json`` sidecar) in ``directory``, sorted by name.

    Corrupt recordings do not stop the others from loading. By default each
    is reported with a :class:`RecordingWarning` naming the file, line and
    column, and collected in the result's ``errors`` list
    (:class:`RecordingError` objects; ``error.path`` is the file). A sidecar
    without its CSV counts as corrupt too; a JSON file whose ``format`` names
    another kind of document (a study's session file, a calibration) is not
    a recording and is left alone. With ``strict=True`` a
    :class:`RecordingError` listing every corrupt file is raised instead
    (its ``loaded`` attribute holds the recordings that did load).
    """
    root = Path(directory)
    if not root.is_dir():
        raise FileNotFoundError(f"recordings directory {str(root)!r} does not exist")
    good: list[Recording] = []
    errors: list[RecordingError] = []
    csvs = sorted(root.glob("*.csv"))
    for path in csvs:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RecordingWarning)
                good.append(load_recording(path))
        except RecordingError as exc:
            errors.append(exc)
    stems = {p.stem for p in csvs}
    for side in sorted(root.glob("*.json")):
        if side.stem not in stems and not _other_document(side):
            errors.append(RecordingError("sidecar without its CSV file", side.with_suffix(".csv")))
    result = RecordingList(good, errors)
    if errors and strict:
        error = RecordingError(
            f"{len(errors)} corrupt recording(s) in {root}:\n" + "\n".join(f"  {e}" for e in errors)
        )
        error.loaded = result
        raise error
    for e in errors:
        warnings.warn(f"skipped corrupt recording: {e}", RecordingWarning, stacklevel=2)
    warn_load_notes(good, stacklevel=2)  # each names its file, shown where this was called
    return result


def subfolder_hint(folder: str | os.PathLike[str]) -> str:
    """For a tool that reads the recordings of ``folder`` itself, not of its subfolders: ``""``
    when none are below it either, else `` (its subfolders hold N recording(s), e.g. in
    DIR: give a subfolder)``, to end a "no recordings" message (a study's root holds one
    folder per participant)."""
    root = Path(folder)
    files, _ = walk_files(root, (".csv",))
    nested = [p for p in files if p.parent != root and p.with_suffix(".json").exists()]
    if not nested:
        return ""
    return (
        f" (its subfolders hold {len(nested)} recording(s), e.g. in {nested[0].parent}: "
        "give a subfolder)"
    )


def load_paths(paths: Sequence[str | os.PathLike[str]]) -> RecordingList:
    """Load the recordings named by ``paths`` (files, or directories searched recursively), quietly.

    The one loader of the command-line tools: every file that cannot be
    loaded is collected, not raised, so one bad file never stops a batch. A
    file may be a recording's CSV (or its sidecar) or a Parquet file written
    by :func:`hasa_env.recording.parquet.to_parquet`; a directory contributes
    every CSV recording in it and below, and every ``*.parquet`` that has no
    CSV of the same name beside it (a converted copy is not loaded twice).

    Returns:
        A :class:`RecordingList`: the loaded recordings in path order; its
        ``errors`` hold one :class:`RecordingError` per file (or path) that
        could not be loaded, naming it (a path that does not exist, a folder
        without recordings, a corrupt file).
    """
    recordings: list[Recording] = []
    problems: list[RecordingError] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            files, unreadable = walk_files(path, (".csv", ".json", ".parquet"))
            problems += [RecordingError(reason, folder) for folder, reason in unreadable]
            found = [p for p in files if p.suffix in (".csv", ".json")]
            parquets = [
                p for p in files if p.suffix == ".parquet" and not p.with_suffix(".csv").exists()
            ]
            if not found and not parquets and not unreadable:
                problems.append(
                    RecordingError(
                        "no recordings (no *.csv or *.parquet files) here or below", path
                    )
                )
            for d in sorted({p.parent for p in found}):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RecordingWarning)
                    loaded = load_recordings(d)
                recordings.extend(loaded)
                problems.extend(loaded.errors)
            for p in parquets:
                try:
                    recordings.append(read_parquet(p))
                except (RecordingError, ImportError) as exc:
                    problems.append(_as_recording_error(exc, p))
        elif not os.path.lexists(path) and not any(map(os.path.lexists, recording_paths(path))):
            problems.append(RecordingError("no such file or directory", path))
        else:
            try:
                recordings.append(load_any(path))
            except (RecordingError, ImportError) as exc:
                problems.append(_as_recording_error(exc, path))
    return RecordingList(recordings, problems)


def _as_recording_error(exc: Exception, path: Path) -> RecordingError:
    if isinstance(exc, RecordingError):
        return exc
    return RecordingError(str(exc), path)


def load_any(path: str | os.PathLike[str]) -> Recording:
    """Load one recording, quietly: a CSV recording (or its sidecar) or a Parquet file.

    Raises:
        RecordingError: corrupt (file, line and column named).
        ImportError: a ``.parquet`` file without pyarrow installed.
    """
    p = Path(path)
    if p.suffix == ".parquet":
        return read_parquet(p)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordingWarning)
        return load_recording(p)


def load_notes(rec: Recording) -> list[str]:
    """What loading ``rec`` repaired or tolerated (:attr:`Recording.warnings`, e.g. the partly
    written last line of a crashed recording dropped), in order, each naming the file."""
    if rec.path is None:
        return list(rec.warnings)
    prefix = f"{rec.path}: "
    return [note if note.startswith(prefix) else prefix + note for note in rec.warnings]


def warn_load_notes(recordings: Iterable[Recording], *, stacklevel: int = 1) -> None:
    """Show each recording's :func:`load_notes` as a :class:`RecordingWarning`, in order: what
    the quiet loaders (:func:`load_paths`, :func:`load_any`) kept in the recordings'
    ``warnings``. The programs that load recordings call it once per loaded recording.
    ``stacklevel``: where the warnings say they arose, counted from the caller (1: the line
    that calls this; 2: its caller's, as :func:`load_recordings` shows them)."""
    for rec in recordings:
        for note in load_notes(rec):
            warnings.warn(note, RecordingWarning, stacklevel=stacklevel + 1)


# -------------------------------------------------------------------- Parquet
PARQUET_METADATA_KEY = b"hasa_env.recording"
"""Key of the sidecar JSON in a converted Parquet file's schema metadata."""


def require_pyarrow() -> Any:
    """Import and return ``pyarrow.parquet``, or raise ImportError saying how to install it."""
    try:
        import pyarrow.parquet as pq  # optional extra 'parquet'
    except ImportError as exc:
        raise ImportError(
            f"pyarrow is not installed; install the parquet extra: {install_hint('parquet')}"
        ) from exc
    return pq


def read_parquet(path: str | os.PathLike[str]) -> Recording:
    """Read a recording written by :func:`hasa_env.recording.parquet.to_parquet` (validated
    like a CSV recording).

    Raises:
        ImportError: pyarrow is not installed.
        RecordingError: not a hasa_env recording, or invalid columns or values.
    """
    pq = require_pyarrow()
    import pyarrow as pa  # optional extra 'parquet'

    path = Path(path)
    try:
        _check_regular(path, "the Parquet file")
        table = pq.read_table(path)
    except FileNotFoundError:
        raise RecordingError("no such Parquet file", path) from None
    except (OSError, ValueError, pa.lib.ArrowException) as exc:  # ArrowInvalid is a ValueError
        raise RecordingError(f"unreadable Parquet file: {exc}", path) from None
    raw = (table.schema.metadata or {}).get(PARQUET_METADATA_KEY)
    if raw is None:
        raise RecordingError(
            "not a hasa_env recording: no 'hasa_env.recording' sidecar in the Parquet metadata",
            path,
        )
    try:
        decoded = json.loads(raw.decode("utf-8"))
    except (ValueError, RecursionError) as exc:  # JSONDecodeError and UnicodeDecodeError too
        raise RecordingError(f"sidecar metadata is not valid JSON: {exc}", path) from None
    meta = validate_sidecar(decoded, path)
    names = list(table.column_names)
    if names != list(RECORDING_COLUMNS):
        missing = [c for c in RECORDING_COLUMNS if c not in names]
        extra = [c for c in names if c not in RECORDING_COLUMNS]
        raise RecordingError(
            f"columns differ from the schema (missing {missing}, unknown {extra})",
            path,
            column=(missing or extra or [None])[0],
        )
    try:
        frame = table.to_pandas()
    except (ValueError, TypeError, pa.lib.ArrowException) as exc:
        raise RecordingError(f"unreadable Parquet columns: {exc}", path) from None
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
            values = frame[column].to_numpy()
            limit = magnitude_limit(column)
            bad = np.flatnonzero(~(np.abs(values) <= limit))
            if bad.size:
                raise RecordingError(
                    f"row {int(bad[0])}: {float(values[bad[0]])!r} is not a finite value of at "
                    f"most {limit:g} in magnitude",
                    path,
                    column=column,
                )
    if not len(frame):
        raise RecordingError("no rows (row 0, the reset state, is required)", path)
    try:
        check_table(frame, meta["config"], path, 0)
    except RecordingError as exc:  # rows, not lines, in a Parquet file
        raise RecordingError(f"row {exc.line}: {exc.reason}", path, column=exc.column) from None
    if meta["complete"] and meta.get("steps") != len(frame) - 1:
        raise RecordingError(
            f"sidecar says steps = {meta.get('steps')!r} but the file has {len(frame) - 1} rows "
            "after row 0",
            path,
            column="steps",
        )
    return Recording(frame, meta, path)


def _check_regular(path: Path, what: str) -> None:
    """Raise OSError unless ``path`` is a regular file (a FIFO would block the reader)."""
    info = os.stat(path)
    if not stat.S_ISREG(info.st_mode):
        raise OSError(f"{what} is {file_kind(info.st_mode)}, not a regular file")
