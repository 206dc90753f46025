"""The settings of a drive session: who drives, which track, how many runs, how long."""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hasa_env.scenarios import SCENARIOS
from hasa_env.sim.config import deep_merge, make_config
from hasa_env.validation import ANY_JSON, Field, schema, validate_fields

__all__ = ["START_KEYS", "DriveSettings", "scenario_env"]

START_KEYS = ("speed", "lateral_offset", "heading")
"""The start-state keys a drive or a study sets: the env config's ``initial_state`` keys."""


def scenario_env(
    scenario: str, env: Mapping[str, Any], start: Mapping[str, float | None]
) -> dict[str, Any]:
    """The env configuration keys of runs in ``scenario`` started as ``start`` says.

    ``env`` (the user's own env keys) with the start keys ``start`` gives
    (:data:`START_KEYS`: speed m/s, lateral_offset m, heading rad; None: not given)
    as ``initial_state`` keys over ``env``'s, and ``scenario``. The scenario's keys lie
    under all of these (:func:`hasa_env.sim.config.make_config`): a key the user gives
    wins, the scenario's others apply; a start key left out is the scenario's (paper:
    15 m/s, -0.5 m, 0 rad). Used by drive settings and study files alike.

    Raises:
        ValueError: a start key not in :data:`START_KEYS`.
    """
    unknown = sorted(set(start) - set(START_KEYS))
    if unknown:
        raise ValueError(f"unknown start key {unknown[0]!r}; allowed: {', '.join(START_KEYS)}")
    given = {key: value for key, value in start.items() if value is not None}
    keys = deep_merge(env, {"initial_state": given} if given else {})
    return deep_merge({"scenario": scenario}, keys)


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
        "scenario": Field(
            "choice", doc="Named scenario (hasa_env.scenarios): env keys under the drive's own.",
            choices=tuple(SCENARIOS),
        ),
        "speed": Field(
            "number", doc="Initial speed (null: the scenario's).", unit="m/s", low=0.0,
            high=150.0, optional=True,
        ),
        "lateral_offset": Field(
            "number", doc="Initial lateral offset (null: the scenario's).", unit="m", low=-10.0,
            high=10.0, optional=True,
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
        speed: initial speed (m/s, 0-150), or None for the scenario's (paper: 15 m/s).
        lateral_offset: initial lateral offset y (m, -10 to 10), or None for the
            scenario's (paper: -0.5 m). Given, it also wins over a scenario's
            ``initial_state.between_hypotheses`` (``late_ambiguity``); a scenario's
            ``lateral_offset_std`` is still added.
        output: root directory of the recordings (a str or path; a Path once validated).
        seed: root seed of the runs' seeds (None: fresh entropy, recorded).
        countdown: seconds of countdown before each run (real time only).
        config: extra env configuration deep-merged onto the defaults (over the
            scenario's keys; a ``scenario`` key in it must equal ``scenario``).
        fsync: also fsync every recorded row (survives power loss).
        speed_control: ``"free"`` (default): throttle and brake set the speed;
            ``"constant"``: the car keeps its initial speed whatever the pedals do.
        min_speed: "no stopping" (m/s): the brake cannot take the car below this
            speed; the recorded action is the acceleration applied (0: no limit).
        scenario: the named scenario of every run (:data:`hasa_env.scenarios.SCENARIOS`,
            default ``"paper"``); its env keys lie under the settings' own.
    """

    participant: str
    track: str = "straight"
    bias: float | None = None
    runs: int = 10
    seconds: float = 30.0
    speed: float | None = None
    lateral_offset: float | None = None
    output: Path | str = Path("recordings")
    seed: int | None = None
    countdown: float = 3.0
    config: Mapping[str, Any] = field(default_factory=dict)
    fsync: bool = False
    speed_control: str = "free"
    min_speed: float = 0.0
    scenario: str = "paper"

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
        named = self.config.get("scenario", self.scenario)
        if named != self.scenario:
            raise ValueError(
                f"drive setting 'config.scenario' = {named!r} differs from the setting "
                f"'scenario' = {self.scenario!r}; give the scenario once, as 'scenario'"
            )
        self.env_config()  # a bad config is refused now, not at the first run

    def env_config(self) -> dict[str, Any]:
        """The env configuration of every run (validated): :func:`scenario_env` of the
        scenario, ``config`` and the start (``speed``, ``lateral_offset``), over the
        track, time limit and physical action; a given ``lateral_offset`` also sets
        ``initial_state.between_hypotheses`` false."""
        base = {"track": self.track, "time_limit": self.seconds, "action": {"type": "physical"}}
        start = {"speed": self.speed, "lateral_offset": self.lateral_offset}
        keys = scenario_env(self.scenario, self.config, start)
        if self.lateral_offset is not None:
            keys = deep_merge(keys, {"initial_state": {"between_hypotheses": False}})
        return make_config(deep_merge(base, keys))

    def reset_options(self) -> dict[str, Any]:
        """``reset`` options of every run: the wheel centred and, if fixed, the bias (m).
        The start state is in the env configuration (:meth:`env_config`), where the
        scenario's start keys apply."""
        options: dict[str, Any] = {"steering": 0.0}
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
