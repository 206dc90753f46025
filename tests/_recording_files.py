"""Shared by the replay tests (pytest puts tests/ on sys.path): edit a recording's CSV."""

from __future__ import annotations

import json
from pathlib import Path


def tamper(csv: Path, row: int, column: str, delta: float) -> None:
    """Add ``delta`` to ``column`` of data row ``row`` (0-based, after the header) of ``csv``,
    in place; the replay check should then say the recording diverges there."""
    lines = csv.read_text().split("\n")
    col = lines[0].split(",").index(column)
    fields = lines[1 + row].split(",")
    fields[col] = repr(float(fields[col]) + delta)
    lines[1 + row] = ",".join(fields)
    csv.write_text("\n".join(lines))


def crash(csv: Path) -> None:
    """Make ``csv`` a recording whose writer crashed while writing its last line, in place: its
    sidecar says it is incomplete, and the CSV ends inside that line (no final newline); it
    should still load, that line dropped with a note (the recording's ``warnings``)."""
    sidecar = csv.with_suffix(".json")
    meta = json.loads(sidecar.read_text())
    meta.update(complete=False, steps=None, end_reason=None, finished=None)
    sidecar.write_text(json.dumps(meta))
    text = csv.read_text()
    csv.write_text(text[: text.rindex(",", 0, len(text) - 10)])  # the line being written
