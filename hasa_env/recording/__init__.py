"""Recordings: one CSV per episode plus a JSON sidecar, and their tools.

Write recordings with :class:`RecordingWrapper` (live env) or
:func:`save_recording` (a DataFrame, e.g. from a synthetic driver); read them
with :func:`load_recording` / :func:`load_recordings`, which validate the
files and name the file, line and column of every problem; re-simulate them
with :func:`replay` and compare with :func:`compare_recordings`. The format
is :mod:`hasa_env.recording.format` (and ``recordings/README.md``); raw wheel
inputs next to a recording: :mod:`hasa_env.recording.raw_inputs`; Minari and
Parquet: :mod:`hasa_env.recording.export`, :mod:`hasa_env.recording.parquet`;
summaries: :mod:`hasa_env.recording.summary`.
"""

from hasa_env.recording.format import (
    COLUMN_UNITS,
    SCHEMA_VERSION,
    Recording,
    RecordingError,
    RecordingList,
    RecordingWarning,
)
from hasa_env.recording.reader import (
    load_notes,
    load_paths,
    load_recording,
    load_recordings,
    warn_load_notes,
)
from hasa_env.recording.replay import (
    ReplayCheck,
    check_replay,
    compare_recordings,
    replay,
    replay_actions,
)
from hasa_env.recording.writer import RecordingWrapper, save_recording

__all__ = [
    "COLUMN_UNITS",
    "SCHEMA_VERSION",
    "Recording",
    "RecordingError",
    "RecordingList",
    "RecordingWarning",
    "RecordingWrapper",
    "ReplayCheck",
    "check_replay",
    "compare_recordings",
    "load_notes",
    "load_paths",
    "load_recording",
    "load_recordings",
    "replay",
    "replay_actions",
    "save_recording",
    "warn_load_notes",
]
