"""The recording format: one CSV per episode plus a JSON sidecar, and its tools.

A recording is a pair of files in one directory:

- ``run_000.csv``: one row per env step in the column order of
  :data:`hasa_env.core.RECORDING_COLUMNS` (units in :data:`COLUMN_UNITS`).
  Row 0 is the reset state; the ``steering`` and ``acceleration`` of row k
  are the physical action applied over the step that ended at row k (row 0:
  the initial steering and 0). Floats are written with ``repr`` so they read
  back bit-exactly; ``bias_index`` and ``step`` are integers; ``terminated``
  and ``truncated`` are ``true`` / ``false``.
- ``run_000.json``: the sidecar (schema version, env id, full config, seed,
  reset options, versions, columns and units, times, completeness, free-form
  ``metadata``). See ``recordings/README.md`` for every field.

Write recordings with :class:`RecordingWrapper` (live env) or
:func:`save_recording` (a DataFrame, e.g. from a synthetic driver); read them
with :func:`load_recording` / :func:`load_recordings`, which validate the
files and name the file, line and column of every problem; re-simulate them
with :func:`replay` and compare with :func:`compare_recordings`.

Crash safety: :class:`RecordingWrapper` writes each row with a single
``write`` and flushes it to the operating system at once, so a crashing
process loses at most the step being written (pass ``fsync=True`` to also
survive an operating-system crash or power loss, at a cost per step). The
sidecar is replaced atomically (temporary file + ``os.replace``); it says
``"complete": false`` until the episode is finalized, and such an incomplete
(crashed) recording still loads, without its last line if that line was
being written when the process died (it has no final newline).
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import platform
import re
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _dist_version
from pathlib import Path
from typing import Any, TextIO

import gymnasium as gym
import numpy as np
import pandas as pd

from hasa_env.config import ConfigError, deep_merge, make_config
from hasa_env.core import RECORDING_COLUMNS, RESET_OPTIONS, recording_row
from hasa_env.lane_keeping import LaneKeepingEnv

__all__ = [
    "SCHEMA_VERSION",
    "COLUMN_UNITS",
    "RecordingError",
    "RecordingWarning",
    "Recording",
    "RecordingList",
    "RecordingWrapper",
    "save_recording",
    "load_recording",
    "load_recordings",
    "replay_actions",
    "replay",
    "compare_recordings",
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
    "sensor_speed": "m/s",
    "sensor_camera_lateral": "m",
    "sensor_camera_heading": "rad",
    "sensor_imu_longitudinal": "m/s^2",
    "sensor_imu_lateral": "m/s^2",
    "sensor_steering": "rad",
    "reward": "1",
    "terminated": "bool",
    "truncated": "bool",
}
"""Unit of every recording column ("1": dimensionless count or index)."""

_INT_COLUMNS = frozenset({"step", "bias_index"})
_BOOL_COLUMNS = frozenset({"terminated", "truncated"})
_INT_RE = re.compile(r"[+-]?[0-9]+")
_SIDECAR_KEYS = (
    "config",
    "seed",
    "env_id",
    "reset_options",
    "metadata",
    "complete",
    "end_reason",
    "created",
)
_END_REASONS = ("terminated", "truncated", "stopped")


# --------------------------------------------------------------------- errors
class RecordingError(ValueError):
    """A corrupt or invalid recording (or DataFrame to be saved as one).

    The message names the file, and where known the line (1 = the CSV header)
    and the column; they are also available as :attr:`path`, :attr:`line` and
    :attr:`column`.
    """

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
        where = []
        if path is not None:
            where.append(str(path))
        if line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column {column!r}")
        super().__init__(f"{', '.join(where)}: {message}" if where else message)


class RecordingWarning(UserWarning):
    """Something about a recording worth knowing that does not stop it loading."""


# ------------------------------------------------------------------ container
@dataclass
class Recording:
    """One loaded recording.

    Attributes:
        data: one row per env step, columns :data:`hasa_env.core.RECORDING_COLUMNS`
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


class RecordingList(list):
    """The recordings that loaded, plus an ``errors`` list of the files that did not.

    A plain ``list`` of :class:`Recording`; ``errors`` holds one
    :class:`RecordingError` per corrupt file (its ``path`` names the file).
    """

    def __init__(self, recordings: Iterable[Recording] = (), errors: Iterable[RecordingError] = ()):
        super().__init__(recordings)
        self.errors: list[RecordingError] = list(errors)


# ------------------------------------------------------------------- helpers
def _versions() -> dict[str, str]:
    def dist(name: str) -> str:
        try:
            return _dist_version(name)
        except PackageNotFoundError:  # pragma: no cover - source tree without install
            return "unknown"

    return {
        "hasa_env": dist("hasa-env"),
        "gymnasium": gym.__version__,
        "numpy": np.__version__,
        "pandas": pd.__version__,
        "python": platform.python_version(),
    }


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"{type(value).__name__} {value!r} is not JSON serializable")


def _to_json(obj: Any) -> str:
    return json.dumps(obj, indent=2, allow_nan=False, default=_json_default) + "\n"


def _write_atomic(path: Path, text: str, fsync: bool = True) -> None:
    """Write ``text`` to ``path`` via a temporary file and ``os.replace``."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8", newline="\n") as f:
        f.write(text)
        f.flush()
        if fsync:
            os.fsync(f.fileno())
    os.replace(tmp, path)


def _format_value(column: str, value: Any) -> str:
    """One CSV field; raises ValueError/TypeError with a reason on a bad value."""
    if column in _BOOL_COLUMNS:
        if isinstance(value, bool | np.bool_) or (
            isinstance(value, int | np.integer | float | np.floating) and value in (0, 1)
        ):
            return "true" if value else "false"
        raise ValueError(f"expected a bool, got {value!r}")
    if column in _INT_COLUMNS:
        if isinstance(value, bool | np.bool_):
            raise ValueError(f"expected an integer, got {value!r}")
        if isinstance(value, float | np.floating):
            if not (math.isfinite(value) and float(value).is_integer()):
                raise ValueError(f"expected an integer, got {value!r}")
        return str(int(value))
    if isinstance(value, bool | np.bool_):
        raise ValueError(f"expected a number, got {value!r}")
    return repr(float(value))


def _format_row(values: Sequence[Any]) -> str:
    return (
        ",".join(_format_value(c, v) for c, v in zip(RECORDING_COLUMNS, values, strict=True)) + "\n"
    )


_HEADER = ",".join(RECORDING_COLUMNS) + "\n"


def _base_sidecar(csv_name: str) -> dict[str, Any]:
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
        "created": _now(),
        "finished": None,
        "complete": False,
        "steps": None,
        "end_reason": None,
        "metadata": {},
    }


def _check_json_able(name: str, value: Any) -> Any:
    """Round-trip ``value`` through JSON (so the sidecar holds exactly what was given)."""
    try:
        return json.loads(_to_json(value))
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"{name} must be JSON-serializable (finite numbers, str, lists, dicts): {exc}"
        ) from None


def _check_seed(seed: Any, what: str) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"{what} must be a non-negative integer or None, got {seed!r}")
    return int(seed)


# -------------------------------------------------------------------- wrapper
class RecordingWrapper(gym.Wrapper):
    """Record every step of a single :class:`hasa_env.LaneKeepingEnv` to the recording format.

    Each episode (``reset`` to episode end) becomes ``<prefix>_NNN.csv`` plus
    the sidecar ``<prefix>_NNN.json`` in ``directory``; NNN counts up from the
    first number not yet used there (existing recordings are never
    overwritten). Row 0 is the reset state, then one row per ``step``; every
    row is flushed as it is written. The sidecar is written when the episode
    starts (``"complete": false``) and rewritten when it is finalized: at the
    episode end (``terminated`` / ``truncated``), at :meth:`close`, or at the
    next :meth:`reset` (``end_reason = "stopped"``). Steps taken after the
    episode ended, without a reset, are passed through but not recorded.

    Seeds: every recorded episode has an explicit seed, stored in its sidecar.
    ``reset(seed=s)`` uses ``s``. ``reset(seed=None)`` draws the episode seed
    (an integer in [0, 2**53)) from the wrapper's own generator, which is
    seeded with the constructor's ``seed``, else with the first seed passed
    to ``reset``, else with fresh OS entropy (recorded in the sidecar as
    ``seed_sequence_entropy``). So ``reset(seed=42)`` followed by plain
    ``reset()`` calls gives a reproducible sequence of episodes. Note that,
    unlike a bare gymnasium env, the env is therefore re-seeded at every
    episode.

    If ``env.step`` raises (e.g. a NaN action), nothing is written for that
    step and the exception propagates; the episode stays open. An exception
    while writing leaves every row written before it on disk.

    Args:
        env: a ``LaneKeepingEnv``, possibly wrapped (e.g. by ``gym.make``).
            The recorded reward and flags are the ones ``env`` returns.
        directory: where to write the files (created if needed).
        prefix: file-name prefix (letters, digits, ``_``, ``-``, ``.``).
        seed: root seed of the wrapper's episode-seed generator.
        metadata: free-form JSON-serializable dict stored in every sidecar
            under ``metadata`` (participant id, driver name, ``"synthetic"``...).
        env_id: id stored in the sidecar; default ``env.spec.id`` if known.
        fsync: also ``os.fsync`` every row (survives power loss; slower).
    """

    def __init__(
        self,
        env: gym.Env,
        directory: str | os.PathLike[str],
        *,
        prefix: str = "run",
        seed: int | None = None,
        metadata: Mapping[str, Any] | None = None,
        env_id: str | None = None,
        fsync: bool = False,
    ) -> None:
        super().__init__(env)
        if not isinstance(env.unwrapped, LaneKeepingEnv):
            raise TypeError(
                "RecordingWrapper records a single hasa_env.LaneKeepingEnv; got "
                f"{type(env.unwrapped).__name__}"
            )
        if not isinstance(prefix, str) or not re.fullmatch(r"[A-Za-z0-9_.\-]+", prefix):
            raise ValueError(
                "prefix must be a non-empty file-name part of letters, digits, '_', '-', '.'; "
                f"got {prefix!r}"
            )
        if metadata is not None and not isinstance(metadata, Mapping):
            raise TypeError(f"metadata must be a dict, got {type(metadata).__name__}")
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.prefix = prefix
        self.recording_metadata: dict[str, Any] = _check_json_able("metadata", dict(metadata or {}))
        spec_id = env.spec.id if env.spec is not None else None
        self.env_id = env_id if env_id is not None else spec_id
        self.fsync = bool(fsync)
        self._seed_entropy: int | None = None
        self._seed_rng: np.random.Generator | None = None
        if seed is not None:
            self._init_seed_sequence(_check_seed(seed, "seed"))
        self._file: TextIO | None = None
        self._sidecar: dict[str, Any] | None = None
        self._sidecar_path: Path | None = None
        self._rows = 0
        self._warned_after_end = False
        self.paths: list[Path] = []
        """CSV files written by this wrapper, in order."""
        self.episode_seed: int | None = None
        """Seed of the current (or last) episode."""

    # ------------------------------------------------------------- public
    @property
    def path(self) -> Path | None:
        """The CSV file of the current (or last) episode."""
        return self.paths[-1] if self.paths else None

    @property
    def recording(self) -> bool:
        """True while an episode is being recorded."""
        return self._file is not None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        self._finalize("stopped")
        if seed is not None:
            episode_seed = _check_seed(seed, "reset(seed=...)")
            source = "reset"
            if self._seed_rng is None:
                self._init_seed_sequence(episode_seed)
        else:
            if self._seed_rng is None:
                self._init_seed_sequence(None)
            assert self._seed_rng is not None
            episode_seed = int(self._seed_rng.integers(0, 2**53))
            source = "wrapper"
        reset_options = (
            None if options is None else _check_json_able("reset options", dict(options))
        )
        obs, info = self.env.reset(seed=episode_seed, options=options)
        self.episode_seed = episode_seed
        self._start_episode(episode_seed, source, reset_options, info)
        return obs, info

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self._file is None:
            if self.paths and not self._warned_after_end:
                gym.logger.warn(
                    "RecordingWrapper: step() after the episode ended is not recorded; call reset()"
                )
                self._warned_after_end = True
            return obs, reward, terminated, truncated, info
        self._write(recording_row(self._rows, info, reward, terminated, truncated))
        if terminated or truncated:
            self._finalize("terminated" if terminated else "truncated")
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        """Finalize the current recording (if any) and close the env."""
        try:
            self._finalize("stopped")
        finally:
            super().close()

    # ------------------------------------------------------------ private
    def _init_seed_sequence(self, entropy: int | None) -> None:
        seq = np.random.SeedSequence(entropy)
        self._seed_entropy = int(seq.entropy)
        self._seed_rng = np.random.default_rng(seq)

    def _next_index(self) -> int:
        pattern = re.compile(re.escape(self.prefix) + r"_([0-9]+)\.(csv|json)")
        used = [
            int(m.group(1)) for p in self.directory.iterdir() if (m := pattern.fullmatch(p.name))
        ]
        return max(used) + 1 if used else 0

    def _start_episode(
        self, seed: int, source: str, reset_options: dict[str, Any] | None, info: Mapping[str, Any]
    ) -> None:
        index = self._next_index()
        while True:
            csv_path = self.directory / f"{self.prefix}_{index:03d}.csv"
            try:
                f = open(csv_path, "x", encoding="utf-8", newline="\n")  # noqa: SIM115
            except FileExistsError:
                index += 1
                continue
            break
        self._file = f
        self._rows = 0
        self._warned_after_end = False
        self.paths.append(csv_path)
        self._sidecar_path = csv_path.with_suffix(".json")
        sidecar = _base_sidecar(csv_path.name)
        sidecar.update(
            env_id=self.env_id,
            seed=seed,
            seed_source=source,
            seed_sequence_entropy=self._seed_entropy,
            reset_options=reset_options,
            config=self.env.unwrapped.config,
            metadata=self.recording_metadata,
        )
        self._sidecar = sidecar
        _write_atomic(self._sidecar_path, _to_json(sidecar))
        f.write(_HEADER)
        self._write(recording_row(0, info, 0.0, False, False))

    def _write(self, row: Sequence[Any]) -> None:
        assert self._file is not None
        try:
            text = _format_row(row)
        except (TypeError, ValueError) as exc:  # pragma: no cover - env info is always valid
            raise RecordingError(f"row {self._rows}: {exc}", self.path) from exc
        self._file.write(text)
        self._file.flush()
        if self.fsync:
            os.fsync(self._file.fileno())
        self._rows += 1

    def _finalize(self, reason: str) -> None:
        f, self._file = self._file, None
        if f is None:
            return
        try:
            f.close()
        finally:
            assert self._sidecar is not None and self._sidecar_path is not None
            self._sidecar.update(
                complete=True, steps=self._rows - 1, end_reason=reason, finished=_now()
            )
            _write_atomic(self._sidecar_path, _to_json(self._sidecar))


# ------------------------------------------------------------------- parsing
def _parse_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"non-finite value {text!r} (NaN and infinities are not allowed)")
    if "_" in text or text != text.strip():
        raise ValueError(f"not a plain number: {text!r}")
    return value


def _parse_int(text: str) -> int:
    if not _INT_RE.fullmatch(text):
        raise ValueError(f"not an integer: {text!r}")
    return int(text)


def _parse_bool(text: str) -> bool:
    low = text.lower()
    if low == "true":
        return True
    if low == "false":
        return False
    raise ValueError(f"not a bool: {text!r} (expected true or false)")


def _parser(column: str):  # noqa: ANN202
    if column in _INT_COLUMNS:
        return _parse_int
    if column in _BOOL_COLUMNS:
        return _parse_bool
    return _parse_float


def _check_header(names: list[str], source: Path | str) -> None:
    seen: set[str] = set()
    dup = [n for n in names if n in seen or seen.add(n)]
    unknown = [n for n in names if n not in RECORDING_COLUMNS]
    missing = [c for c in RECORDING_COLUMNS if c not in seen]
    problems = []
    if dup:
        problems.append("duplicated column(s) " + ", ".join(repr(n) for n in dict.fromkeys(dup)))
    if unknown:
        problems.append("unknown column(s) " + ", ".join(repr(n) for n in unknown))
    if missing:
        problems.append("missing column(s) " + ", ".join(repr(n) for n in missing))
    if problems:
        column = (dup or unknown or missing)[0]
        raise RecordingError(
            "bad header: " + "; ".join(problems) + f" (expected: {','.join(RECORDING_COLUMNS)})",
            source,
            1,
            column,
        )


def _parse_lines(lines: list[str], source: Path | str) -> dict[str, list[Any]]:
    """Parse header + data lines (without newlines) into columns; line 1 is the header."""
    if not lines:
        raise RecordingError("empty file: no header", source, 1)
    names = lines[0].split(",")
    _check_header(names, source)
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


def _frame(columns: Mapping[str, Sequence[Any]]) -> pd.DataFrame:
    data = {}
    for c in RECORDING_COLUMNS:
        if c in _INT_COLUMNS:
            data[c] = np.asarray(columns[c], dtype=np.int64)
        elif c in _BOOL_COLUMNS:
            data[c] = np.asarray(columns[c], dtype=bool)
        else:
            data[c] = np.asarray(columns[c], dtype=np.float64)
    return pd.DataFrame(data)


def _check_table(
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
            f"time = {time[i]!r} s does not match step {i}: expected {expected[i]!r} s "
            f"(step x {dt_step!r} s per env step, from the config's sim_frequency and "
            "action_repeat)",
            source,
            first_line + i,
            "time",
        )


def _validate_meta(meta: Any, source: Path) -> dict[str, Any]:
    if not isinstance(meta, dict):
        raise RecordingError(f"sidecar must hold a JSON object, got {type(meta).__name__}", source)
    if "schema_version" not in meta:
        raise RecordingError("sidecar has no 'schema_version'", source, column="schema_version")
    version = meta["schema_version"]
    if version != SCHEMA_VERSION or isinstance(version, bool):
        raise RecordingError(
            f"unknown schema_version {version!r}: this hasa_env reads version {SCHEMA_VERSION}",
            source,
            column="schema_version",
        )
    for key in ("config", "complete", "columns"):
        if key not in meta:
            raise RecordingError(f"sidecar has no {key!r}", source, column=key)
    if not isinstance(meta["complete"], bool):
        raise RecordingError(
            f"'complete' must be true or false, got {meta['complete']!r}", source, column="complete"
        )
    if not isinstance(meta["config"], dict):
        raise RecordingError("'config' must be a JSON object", source, column="config")
    try:
        meta["config"] = make_config(meta["config"])
    except ConfigError as exc:
        raise RecordingError(f"invalid config: {exc}", source, column="config") from None
    seed = meta.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise RecordingError(
            f"'seed' must be a non-negative integer or null, got {seed!r}", source, column="seed"
        )
    if meta["columns"] != list(RECORDING_COLUMNS):
        raise RecordingError(
            f"'columns' = {meta['columns']!r} differs from the schema's columns "
            f"{list(RECORDING_COLUMNS)!r}",
            source,
            column="columns",
        )
    return meta


def _read_sidecar(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
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
    return _validate_meta(meta, path)


def _paths(path: str | os.PathLike[str]) -> tuple[Path, Path]:
    p = Path(path)
    if p.suffix == ".json":
        return p.with_suffix(".csv"), p
    if p.suffix != ".csv":
        p = p.with_name(p.name + ".csv")
    return p, p.with_suffix(".json")


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


# -------------------------------------------------------------------- saving
def save_recording(
    frame: pd.DataFrame, path: str | os.PathLike[str], meta: Mapping[str, Any] | None = None
) -> Path:
    """Save a DataFrame with the recording columns as a recording (CSV + sidecar).

    Args:
        frame: one row per env step, row 0 the reset state, columns
            :data:`hasa_env.core.RECORDING_COLUMNS` (any order; extra columns
            are an error). Integer columns must hold whole numbers.
        path: the CSV path (``.csv`` is appended if missing); the sidecar goes
            next to it with ``.json``. Existing files are replaced.
        meta: sidecar fields: ``config`` (the env config; deep-merged onto the
            defaults, default: the default config), ``seed`` (int or None: a
            recording without a seed cannot be replayed), ``env_id``,
            ``reset_options``, ``metadata`` (free-form dict), ``complete``
            (default True), ``end_reason`` (default from the last row's flags:
            ``"terminated"``, ``"truncated"`` or ``"stopped"``), ``created``.

    Returns:
        The CSV path.

    Raises:
        RecordingError: a bad column or value (naming row and column), or a
            ``time`` column inconsistent with the config.
        ValueError: an unknown ``meta`` key or a non-JSON-serializable value.
    """
    meta = dict(meta or {})
    unknown = [k for k in meta if k not in _SIDECAR_KEYS]
    if unknown:
        raise ValueError(
            f"unknown meta key {unknown[0]!r}; allowed: {', '.join(_SIDECAR_KEYS)} "
            "(put free-form information in meta['metadata'])"
        )
    csv_path, json_path = _paths(path)
    source = f"DataFrame for {csv_path}"
    if not isinstance(frame, pd.DataFrame):
        raise TypeError(f"frame must be a pandas DataFrame, got {type(frame).__name__}")
    _check_header([str(c) for c in frame.columns], source)
    try:
        config = make_config(meta.get("config"))
    except ConfigError as exc:
        raise ValueError(f"meta['config'] is invalid: {exc}") from None
    seed = meta.get("seed")
    if seed is not None:
        seed = _check_seed(seed, "meta['seed']")
    ordered = frame[list(RECORDING_COLUMNS)]
    lines = [_HEADER]
    cols = [ordered[c].to_numpy() for c in RECORDING_COLUMNS]
    for i in range(len(ordered)):
        parts = []
        for c, col in zip(RECORDING_COLUMNS, cols, strict=True):
            value = col[i]
            try:
                text = _format_value(c, value)
                if c not in _INT_COLUMNS and c not in _BOOL_COLUMNS:
                    _parse_float(text)
            except (TypeError, ValueError) as exc:
                raise RecordingError(f"row {i}: {exc}", source, column=c) from None
            parts.append(text)
        lines.append(",".join(parts) + "\n")
    if len(lines) < 2:
        raise RecordingError("no rows (row 0, the reset state, is required)", source)
    parsed = _frame(_parse_lines([ln[:-1] for ln in lines], source))
    _check_table(parsed, config, source, 2)
    last = parsed.iloc[-1]
    default_reason = (
        "terminated" if last["terminated"] else "truncated" if last["truncated"] else "stopped"
    )
    complete = meta.get("complete", True)
    if not isinstance(complete, bool):
        raise ValueError(f"meta['complete'] must be a bool, got {complete!r}")
    sidecar = _base_sidecar(csv_path.name)
    sidecar.update(
        env_id=meta.get("env_id"),
        seed=seed,
        seed_source=None if seed is None else "given",
        reset_options=_check_json_able("meta['reset_options']", meta.get("reset_options")),
        config=config,
        metadata=_check_json_able("meta['metadata']", dict(meta.get("metadata") or {})),
        complete=complete,
        steps=len(parsed) - 1 if complete else None,
        end_reason=meta.get("end_reason", default_reason) if complete else None,
        finished=_now() if complete else None,
    )
    if "created" in meta:
        sidecar["created"] = str(meta["created"])
    if sidecar["end_reason"] is not None and sidecar["end_reason"] not in _END_REASONS:
        raise ValueError(
            f"meta['end_reason'] must be one of {_END_REASONS}, got {sidecar['end_reason']!r}"
        )
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    _write_atomic(csv_path, "".join(lines))
    _write_atomic(json_path, _to_json(sidecar))
    return csv_path


# -------------------------------------------------------------------- replay
def _data(recording: Recording | pd.DataFrame) -> pd.DataFrame:
    if isinstance(recording, Recording):
        return recording.data
    if isinstance(recording, pd.DataFrame):
        return recording
    raise TypeError(f"expected a Recording or a DataFrame, got {type(recording).__name__}")


def replay_actions(recording: Recording | pd.DataFrame) -> np.ndarray:
    """The physical actions of rows 1..n as an (n, 2) float64 array.

    Columns: steering (road-wheel angle, rad) and acceleration (m/s^2); row i
    of the result is the action that led from recording row i to row i + 1.
    """
    data = _data(recording)
    return data[["steering", "acceleration"]].to_numpy(dtype=np.float64)[1:].copy()


def _replay_options(
    row0: pd.Series, config: Mapping[str, Any], hypotheses: Sequence[float]
) -> dict[str, Any]:
    options: dict[str, Any] = {}
    index = int(row0["bias_index"])
    if 0 <= index < len(hypotheses):
        options["bias_index"] = index
    else:
        options["bias"] = float(row0["bias"])
    limits = {
        "lateral_offset": (-10.0, 10.0),
        "heading": (-1.0, 1.0),
        "speed": (0.0, config["vehicle"]["max_speed"]),
        "steering": (-config["action"]["max_steering"], config["action"]["max_steering"]),
    }
    for key, (lo, hi) in limits.items():
        value = float(row0[key])
        if lo <= value <= hi:  # outside a reset option's range the seed reproduces it
            options[key] = value
    assert set(options) <= set(RESET_OPTIONS)
    return options


def replay(recording: Recording) -> pd.DataFrame:
    """Re-simulate a recording and return the replayed frame (same columns and dtypes).

    Builds a :class:`hasa_env.LaneKeepingEnv` from the sidecar's config with
    ``action.type = "physical"``, resets it with the recorded seed and, as
    reset options, row 0's bias (``bias_index``) and initial state
    (lateral_offset, heading, speed, steering), then steps through
    :func:`replay_actions`. Row 0 is the reset state, as in the recording.
    With the same code and versions the result equals the recording bit for
    bit, sensor noise included (the noise comes from the seeded generator);
    :func:`compare_recordings` finds the first difference. The replay stops
    early if its episode ends before the recording's last row.

    Raises:
        ValueError: the recording has no seed.
    """
    if not isinstance(recording, Recording):
        raise TypeError(
            f"replay needs a Recording (data + sidecar), got {type(recording).__name__}"
        )
    seed = recording.seed
    if seed is None:
        raise ValueError(
            f"recording {recording.path} has no seed in its sidecar; it cannot be replayed "
            "(the sensor noise and any random draws depend on it)"
        )
    config = deep_merge(recording.config, {"action": {"type": "physical"}})
    env = LaneKeepingEnv(config=config)
    try:
        data = recording.data
        options = _replay_options(data.iloc[0], env.config, env.setup.hypotheses)
        _, info = env.reset(seed=int(seed), options=options)
        rows = [recording_row(0, info, 0.0, False, False)]
        for k, action in enumerate(replay_actions(data), start=1):
            _, reward, terminated, truncated, info = env.step(action)
            rows.append(recording_row(k, info, reward, terminated, truncated))
            if terminated or truncated:
                break
    finally:
        env.close()
    return _frame(dict(zip(RECORDING_COLUMNS, zip(*rows, strict=True), strict=True)))


def compare_recordings(
    a: Recording | pd.DataFrame,
    b: Recording | pd.DataFrame,
    *,
    columns: Sequence[str] | None = None,
    atol: float = 0.0,
) -> tuple[int, str] | None:
    """The first (row, column) where two recordings differ, or None if they agree.

    Rows are scanned in order and, within a row, columns in
    :data:`hasa_env.core.RECORDING_COLUMNS` order (or ``columns``). With
    ``atol = 0`` floats must be bit-identical (so ``0.0`` and ``-0.0``
    differ); otherwise ``|a - b| <= atol`` (in the column's unit). If one
    recording is a prefix of the other, the answer is
    ``(length of the shorter, "step")``: the first row that only one has.
    """
    da, db = _data(a), _data(b)
    cols = list(RECORDING_COLUMNS if columns is None else columns)
    for c in cols:
        for d, name in ((da, "first"), (db, "second")):
            if c not in d.columns:
                raise KeyError(f"column {c!r} missing from the {name} recording")
    n = min(len(da), len(db))
    best: tuple[int, str] | None = None
    for c in cols:
        x = da[c].to_numpy()[:n]
        y = db[c].to_numpy()[:n]
        if x.dtype.kind == "f" or y.dtype.kind == "f":
            x = x.astype(np.float64)
            y = y.astype(np.float64)
            if atol == 0.0:
                diff = x.view(np.int64) != y.view(np.int64)
            else:
                diff = ~(np.abs(x - y) <= atol) & ~(np.isnan(x) & np.isnan(y))
        else:
            diff = x != y
        idx = np.flatnonzero(diff)
        if idx.size and (best is None or int(idx[0]) < best[0]):
            best = (int(idx[0]), c)
    if best is not None:
        return best
    if len(da) != len(db):
        return (n, "step")
    return None
