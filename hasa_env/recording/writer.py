"""Writing recordings: :class:`RecordingWrapper` (a live env) and :func:`save_recording`
(a DataFrame, e.g. from a synthetic driver).

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

import contextlib
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd

from hasa_env.atomic import write_atomic
from hasa_env.envs.base import hasa_unwrapped
from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.recording.format import (
    BOOL_COLUMNS,
    CSV_HEADER,
    END_REASONS,
    INT_COLUMNS,
    SIDECAR_KEYS,
    RecordingError,
    base_sidecar,
    check_header,
    check_json_able,
    check_seed,
    check_table,
    columns_frame,
    format_row,
    format_value,
    magnitude_limit,
    parse_float,
    parse_lines,
    recording_paths,
    to_json_text,
    utc_now_text,
)
from hasa_env.sim.config import ConfigError, make_config
from hasa_env.sim.setup import RECORDING_COLUMNS, recording_row

__all__ = ["RecordingWrapper", "save_recording"]


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
    step and the exception propagates; the episode stays open. If writing a
    row fails (a full disk, an I/O error), the file is cut back to the last
    complete row, so it loads as an incomplete recording of every row written
    before, and :class:`RecordingError` is raised naming the file and the
    OS error; from then on ``step`` refuses (without stepping the env) until
    ``reset`` starts a new recording.

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
        self.recording_metadata: dict[str, Any] = check_json_able("metadata", dict(metadata or {}))
        spec_id = env.spec.id if env.spec is not None else None
        self.env_id = env_id if env_id is not None else spec_id
        self.fsync = bool(fsync)
        self._seed_entropy: int | None = None
        self._seed_rng: np.random.Generator | None = None
        if seed is not None:
            self._init_seed_sequence(check_seed(seed, "seed"))
        self._fd: int | None = None
        self._offset = 0
        self._write_error: RecordingError | None = None
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
        return self._fd is not None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        self._finalize("stopped")
        if seed is not None:
            episode_seed = check_seed(seed, "reset(seed=...)")
            source = "reset"
            if self._seed_rng is None:
                self._init_seed_sequence(episode_seed)
        else:
            if self._seed_rng is None:
                self._init_seed_sequence(None)
            assert self._seed_rng is not None
            episode_seed = int(self._seed_rng.integers(0, 2**53))
            source = "wrapper"
        reset_options = None if options is None else check_json_able("reset options", dict(options))
        obs, info = self.env.reset(seed=episode_seed, options=options)
        self.episode_seed = episode_seed
        self._start_episode(episode_seed, source, reset_options, info)
        return obs, info

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        if self._write_error is not None:
            raise RecordingError(
                f"not recording since a write failed ({self._write_error.reason}); "
                f"rows 0..{self._rows - 1} are on disk; call reset() to start a new recording",
                self.path,
            )
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self._fd is None:
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
        assert isinstance(seq.entropy, int | np.integer)  # (from an int or fresh: one int)
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
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
        while True:
            csv_path = self.directory / f"{self.prefix}_{index:03d}.csv"
            try:
                fd = os.open(csv_path, flags, 0o666)
                break
            except FileExistsError:
                index += 1
        self._fd = fd
        self._offset = 0
        self._write_error = None
        self._rows = 0
        self._warned_after_end = False
        self.paths.append(csv_path)
        self._sidecar_path = csv_path.with_suffix(".json")
        sidecar = base_sidecar(csv_path.name)
        sidecar.update(
            env_id=self.env_id,
            seed=seed,
            seed_source=source,
            seed_sequence_entropy=self._seed_entropy,
            reset_options=reset_options,
            config=hasa_unwrapped(self.env).config,
            metadata=self.recording_metadata,
        )
        self._sidecar = sidecar
        try:
            # header and row 0 in one write, then the sidecar: a process killed in between
            # leaves a CSV of at most its reset row and no sidecar, which the loader names
            # as an episode that was being started (nothing of it had been returned yet)
            self._write_text(CSV_HEADER + format_row(recording_row(0, info, 0.0, False, False)),
                             "the header and row 0")  # fmt: skip
            self._rows = 1
            write_atomic(self._sidecar_path, to_json_text(sidecar))
        except (OSError, RecordingError):
            # nothing of this episode is recorded: leave no half-made recording behind
            fd, self._fd = self._fd, None
            self._write_error = None
            if fd is not None:
                os.close(fd)
            for path in (csv_path, self._sidecar_path):
                with contextlib.suppress(OSError):
                    path.unlink()
            self.paths.pop()
            raise

    def _write(self, row: Sequence[Any]) -> None:
        try:
            text = format_row(row)
        except (TypeError, ValueError) as exc:  # pragma: no cover - env info is always valid
            raise RecordingError(f"row {self._rows}: {exc}", self.path) from exc
        self._write_text(text, f"row {self._rows}")
        self._rows += 1

    def _write_text(self, text: str, what: str) -> None:
        """Write ``text`` whole at the end of the CSV, or cut the file back and stop recording."""
        assert self._fd is not None
        data = text.encode("utf-8")
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(self._fd, view) :]
            if self.fsync:
                os.fsync(self._fd)
        except OSError as exc:
            with contextlib.suppress(OSError):  # drop a partly written row
                os.ftruncate(self._fd, self._offset)
            self._write_error = RecordingError(f"writing {what} failed: {exc}", self.path)
            fd, self._fd = self._fd, None
            with contextlib.suppress(OSError):
                os.close(fd)
            raise self._write_error from exc
        self._offset += len(data)

    def _finalize(self, reason: str) -> None:
        self._write_error = None
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            os.close(fd)
        finally:
            assert self._sidecar is not None and self._sidecar_path is not None
            self._sidecar.update(
                complete=True, steps=self._rows - 1, end_reason=reason, finished=utc_now_text()
            )
            try:
                write_atomic(self._sidecar_path, to_json_text(self._sidecar))
            except OSError as exc:  # the sidecar on disk still says "complete": false
                raise RecordingError(
                    f"finalizing the sidecar failed ({exc}); the recording stays incomplete "
                    f"with rows 0..{self._rows - 1}",
                    self._sidecar_path,
                ) from exc


# -------------------------------------------------------------------- saving
def save_recording(
    frame: pd.DataFrame, path: str | os.PathLike[str], meta: Mapping[str, Any] | None = None
) -> Path:
    """Save a DataFrame with the recording columns as a recording (CSV + sidecar).

    Args:
        frame: one row per env step, row 0 the reset state, columns
            :data:`hasa_env.sim.setup.RECORDING_COLUMNS` (any order; extra columns
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
    unknown = [k for k in meta if k not in SIDECAR_KEYS]
    if unknown:
        raise ValueError(
            f"unknown meta key {unknown[0]!r}; allowed: {', '.join(SIDECAR_KEYS)} "
            "(put free-form information in meta['metadata'])"
        )
    csv_path, json_path = recording_paths(path)
    source = f"DataFrame for {csv_path}"
    if not isinstance(frame, pd.DataFrame):
        raise TypeError(f"frame must be a pandas DataFrame, got {type(frame).__name__}")
    check_header([str(c) for c in frame.columns], source)
    try:
        config = make_config(meta.get("config"))
    except ConfigError as exc:
        raise ValueError(f"meta['config'] is invalid: {exc}") from None
    seed = meta.get("seed")
    if seed is not None:
        seed = check_seed(seed, "meta['seed']")
    ordered = frame[list(RECORDING_COLUMNS)]
    lines = [CSV_HEADER]
    cols = [ordered[c].to_numpy() for c in RECORDING_COLUMNS]
    for i in range(len(ordered)):
        parts = []
        for c, col in zip(RECORDING_COLUMNS, cols, strict=True):
            value = col[i]
            try:
                text = format_value(c, value)
                if c not in INT_COLUMNS and c not in BOOL_COLUMNS:
                    parse_float(text, magnitude_limit(c))
            except (TypeError, ValueError) as exc:
                raise RecordingError(f"row {i}: {exc}", source, column=c) from None
            parts.append(text)
        lines.append(",".join(parts) + "\n")
    if len(lines) < 2:
        raise RecordingError("no rows (row 0, the reset state, is required)", source)
    parsed = columns_frame(parse_lines([ln[:-1] for ln in lines], source))
    check_table(parsed, config, source, 2)
    last = parsed.iloc[-1]
    default_reason = (
        "terminated" if last["terminated"] else "truncated" if last["truncated"] else "stopped"
    )
    complete = meta.get("complete", True)
    if not isinstance(complete, bool):
        raise ValueError(f"meta['complete'] must be a bool, got {complete!r}")
    sidecar = base_sidecar(csv_path.name)
    sidecar.update(
        env_id=meta.get("env_id"),
        seed=seed,
        seed_source=None if seed is None else "given",
        reset_options=check_json_able("meta['reset_options']", meta.get("reset_options")),
        config=config,
        metadata=check_json_able("meta['metadata']", dict(meta.get("metadata") or {})),
        complete=complete,
        steps=len(parsed) - 1 if complete else None,
        end_reason=meta.get("end_reason", default_reason) if complete else None,
        finished=utc_now_text() if complete else None,
    )
    if "created" in meta:
        sidecar["created"] = str(meta["created"])
    if sidecar["end_reason"] is not None and sidecar["end_reason"] not in END_REASONS:
        raise ValueError(
            f"meta['end_reason'] must be one of {END_REASONS}, got {sidecar['end_reason']!r}"
        )
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(csv_path, "".join(lines))
    write_atomic(json_path, to_json_text(sidecar))
    return csv_path
