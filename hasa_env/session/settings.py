"""The settings of a drive session: who drives, which track, how many runs, how long."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hasa_env.sim.config import deep_merge, make_config

__all__ = ["DriveSettings"]

_PARTICIPANT_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]*")


@dataclass
class DriveSettings:
    """One session of runs (units: s, m/s, m).

    Attributes:
        participant: participant id; recordings go to ``output / participant``.
        track: ``"straight"`` or ``"curved"``.
        bias: camera bias b (m) of every run, or None to draw it per run
            (equally likely hypotheses, from the run's seed).
        runs: number of runs.
        seconds: length of a run (the paper: 30 s).
        speed: initial speed (15 m/s).
        lateral_offset: initial lateral offset y (-0.5 m).
        output: root directory of the recordings.
        seed: root seed of the runs' seeds (None: fresh entropy, recorded).
        countdown: seconds of countdown before each run (real time only).
        config: extra env configuration deep-merged onto the defaults.
        fsync: also fsync every recorded row (survives power loss).
    """

    participant: str
    track: str = "straight"
    bias: float | None = None
    runs: int = 10
    seconds: float = 30.0
    speed: float = 15.0
    lateral_offset: float = -0.5
    output: Path = Path("recordings")
    seed: int | None = None
    countdown: float = 3.0
    config: Mapping[str, Any] = field(default_factory=dict)
    fsync: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.participant, str) or not _PARTICIPANT_RE.fullmatch(self.participant):
            raise ValueError(
                "participant id must be letters, digits, '_', '-', '.' "
                "(starting with a letter or digit), "
                f"got {self.participant!r}"
            )
        if isinstance(self.runs, bool) or not isinstance(self.runs, int) or self.runs < 1:
            raise ValueError(f"runs must be a positive integer, got {self.runs!r}")
        if not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"seconds must be > 0, got {self.seconds!r}")
        if self.seed is not None and (isinstance(self.seed, bool) or self.seed < 0):
            raise ValueError(f"seed must be a non-negative integer or None, got {self.seed!r}")
        self.output = Path(self.output)

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

    @property
    def directory(self) -> Path:
        return self.output / self.participant
