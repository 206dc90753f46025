"""Shared by the replay tests (pytest puts tests/ on sys.path): edit a recording's CSV."""

from __future__ import annotations

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
