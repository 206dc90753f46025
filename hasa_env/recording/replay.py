"""Re-simulating recordings: :func:`replay` re-runs the recorded actions with the
recorded seed; :func:`compare_recordings` finds the first difference.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.recording.format import Recording, columns_frame
from hasa_env.sim.config import deep_merge
from hasa_env.sim.setup import (
    RECORDING_COLUMNS,
    RESET_HEADING_LIMIT,
    RESET_LATERAL_LIMIT,
    RESET_OPTIONS,
    recording_row,
)

__all__ = ["ReplayCheck", "check_replay", "compare_recordings", "replay", "replay_actions"]


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
        "lateral_offset": (-RESET_LATERAL_LIMIT, RESET_LATERAL_LIMIT),
        "heading": (-RESET_HEADING_LIMIT, RESET_HEADING_LIMIT),
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
    return columns_frame(dict(zip(RECORDING_COLUMNS, zip(*rows, strict=True), strict=True)))


def compare_recordings(
    a: Recording | pd.DataFrame,
    b: Recording | pd.DataFrame,
    *,
    columns: Sequence[str] | None = None,
    atol: float = 0.0,
) -> tuple[int, str] | None:
    """The first (row, column) where two recordings differ, or None if they agree.

    Rows are scanned in order and, within a row, columns in
    :data:`hasa_env.sim.setup.RECORDING_COLUMNS` order (or ``columns``). With
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


@dataclass(frozen=True)
class ReplayCheck:
    """Result of replaying one recording.

    Attributes:
        rows: rows in the recording (row 0 = the reset state).
        replayed_rows: rows the replay produced.
        divergence: None if they match, else (row, column, recorded value, replayed value).
        time: simulated time (s) of the divergent row (NaN if they match).
    """

    rows: int
    replayed_rows: int
    divergence: tuple[int, str, Any, Any] | None
    time: float = math.nan

    @property
    def matches(self) -> bool:
        return self.divergence is None

    def describe(self, atol: float = 0.0) -> str:
        if self.divergence is None:
            how = "bit for bit" if atol == 0.0 else f"within {atol:g}"
            return f"replay matches the recording {how} ({self.rows} rows)"
        row, column, a, b = self.divergence
        if column == "step" and (a is None or b is None):
            shorter = "replay" if b is None else "recording"
            return (
                f"DIVERGES: the {shorter} ends at row {row} (recording {self.rows} rows, "
                f"replay {self.replayed_rows} rows)"
            )
        return (
            f"DIVERGES at row {row} (t = {self.time:.2f} s), column {column!r}: "
            f"recorded {a!r}, replayed {b!r}"
        )


def check_replay(recording: Recording, atol: float = 0.0) -> ReplayCheck:
    """Replay ``recording`` (a :class:`hasa_env.recording.Recording`) and compare."""
    replayed = replay(recording)
    first = compare_recordings(recording, replayed, atol=atol)
    n, m = len(recording.data), len(replayed)
    if first is None:
        return ReplayCheck(n, m, None)
    row, column = first
    a = recording.data[column].iloc[row].item() if row < n else None
    b = replayed[column].iloc[row].item() if row < m else None
    t = float(recording.data["time"].iloc[row]) if row < n else math.nan
    return ReplayCheck(n, m, (row, column, a, b), t)
