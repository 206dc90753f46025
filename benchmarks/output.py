"""A benchmark result's folder: checked before the protocol runs, replaced only when complete.

``hasa-bench paper|score --out DIR`` writes ``results.json``, the CSV tables,
``report.md``, ``report.html`` and the figures (:func:`benchmarks.report.write_outputs`)
into a new folder beside ``DIR`` and swaps it in at the end, so a failure leaves
``DIR`` as it was; a folder that holds anything but a previous result is
never replaced.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
from pathlib import Path

from benchmarks.protocol.results import RESULTS_FORMAT, BenchmarkResult
from benchmarks.report import write_outputs
from benchmarks.schema import ResultsSchemaError

__all__ = ["output_problem", "write_result_folder"]


def output_problem(out: Path, overwrite: bool) -> str | None:
    """What is wrong with writing the results to ``out``, or None (checked before any run).

    ``out`` must be absent, empty, or hold a previous result (``results.json`` of format
    :data:`RESULTS_FORMAT`) and ``overwrite`` be set; its parent must be writable.
    """
    if out.exists() and not out.is_dir():
        return f"--out {out}: exists and is not a folder"
    if out.is_dir() and any(out.iterdir()):
        previous = out / "results.json"
        try:
            ours = json.loads(previous.read_text(encoding="utf-8")).get("format")
        except (OSError, ValueError, AttributeError):
            ours = None
        if ours != RESULTS_FORMAT:
            return (
                f"--out {out}: is a folder that holds no hasa-bench result; "
                "choose another --out (it is never replaced)"
            )
        if not overwrite:
            return f"--out {out}: holds a previous result; --overwrite replaces it, or choose another --out"
    parent = out.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        probe = parent / f".{out.name}.probe-{secrets.token_hex(4)}"
        probe.mkdir()
        probe.rmdir()
    except OSError as exc:
        return f"--out {out}: cannot write there ({exc.strerror or exc})"
    return None


def write_result_folder(result: BenchmarkResult, out: Path, figures: bool) -> dict[str, Path]:
    """Write into a new folder beside ``out``, then swap it in: a failure leaves ``out`` as it was.

    Returns the files written (name -> path inside ``out``). Raises OSError if they cannot be
    written, and :class:`ResultsSchemaError` (the folder swapped in all the same: nothing
    measured is lost) if results.json breaks the shipped schema.
    """
    fresh = out.with_name(f".{out.name}.new-{secrets.token_hex(4)}")
    schema_error = None
    try:
        try:
            written = write_outputs(result, fresh, figures=figures)
        except ResultsSchemaError as exc:
            schema_error = exc
            written = {p.name: p for p in fresh.iterdir()}
        old = None
        if out.exists():
            old = out.with_name(f".{out.name}.old-{secrets.token_hex(4)}")
            os.replace(out, old)
        os.replace(fresh, out)
    except BaseException:
        shutil.rmtree(fresh, ignore_errors=True)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    if schema_error is not None:
        raise schema_error
    return {name: out / path.relative_to(fresh) for name, path in written.items()}
