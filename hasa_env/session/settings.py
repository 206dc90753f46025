"""The settings of a drive session: who drives, which track, how many runs, how long."""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hasa_env.sim.config import deep_merge, make_config
from hasa_env.validation import ANY_JSON, Field, schema, validate_fields

__all__ = ["DriveSettings"]

_PARTICIPANT_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]*")

_SCHEMA = schema(
    {
        "participant": Field(
            "string", doc="Participant id; recordings go to output / participant.",
            max_length=64, pattern=_PARTICIPANT_RE,
            pattern_doc="letters, digits, '_', '-', '.', starting with a letter or digit",
        ),
        "track": Field("choice", doc="The road.", choices=("straight", "curved")),
        "bias": Field(
            "number", doc="Camera bias of every run (null: drawn per run).", unit="m",
            low=-20.0, high=20.0, optional=True,
        ),
        "runs": Field("integer", doc="Number of runs.", low=1),
        "seconds": Field(
            "number", doc="Length of a run.", unit="s", low=0.0, high=1e6, low_open=True
        ),
        "speed": Field("number", doc="Initial speed.", unit="m/s", low=0.0, high=150.0),
        "lateral_offset": Field(
            "number", doc="Initial lateral offset.", unit="m", low=-30.0, high=30.0
        ),
        "output": Field("string", doc="Root directory of the recordings.", non_empty=True),
        "seed": Field("integer", doc="Root seed (null: fresh entropy).", low=0, optional=True),
        "countdown": Field("number", doc="Countdown before each run.", unit="s", low=0.0),
        "config": Field("mapping", doc="Extra env configuration.", each=ANY_JSON),
        "fsync": Field("bool", doc="Also fsync every recorded row."),
        "speed_control": Field(
            "choice", doc="'free': the pedals (or keys) set the speed; 'constant': they do "
            "nothing and the car keeps its speed.", choices=("free", "constant"),
        ),
        "min_speed": Field(
            "number", doc="No stopping: the brake cannot take the car below this speed (0: it "
            "can stop).", unit="m/s", low=0.0, high=150.0,
        ),
    }
)  # fmt: skip


@dataclass
class DriveSettings:
    """One session of runs (units: s, m/s, m).

    Attributes:
        participant: participant id (at most 64 letters, digits, '_', '-', '.',
            starting with a letter or digit); recordings go to ``output / participant``.
        track: ``"straight"`` or ``"curved"``.
        bias: camera bias b (m) of every run, or None to draw it per run
            (equally likely hypotheses, from the run's seed).
        runs: number of runs.
        seconds: length of a run (the paper: 30 s).
        speed: initial speed (15 m/s).
        lateral_offset: initial lateral offset y (-0.5 m).
        output: root directory of the recordings (a str or path; a Path once validated).
        seed: root seed of the runs' seeds (None: fresh entropy, recorded).
        countdown: seconds of countdown before each run (real time only).
        config: extra env configuration deep-merged onto the defaults.
        fsync: also fsync every recorded row (survives power loss).
        speed_control: ``"free"`` (default): throttle and brake set the speed;
            ``"constant"``: the car keeps its initial speed whatever the pedals do.
        min_speed: "no stopping" (m/s): the brake cannot take the car below this
            speed; the recorded action is the acceleration applied (0: no limit).
    """

    participant: str
    track: str = "straight"
    bias: float | None = None
    runs: int = 10
    seconds: float = 30.0
    speed: float = 15.0
    lateral_offset: float = -0.5
    output: Path | str = Path("recordings")
    seed: int | None = None
    countdown: float = 3.0
    config: Mapping[str, Any] = field(default_factory=dict)
    fsync: bool = False
    speed_control: str = "free"
    min_speed: float = 0.0

    def __post_init__(self) -> None:
        """Validate every setting (shared validator) and keep the converted values.

        Raises:
            ValueError: naming the setting and its allowed range (a
                :class:`~hasa_env.sim.config.ConfigError` for ``config``).
        """
        if isinstance(self.output, os.PathLike):
            self.output = os.fspath(self.output)
        validate_fields(
            self,
            _SCHEMA,
            describe=lambda path: f"drive setting '{path}'",
            error=lambda path, message: ValueError(message),
        )
        self.output = Path(self.output)
        self.env_config()  # a bad config is refused now, not at the first run

    def env_config(self) -> dict[str, Any]:
        """The env configuration of every run (validated)."""
        base = {"track": self.track, "time_limit": self.seconds, "action": {"type": "physical"}}
        return make_config(deep_merge(base, self.config))

    def reset_options(self) -> dict[str, Any]:
        """``reset`` options of every run: the protocol's initial state and, if fixed, the bias."""
        options: dict[str, Any] = {
            "lateral_offset": float(self.lateral_offset),
            "heading": 0.0,
            "speed": float(self.speed),
            "steering": 0.0,
        }
        if self.bias is not None:
            options["bias"] = float(self.bias)
        return options

    def applied_acceleration(self, acceleration: float, speed: float, dt: float) -> float:
        """The acceleration (m/s^2) applied over a step of ``dt`` s for the one commanded at
        ``speed`` (m/s): zero with ``speed_control = "constant"``; with ``min_speed``, a
        braking command is reduced so the step ends no slower than ``min_speed``."""
        if self.speed_control == "constant":
            return 0.0
        if acceleration < 0.0 and self.min_speed > 0.0:
            return min(0.0, max(acceleration, (self.min_speed - speed) / dt))
        return acceleration

    @property
    def directory(self) -> Path:
        """Where this participant's recordings go: ``output / participant``."""
        return Path(self.output) / self.participant
