"""The raw-input side file of a recording: what the wheel and pedals reported, per step.

Next to each recording made by ``hasa-drive`` (``run_NNN.csv``),
``run_NNN.inputs.tsv`` holds the raw input per env step: the raw axis
values of the steering wheel and pedals as pygame reported them, the mapped
angles and pedal travels, the source (keyboard or joystick) and the
wall-clock time (:data:`RAW_INPUT_UNITS`). Row k (k >= 1) is the input
applied over the step that ended at recording row k.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pandas as pd

from hasa_env.devices.sources import RAW_INPUT_COLUMNS, InputReading

__all__ = [
    "RAW_INPUTS_SUFFIX",
    "RAW_INPUT_HEADER",
    "RAW_INPUT_UNITS",
    "RawInputWriter",
    "load_raw_inputs",
    "raw_inputs_path",
]

RAW_INPUTS_SUFFIX = ".inputs.tsv"
"""File-name suffix of the raw-input side file (replaces ``.csv``)."""


def raw_inputs_path(recording_csv: str | os.PathLike[str]) -> Path:
    """The raw-input side file of a recording: ``run_000.csv`` -> ``run_000.inputs.tsv``."""
    p = Path(recording_csv)
    return p.with_name(p.stem + RAW_INPUTS_SUFFIX)


RAW_INPUT_HEADER = ("step", "time", "wall_time", *RAW_INPUT_COLUMNS)
RAW_INPUT_UNITS = {
    "step": "1",
    "time": "s (simulation)",
    "wall_time": "s since the run started (wall clock, includes pauses)",
    "source": "keyboard | joystick:<device name>",
    "raw_steering": "raw axis value as pygame reports it (about -1..1); NaN for the keyboard",
    "raw_throttle": "raw axis value; NaN for the keyboard",
    "raw_brake": "raw axis value; NaN for the keyboard",
    "steering_wheel_angle": "rad (left positive)",
    "road_wheel_angle": "rad (left positive; the commanded steering)",
    "throttle": "pedal travel 0..1",
    "brake": "pedal travel 0..1",
    "acceleration": "m/s^2 (commanded)",
}


class RawInputWriter:
    """Writes the raw-input side file, one tab-separated line per env step, flushed at once.

    Row k (k >= 1) is the input applied over the step that ended at recording row k.
    """

    def __init__(self, path: str | os.PathLike[str], fsync: bool = False) -> None:
        self.path = Path(path)
        if self.path.exists():
            # left over from a recording whose CSV and sidecar were removed: keep it, aside
            self.path.rename(self.path.with_name(f"{self.path.name}.orphaned-{time.time_ns()}"))
        self._file = open(self.path, "x", encoding="utf-8", newline="\n")  # noqa: SIM115
        self.fsync = fsync
        self._file.write("\t".join(RAW_INPUT_HEADER) + "\n")
        self._file.flush()

    def write(self, step: int, sim_time: float, wall_time: float, reading: InputReading) -> None:
        fields = [str(int(step)), repr(float(sim_time)), repr(float(wall_time))]
        for name, value in zip(RAW_INPUT_COLUMNS, reading.as_row(), strict=True):
            if name == "source":
                fields.append(str(value).replace("\t", " ").replace("\n", " "))
            else:
                fields.append(repr(float(value)))
        self._file.write("\t".join(fields) + "\n")
        self._file.flush()
        if self.fsync:
            os.fsync(self._file.fileno())

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


def load_raw_inputs(path: str | os.PathLike[str]) -> pd.DataFrame:
    """Read a raw-input side file (or the one next to a recording CSV) as a pandas DataFrame."""
    p = Path(path)
    if p.suffix == ".csv":
        p = raw_inputs_path(p)
    frame = pd.read_csv(
        p, sep="\t", dtype={"source": str}, keep_default_na=False, na_values=["nan"]
    )
    missing = [c for c in RAW_INPUT_HEADER if c not in frame.columns]
    if missing:
        raise ValueError(f"{p}: not a raw-input file, missing column(s) {', '.join(missing)}")
    return frame
