"""The recording format: columns, units, errors, the loaded container, value
formatting and parsing, and the sidecar's schema.

A recording is a pair of files in one directory:

- ``run_000.csv``: one row per env step in the column order of
  :data:`hasa_env.sim.setup.RECORDING_COLUMNS` (units in :data:`COLUMN_UNITS`).
  Row 0 is the reset state; the ``steering`` and ``acceleration`` of row k
  are the physical action applied over the step that ended at row k (row 0:
  the initial steering and 0). Floats are written with ``repr`` so they read
  back bit-exactly; ``bias_index`` and ``step`` are integers; ``terminated``
  and ``truncated`` are ``true`` / ``false``.
- ``run_000.json``: the sidecar (schema version, env id, full config, seed,
  reset options, versions, columns and units, times, completeness, free-form
  ``metadata``). See ``recordings/README.md`` for every field; the loader
  checks each field's type through the shared validator
  (:mod:`hasa_env.validation`) and refuses fields it does not know.

Writing: :mod:`hasa_env.recording.writer`; reading: :mod:`hasa_env.recording.reader`;
re-simulating: :mod:`hasa_env.recording.replay`.

Why this module is long: it is the one definition of the files on disk (columns, units, value
formatting and parsing, the sidecar's schema, safe reads; atomic writes are :mod:`hasa_env.atomic`), which the writer,
the reader, the replay and the Parquet export share through its documented public names.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hasa_env._versions import installed_versions
from hasa_env.files import read_bounded_bytes, read_bounded_text
from hasa_env.sim.config import ConfigError, make_config
from hasa_env.sim.road import Road, make_road
from hasa_env.sim.sensors import SENSOR_NAMES, SENSOR_UNITS
from hasa_env.sim.setup import RECORDING_COLUMNS
from hasa_env.validation import ABSENT, ANY_JSON, Field, schema, show, validate, version

__all__ = [
    "SCHEMA_VERSION",
    "COLUMN_UNITS",
    "RecordingError",
    "RecordingWarning",
    "Recording",
    "RecordingList",
]

SCHEMA_VERSION = 1
"""Version of the recording format written by this module (the only one it reads)."""

COLUMN_UNITS: dict[str, str] = {
    "step": "1",
    "time": "s",
    "station": "m",
    "lateral_offset": "m",
    "heading": "rad",
    "speed": "m/s",
    "steering": "rad",
    "acceleration": "m/s^2",
    "road_curvature": "1/m",
    "longitudinal_velocity": "m/s",
    "lateral_velocity": "m/s",
    "bias": "m",
    "bias_index": "1",
    **{f"sensor_{name}": unit for name, unit in zip(SENSOR_NAMES, SENSOR_UNITS, strict=True)},
    "reward": "1",
    "terminated": "bool",
    "truncated": "bool",
}
"""Unit of every recording column ("1": dimensionless count or index)."""

INT_COLUMNS = frozenset({"step", "bias_index"})
"""Columns written and read as integers (int64 in a loaded frame)."""

BOOL_COLUMNS = frozenset({"terminated", "truncated"})
"""Columns written as ``true`` / ``false`` and read as bool."""

_INT_RE = re.compile(r"[+-]?[0-9]+")
SIDECAR_KEYS = (
    "config",
    "seed",
    "env_id",
    "reset_options",
    "metadata",
    "complete",
    "end_reason",
    "created",
)
"""Sidecar fields a caller may set through ``save_recording(..., meta=...)``."""

END_REASONS = ("terminated", "truncated", "stopped")
"""Allowed values of the sidecar field ``end_reason``."""


# --------------------------------------------------------------------- errors
class RecordingError(ValueError):
    """A corrupt or invalid recording (or DataFrame to be saved as one).

    The message names the file, and where known the line (1 = the CSV header)
    and the column; they are also available as :attr:`path`, :attr:`line` and
    :attr:`column`.
    """

    loaded: RecordingList
    """Set on the error :func:`~hasa_env.recording.reader.load_recordings` raises with
    ``strict=True``: the recordings that did load."""

    def __init__(
        self,
        message: str,
        path: str | os.PathLike[str] | None = None,
        line: int | None = None,
        column: str | None = None,
    ) -> None:
        self.path = None if path is None else Path(path)
        self.line = line
        self.column = column
        self.reason = message
        super().__init__(self.located if path is None else f"{path}{self._where(', ')}: {message}")

    @property
    def located(self) -> str:
        """The message with its line and column but not its file (for a list of skipped
        files that names each file itself): ``line 50, column 'speed': not a number: 'abc'``."""
        where = self._where("")
        return f"{where}: {self.reason}" if where else self.reason

    def _where(self, lead: str) -> str:
        """``line N, column 'c'`` (those known) after ``lead``, or ``""`` when neither is."""
        where = [f"line {self.line}"] if self.line is not None else []
        if self.column is not None:
            where.append(f"column {show(self.column)}")
        return lead + ", ".join(where) if where else ""


class RecordingWarning(UserWarning):
    """Something about a recording worth knowing that does not stop it loading."""


# ------------------------------------------------------------------ container
@dataclass
class Recording:
    """One loaded recording.

    Attributes:
        data: one row per env step, columns :data:`hasa_env.sim.setup.RECORDING_COLUMNS`
            (``step``, ``bias_index`` int64; ``terminated``, ``truncated`` bool;
            the rest float64, units in :data:`COLUMN_UNITS`).
        meta: the JSON sidecar as a dict (``config``, ``seed``, ``complete``, ...).
        path: the CSV file (None for a recording built in memory, e.g. by :func:`replay`).
        warnings: non-fatal notes from loading (e.g. a partly written last line dropped).
    """

    data: pd.DataFrame
    meta: dict[str, Any]
    path: Path | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def seed(self) -> int | None:
        """The episode's seed (passed to ``env.reset``), or None if unknown."""
        return self.meta.get("seed")

    @property
    def config(self) -> dict[str, Any]:
        """The env's full configuration."""
        return self.meta["config"]

    @property
    def complete(self) -> bool:
        """False for a recording whose writer never finalized it (a crash)."""
        return bool(self.meta.get("complete"))

    @property
    def steps(self) -> int:
        """Number of env steps recorded (rows after row 0)."""
        return len(self.data) - 1

    @property
    def dt(self) -> float:
        """Time between two rows (s): the env step, action_repeat / sim_frequency."""
        config = self.config
        return config["action_repeat"] / config["sim_frequency"]

    @property
    def road(self) -> Road:
        """The road the recording was made on (its config's track, lane width, lane shifts
        and hypotheses: a shift toward the other hypothesis is signed by the recorded bias)."""
        road = self.config["road"]
        return make_road(
            self.config["track"],
            lane_width=road["lane_width"],
            lane_shifts=road.get("lane_shifts", ()),
            hypotheses=self.config.get("markings", {}).get("hypotheses", ()),
        )


class RecordingList(list):
    """The recordings that loaded, plus an ``errors`` list of the files that did not.

    A plain ``list`` of :class:`Recording`; ``errors`` holds one
    :class:`RecordingError` per corrupt file (its ``path`` names the file).
    """

    def __init__(
        self, recordings: Iterable[Recording] = (), errors: Iterable[RecordingError] = ()
    ) -> None:
        super().__init__(recordings)
        self.errors: list[RecordingError] = list(errors)


# ------------------------------------------------------------------- helpers
def _versions() -> dict[str, str]:
    return installed_versions(
        {"hasa_env": "hasa-env", "gymnasium": "gymnasium", "numpy": "numpy", "pandas": "pandas"}
    )


def utc_now_text() -> str:
    """The current UTC time as ISO 8601 text with milliseconds and a ``Z`` suffix."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"{type(value).__name__} {value!r} is not JSON serializable")


def to_json_text(obj: Any) -> str:
    """``obj`` as indented JSON text ending in a newline; numpy values and paths converted,
    NaN and infinities refused (``ValueError``)."""
    return json.dumps(obj, indent=2, allow_nan=False, default=_json_default) + "\n"


MAX_FILE_BYTES = 2**31
"""Largest recording file read (2 GiB; a 30 s drive at 100 Hz is about 1.3 MB)."""


def read_regular_file(path: Path, what: str) -> str:
    """The text of ``path`` if it is a regular file of at most :data:`MAX_FILE_BYTES`, read
    without blocking on a FIFO or device (:func:`hasa_env.files.read_bounded_text`).

    Raises:
        FileNotFoundError: no such file.
        OSError, UnicodeDecodeError: unreadable (the message says why, e.g. a FIFO).
    """
    return read_bounded_text(path, what, MAX_FILE_BYTES)


def read_regular_bytes(path: Path, what: str) -> bytes:
    """The bytes of ``path`` if it is a regular file of at most :data:`MAX_FILE_BYTES`
    (:func:`hasa_env.files.read_bounded_bytes`).

    Raises:
        FileNotFoundError: no such file.
        OSError: unreadable (the message says why, e.g. a FIFO, or larger than
            :data:`MAX_FILE_BYTES`).
    """
    return read_bounded_bytes(path, what, MAX_FILE_BYTES)


def format_value(column: str, value: Any) -> str:
    """One CSV field; raises ValueError/TypeError with a reason on a bad value."""
    if column in BOOL_COLUMNS:
        if isinstance(value, bool | np.bool_) or (
            isinstance(value, int | np.integer | float | np.floating) and value in (0, 1)
        ):
            return "true" if value else "false"
        raise ValueError(f"expected a bool, got {value!r}")
    if column in INT_COLUMNS:
        if isinstance(value, bool | np.bool_):
            raise ValueError(f"expected an integer, got {value!r}")
        if isinstance(value, float | np.floating):
            if not (math.isfinite(value) and float(value).is_integer()):
                raise ValueError(f"expected an integer, got {value!r}")
        return str(int(value))
    if isinstance(value, bool | np.bool_):
        raise ValueError(f"expected a number, got {value!r}")
    return repr(float(value))


def format_row(values: Sequence[Any]) -> str:
    """One CSV line (with newline) of ``values`` in :data:`RECORDING_COLUMNS` order."""
    return (
        ",".join(format_value(c, v) for c, v in zip(RECORDING_COLUMNS, values, strict=True)) + "\n"
    )


CSV_HEADER = ",".join(RECORDING_COLUMNS) + "\n"
"""The CSV header line: the column names in :data:`RECORDING_COLUMNS` order."""


def base_sidecar(csv_name: str) -> dict[str, Any]:
    """A new sidecar for the CSV file ``csv_name``: every field, incomplete, created now."""
    return {
        "schema_version": SCHEMA_VERSION,
        "format": "hasa_env recording",
        "csv": csv_name,
        "env_id": None,
        "seed": None,
        "seed_source": None,
        "reset_options": None,
        "config": None,
        "versions": _versions(),
        "columns": list(RECORDING_COLUMNS),
        "units": {c: COLUMN_UNITS.get(c, "unknown") for c in RECORDING_COLUMNS},
        "created": utc_now_text(),
        "finished": None,
        "complete": False,
        "steps": None,
        "end_reason": None,
        "metadata": {},
    }


def _python_error(path: str, message: str) -> ValueError:
    return ValueError(message)


def check_json_able(name: str, value: Any) -> Any:
    """A fresh JSON-able copy of ``value`` (numpy values and tuples converted), so the sidecar
    holds exactly what was given; ``name`` names it in the ``ValueError``."""
    return validate(value, ANY_JSON, describe=lambda path: path, error=_python_error, path=name)


_SEED = Field("integer", doc="A seed of numpy's generators.", low=0)


def check_seed(seed: Any, what: str) -> int:
    """``seed`` as an int >= 0 (numpy integers accepted); ``what`` names it in the ``ValueError``."""
    return validate(seed, _SEED, describe=lambda path: path, error=_python_error, path=what)


# ------------------------------------------------------------------- parsing
MAX_MAGNITUDE = 1e6
"""Largest |value| of a float cell (in its column's unit) except ``time`` and ``station``.

No quantity of a lane-keeping drive comes near it (the road is at most about
50 m wide, speeds are at most 150 m/s, sensor noise std at most 50); a larger
finite value (``1e308``) is corruption, and would overflow to inf or NaN in
any mean of squares downstream."""

MAX_MAGNITUDE_LONG = 1e10
"""Largest |value| of ``time`` (s) and ``station`` (m): a 1e6 s episode at 150 m/s is 1.5e8 m."""

_LONG_COLUMNS = frozenset({"time", "station"})


def parse_float(text: str, limit: float = math.inf) -> float:
    """A finite float of plain ASCII ``text`` with ``|value| <= limit``; else ``ValueError``."""
    if not text.isascii():
        raise ValueError(f"not a number: {show(text)} (only ASCII digits are numbers here)")
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"not a number: {show(text)}") from None
    if not math.isfinite(value):
        raise ValueError(f"non-finite value {show(text)} (NaN and infinities are not allowed)")
    if "_" in text or text != text.strip():
        raise ValueError(f"not a plain number: {show(text)}")
    if abs(value) > limit:
        raise ValueError(
            f"implausible value {show(text)}: |value| must be at most {limit:g} in this column's unit"
        )
    return value


def magnitude_limit(column: str) -> float:
    """Largest |value| of a float cell of ``column``: :data:`MAX_MAGNITUDE_LONG` for ``time``
    and ``station``, :data:`MAX_MAGNITUDE` otherwise."""
    return MAX_MAGNITUDE_LONG if column in _LONG_COLUMNS else MAX_MAGNITUDE


def _parse_int(text: str) -> int:
    if not _INT_RE.fullmatch(text):
        raise ValueError(f"not an integer: {show(text)}")
    if len(text.lstrip("+-").lstrip("0")) > 18:  # (leading zeros are no digits of the value)
        raise ValueError(f"integer {show(text)} out of range: at most 18 digits")
    return int(text)


def _parse_bool(text: str) -> bool:
    low = text.lower()
    if low == "true":
        return True
    if low == "false":
        return False
    raise ValueError(f"not a bool: {show(text)} (expected true or false)")


def _parser(column: str):  # noqa: ANN202
    if column in INT_COLUMNS:
        return _parse_int
    if column in BOOL_COLUMNS:
        return _parse_bool
    limit = magnitude_limit(column)
    return lambda text: parse_float(text, limit)


def check_header(names: list[str], source: Path | str) -> None:
    """Raise :class:`RecordingError` (line 1) unless ``names`` are exactly the recording columns,
    each once, in any order."""
    seen: set[str] = set()
    dup = []
    for n in names:
        if n in seen:
            dup.append(n)
        seen.add(n)
    unknown = [n for n in names if n not in RECORDING_COLUMNS]
    missing = [c for c in RECORDING_COLUMNS if c not in seen]
    problems = []
    if dup:
        problems.append("duplicated column(s) " + _some(list(dict.fromkeys(dup))))
    if unknown:
        problems.append("unknown column(s) " + _some(unknown))
    if missing:
        problems.append("missing column(s) " + _some(missing))
    if problems:
        column: str | None = (dup or unknown or missing)[0]
        header = ",".join(names)
        if "\r" in header or "\u2028" in header or "\u2029" in header:
            # the whole file reads as one header line: its columns say nothing more
            problems = [
                "the header holds a carriage return or a Unicode line separator (a file of "
                "CR-only or U+2028 line ends?): lines must end with \\n (or \\r\\n)"
            ]
            column = None
        raise RecordingError(
            "bad header: " + "; ".join(problems) + f" (expected: {','.join(RECORDING_COLUMNS)})",
            source,
            1,
            column,
        )


MAX_QUOTED = 6
"""Most items of a list an error message quotes (then "and N more")."""


def _some(items: Sequence[str]) -> str:
    """At most :data:`MAX_QUOTED` of ``items``, each shortened (:func:`show`), then a count."""
    shown = ", ".join(show(n) for n in items[:MAX_QUOTED])
    more = len(items) - MAX_QUOTED
    return shown + (f" and {more} more" if more > 0 else "")


def parse_lines(lines: list[str], source: Path | str) -> dict[str, list[Any]]:
    """Parse header + data lines (without newlines) into columns; line 1 is the header."""
    if not lines:
        raise RecordingError("empty file: no header", source, 1)
    names = lines[0].split(",")
    check_header(names, source)
    parsers = [_parser(n) for n in names]
    columns: list[list[Any]] = [[] for _ in names]
    ncols = len(names)
    for lineno, line in enumerate(lines[1:], start=2):
        if not line:
            raise RecordingError(f"empty line (expected {ncols} fields)", source, lineno, names[0])
        fields = line.split(",")
        if len(fields) != ncols:
            if len(fields) < ncols:
                msg = f"{len(fields)} fields, expected {ncols}: the line ends before this column"
                raise RecordingError(msg, source, lineno, names[len(fields)])
            msg = f"{len(fields)} fields, expected {ncols}: extra field(s) after this column"
            raise RecordingError(msg, source, lineno, names[-1])
        for j, (text, parse) in enumerate(zip(fields, parsers, strict=True)):
            try:
                columns[j].append(parse(text))
            except ValueError as exc:
                raise RecordingError(str(exc), source, lineno, names[j]) from None
    if len(lines) < 2:
        raise RecordingError("no data rows (row 0, the reset state, is required)", source, 2)
    return dict(zip(names, columns, strict=True))


def columns_frame(columns: Mapping[str, Sequence[Any]]) -> pd.DataFrame:
    """A DataFrame of the recording columns in order, with their dtypes (int64, bool, float64)."""
    data = {}
    for c in RECORDING_COLUMNS:
        if c in INT_COLUMNS:
            data[c] = np.asarray(columns[c], dtype=np.int64)
        elif c in BOOL_COLUMNS:
            data[c] = np.asarray(columns[c], dtype=bool)
        else:
            data[c] = np.asarray(columns[c], dtype=np.float64)
    return pd.DataFrame(data)


def check_table(
    frame: pd.DataFrame, config: Mapping[str, Any], source: Path | str, first_line: int
) -> None:
    """Consistency checks on parsed rows; row i is on line ``first_line + i``."""
    step = frame["step"].to_numpy()
    bad = np.flatnonzero(step != np.arange(len(step)))
    if bad.size:
        i = int(bad[0])
        raise RecordingError(
            f"step = {int(step[i])}, expected {i} (steps must count 0, 1, 2, ... from row 0)",
            source,
            first_line + i,
            "step",
        )
    dt_step = config["action_repeat"] * (1.0 / config["sim_frequency"])
    expected = (step * config["action_repeat"]) * (1.0 / config["sim_frequency"])
    time = frame["time"].to_numpy()
    bad = np.flatnonzero(np.abs(time - expected) > 1e-9 * np.maximum(1.0, np.abs(expected)))
    if bad.size:
        i = int(bad[0])
        raise RecordingError(
            f"time = {float(time[i])!r} s does not match step {i}: expected "
            f"{float(expected[i])!r} s "
            f"(step x {dt_step!r} s per env step, from the config's sim_frequency and "
            "action_repeat)",
            source,
            first_line + i,
            "time",
        )
    check_physics(frame, config, source, first_line)


def _first_bad(bad: np.ndarray, source: Path | str, first_line: int, column: str, why: Any) -> None:
    """Raise :class:`RecordingError` at the first True of ``bad`` (``why(i)``: the reason)."""
    rows = np.flatnonzero(bad)
    if rows.size:
        i = int(rows[0])
        raise RecordingError(why(i), source, first_line + i, column)


def lateral_limit(config: Mapping[str, Any]) -> float:
    """Largest |lateral_offset| (m) an env with ``config`` can record: a reset may put the car
    up to 30 m from the lane centre (or the road's outer edge plus ``offroad_margin``; or
    the configured start, 20 m to a halfway point and 8 std of its randomisation), and the
    episode ends at the first env step past the edge, during which the car moves at most
    ``max_speed`` x the env step sideways."""
    road, start = config["road"], config["initial_state"]
    width = road["lane_width"]
    edge = width / 2 + max(road["lanes_left"], road["lanes_right"]) * width
    drawn = abs(start["lateral_offset"]) + 20.0 + 8.0 * start["lateral_offset_std"]
    reach = max(30.0, edge + road["offroad_margin"], drawn)
    return (
        reach + config["vehicle"]["max_speed"] * config["action_repeat"] / config["sim_frequency"]
    )


def check_physics(
    frame: pd.DataFrame, config: Mapping[str, Any], source: Path | str, first_line: int
) -> None:
    """Refuse rows that the env cannot have recorded (row i is on line ``first_line + i``).

    The true lane (``bias_index``: -1 or an index of ``markings.hypotheses``, and ``bias``
    that hypothesis's value) is drawn once per episode and never changes; ``terminated``
    and ``truncated`` end the episode, so only the last row may have them; the speed is
    within [0, ``vehicle.max_speed``] m/s; ``|lateral_offset|`` is at most
    :func:`lateral_limit` m.
    """
    hyps = np.asarray(config["markings"]["hypotheses"], dtype=np.float64)
    index = frame["bias_index"].to_numpy()
    bias = frame["bias"].to_numpy()
    _first_bad((index < -1) | (index >= len(hyps)), source, first_line, "bias_index", lambda i: (
        f"bias_index = {int(index[i])} is none of the config's {len(hyps)} hypotheses "
        f"(0 .. {len(hyps) - 1}; -1: a bias given as a reset option)"
    ))  # fmt: skip
    _first_bad(index != index[0], source, first_line, "bias_index", lambda i: (
        f"bias_index = {int(index[i])} but row 0 has {int(index[0])}: the true lane is drawn "
        "once per episode and cannot change"
    ))  # fmt: skip
    _first_bad(bias != bias[0], source, first_line, "bias", lambda i: (
        f"bias = {float(bias[i])!r} m but row 0 has {float(bias[0])!r} m: the camera bias is "
        "drawn once per episode and cannot change"
    ))  # fmt: skip
    if index[0] >= 0 and bias[0] != hyps[index[0]]:
        raise RecordingError(
            f"bias = {float(bias[0])!r} m but bias_index {int(index[0])} is the hypothesis "
            f"{float(hyps[index[0]])!r} m of the config",
            source,
            first_line,
            "bias",
        )
    for flag in ("terminated", "truncated"):
        ends = frame[flag].to_numpy()[:-1]
        _first_bad(ends, source, first_line, flag, lambda i, flag=flag: (
            f"{flag} = true before the last row ({len(frame) - 1 - i} more row(s) follow): "
            "an episode ends at its first terminated or truncated step"
        ))  # fmt: skip
    speed = frame["speed"].to_numpy()
    top = config["vehicle"]["max_speed"]
    _first_bad((speed < 0) | (speed > top), source, first_line, "speed", lambda i: (
        f"speed = {float(speed[i])!r} m/s is outside [0, {top:g}] m/s (the env keeps the speed "
        "between 0 and the config's vehicle.max_speed)"
    ))  # fmt: skip
    y = frame["lateral_offset"].to_numpy()
    reach = lateral_limit(config)
    _first_bad(np.abs(y) > reach, source, first_line, "lateral_offset", lambda i: (
        f"lateral_offset = {float(y[i])!r} m is farther from the lane centre than the "
        f"{reach:g} m this config's env can record (a reset at most 30 m or past the road "
        "edge, then one env step before it terminates)"
    ))  # fmt: skip


_SIDECAR = schema(
    {
        "schema_version": version(SCHEMA_VERSION, "Version of the recording format."),
        "format": Field("choice", ABSENT, choices=("hasa_env recording",)),
        "csv": Field("string", ABSENT, "Name of the CSV file.", optional=True),
        "env_id": Field("string", ABSENT, "Gymnasium id (null: unknown).", optional=True),
        "seed": Field(
            "integer", ABSENT, "Seed passed to env.reset (null: not replayable).", low=0,
            optional=True,
        ),
        "seed_source": Field(
            "choice", ABSENT, "Who chose the seed.", choices=("reset", "wrapper", "given"),
            optional=True,
        ),
        "seed_sequence_entropy": Field(
            "integer", ABSENT, "Root of the wrapper's seed generator.", low=0, optional=True
        ),
        "reset_options": Field(
            "mapping", ABSENT, "The options passed to reset.", each=ANY_JSON, optional=True
        ),
        "config": Field("mapping", doc="The env's full configuration.", each=ANY_JSON),
        "versions": Field("mapping", ABSENT, "Package versions.", each=Field("string")),
        "columns": Field("strings", doc="The CSV columns in order."),
        "units": Field("mapping", ABSENT, "Unit of each column.", each=Field("string")),
        "created": Field("string", ABSENT, "UTC time (ISO 8601) of the start.", optional=True),
        "finished": Field("string", ABSENT, "UTC time (ISO 8601) of the end.", optional=True),
        "complete": Field("bool", doc="False until the recording is finalized."),
        "steps": Field("integer", ABSENT, "Rows after row 0.", low=0, optional=True),
        "end_reason": Field(
            "choice", ABSENT, "Why the episode ended.", choices=END_REASONS, optional=True
        ),
        "metadata": Field("mapping", ABSENT, "Free-form information.", each=ANY_JSON),
    }
)  # fmt: skip
"""Every field of a sidecar (``recordings/README.md``); a field that is left out stays out."""


def validate_sidecar(meta: Any, source: Path) -> dict[str, Any]:
    """The validated sidecar: every field's type, a valid config (made full), the columns."""

    def fail(path: str, message: str) -> RecordingError:
        return RecordingError(message, source, column=path or None)

    checked: dict[str, Any] = validate(
        meta,
        _SIDECAR,
        describe=lambda path: f"sidecar field '{path}'" if path else "the sidecar",
        error=fail,
    )
    try:
        checked["config"] = make_config(checked["config"])
    except ConfigError as exc:
        raise RecordingError(f"invalid config: {exc}", source, column="config") from None
    if checked["columns"] != list(RECORDING_COLUMNS):
        raise RecordingError(
            f"sidecar field 'columns' = {show(checked['columns'])} differs from the schema's columns "
            f"{list(RECORDING_COLUMNS)!r}",
            source,
            column="columns",
        )
    return checked


def read_sidecar(path: Path) -> dict[str, Any]:
    """The validated sidecar read from ``path`` (:func:`validate_sidecar`); a missing, unreadable
    or invalid file raises :class:`RecordingError`."""
    try:
        text = read_regular_file(path, "the sidecar")
    except FileNotFoundError:
        raise RecordingError("missing sidecar (the JSON file next to the CSV)", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"unreadable sidecar: {exc}", path) from None
    try:
        meta = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordingError(
            f"sidecar is not valid JSON: {exc.msg} (column {exc.colno})", path, exc.lineno
        ) from None
    except (ValueError, RecursionError) as exc:  # an integer of > 4300 digits, deep nesting
        raise RecordingError(f"sidecar cannot be read as JSON: {exc}", path) from None
    return validate_sidecar(meta, path)


def recording_paths(path: str | os.PathLike[str]) -> tuple[Path, Path]:
    """The (CSV, sidecar) paths of a recording given either file or the name without suffix."""
    p = Path(path)
    if p.suffix == ".json":
        return p.with_suffix(".csv"), p
    if p.suffix != ".csv":
        p = p.with_name(p.name + ".csv")
    return p, p.with_suffix(".json")
