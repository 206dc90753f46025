"""Reading recordings: :func:`load_recording` and :func:`load_recordings` validate
the files and name the file, line and column of every problem.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path

from hasa_env.recording.format import (
    Recording,
    RecordingError,
    RecordingList,
    RecordingWarning,
    _check_table,
    _frame,
    _parse_lines,
    _paths,
    _read_sidecar,
)

__all__ = ["load_paths", "load_recording", "load_recordings"]


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
    csv_path, json_path = _paths(path)
    meta = _read_sidecar(json_path)
    try:
        with open(csv_path, encoding="utf-8", newline="") as f:
            text = f.read()
    except FileNotFoundError:
        raise RecordingError("missing CSV file (the sidecar exists)", csv_path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"unreadable CSV: {exc}", csv_path) from None
    lines = text.split("\n")
    notes: list[str] = []
    if lines[-1] == "":
        lines.pop()
    elif not meta["complete"]:
        partial = lines.pop()
        note = (
            f"{csv_path}: dropped the partly written line {len(lines) + 1} of this incomplete "
            f"recording ({len(partial)} characters, no final newline)"
        )
        notes.append(note)
        warnings.warn(note, RecordingWarning, stacklevel=2)
    lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    columns = _parse_lines(lines, csv_path)
    frame = _frame(columns)
    _check_table(frame, meta["config"], csv_path, 2)
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


def load_recordings(directory: str | os.PathLike[str], *, strict: bool = False) -> RecordingList:
    """Load every recording (``*.csv`` with its ``.json`` sidecar) in ``directory``, sorted by name.

    Corrupt recordings do not stop the others from loading. By default each
    is reported with a :class:`RecordingWarning` naming the file, line and
    column, and collected in the result's ``errors`` list
    (:class:`RecordingError` objects; ``error.path`` is the file). A sidecar
    without its CSV counts as corrupt too. With ``strict=True`` a
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
        if side.stem not in stems:
            errors.append(RecordingError("sidecar without its CSV file", side.with_suffix(".csv")))
    result = RecordingList(good, errors)
    if errors and strict:
        exc = RecordingError(
            f"{len(errors)} corrupt recording(s) in {root}:\n" + "\n".join(f"  {e}" for e in errors)
        )
        exc.loaded = result  # type: ignore[attr-defined]
        raise exc
    for e in errors:
        warnings.warn(f"skipped corrupt recording: {e}", RecordingWarning, stacklevel=2)
    for rec in good:
        for note in rec.warnings:
            warnings.warn(note, RecordingWarning, stacklevel=2)
    return result


def load_paths(paths: Sequence[str | os.PathLike[str]]) -> RecordingList:
    """Load the recordings named by ``paths`` (files, or directories searched recursively), quietly.

    The one loader of the command-line tools and the benchmark: every file
    that cannot be loaded is collected, not raised, so one bad file never
    stops a batch.

    Returns:
        A :class:`RecordingList`: the loaded recordings in path order; its
        ``errors`` hold one :class:`RecordingError` per file (or path) that
        could not be loaded, naming it.
    """
    recordings: list[Recording] = []
    problems: list[RecordingError] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            dirs = sorted(
                {p.parent for p in path.rglob("*.csv")} | {p.parent for p in path.rglob("*.json")}
            )
            if not dirs:
                problems.append(
                    RecordingError("no recordings (no *.csv files) here or below", path)
                )
            for d in dirs:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RecordingWarning)
                    loaded = load_recordings(d)
                recordings.extend(loaded)
                problems.extend(loaded.errors)
        else:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RecordingWarning)
                    recordings.append(load_recording(path))
            except RecordingError as exc:
                problems.append(exc)
    return RecordingList(recordings, problems)
