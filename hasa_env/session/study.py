"""Study files: what a human study is, and the schedule of runs each participant drives.

A study file (TOML, read with the standard library's :mod:`tomllib`, or the
same structure in JSON) describes a study; ``hasa-drive study STUDY.toml
--participant P07`` runs one participant's session of it
(:mod:`hasa_env.session.study_session`). ``studies/paper.toml`` is the
paper's protocol. Every key, with its default and range::

    format_version = 1                  # this hasa_env reads version 1

    [study]
    name = "paper"                      # letters, digits, '_', '-', '.' (<= 64)
    title = "..."                       # free text
    seed = 20240615                     # root seed of the run seeds (omit: drawn, recorded)

    [participant.age_band]              # metadata asked for before the first run
    prompt = "Age band"                 # (no names: the id is the only identifier)
    choices = ["18-24", "25-34", "35-44", "45-54", "55-64", "65+"]
    [participant.licence_years]
    prompt = "Years since the driving licence"
    kind = "integer"                    # choice (needs choices) | integer | number | text
    low = 0
    high = 80
    required = true                     # default true

    [runs]                              # every run
    seconds = 30.0                      # (0, 3600] s
    scenario = "paper"                  # hasa_env.scenarios.SCENARIOS (default "paper")
    speed = 15.0                        # start speed, [0, 60] m/s     } omitted: the env
    lateral_offset = -0.5               # start y, [-5, 5] m           } config's initial_state
    heading = 0.0                       # start heading, [-0.5, 0.5] rad } (the scenario's;
                                        #   paper: 15 m/s, -0.5 m, 0 rad)
    speed_control = "free"              # "free" (pedals) | "constant" (cruise)
    min_speed = 0.0                     # no stopping: the brake stops here, [0, 60] m/s
    countdown = 3.0                     # [0, 60] s
    repeat_aborted = true               # an aborted run is driven again (a new file)

    [practice]
    runs = 1                            # [0, 100]; never analysed
    track = "straight"                  # "straight" | "curved"
    bias = 0.0                          # camera bias of practice runs (default: the first
                                        # hypothesis)
    [measured]
    runs = 10                           # [1, 1000]
    track = "straight"
    break_every = 5                     # a break after every 5 measured runs (0: none)
    break_seconds = 30.0                # shortest break, [0, 3600] s

    [schedule]                          # the true camera bias of each measured run
    kind = "latin_square"               # latin_square | counterbalanced | random | fixed
    order = [0.0, -1.8]                 # kind = "fixed": one bias per measured run

    [env]                               # env configuration (hasa_env.describe_config())
    markings.hypotheses = [0.0, -1.8]   # the lane hypotheses (for the estimator)

    [view]                              # what the participant sees
    view = "driver"                     # "driver" | "top_down"
    ghosts = false                      # the wrong hypotheses' ghost markings
    hud = []                            # of "time", "speed", "steering", "weights"
    bonnet = true
    road_texture = true
    show_points = false                 # the near and far points

    [instructions]                      # screens (newlines allowed)
    welcome = "..."
    practice = "..."                    # before the practice runs
    measured = "..."                    # before the measured runs
    break = "..."
    end = "..."

Schedules (the hypotheses are ``env.markings.hypotheses``, n of them):

- ``latin_square``: a Williams balanced Latin square over the hypotheses
  (n rows, 2n for odd n; every hypothesis equally often at each position and
  after each other one, across participants); participant number k (the
  digits at the end of the id, ``P07`` -> 7, or ``--slot``) takes row
  ``(k - 1) mod rows``, repeated over the measured runs;
- ``counterbalanced``: each hypothesis equally often for every participant
  (when n does not divide the runs, the extra runs follow the participant's
  Latin-square row), in an order shuffled from the study seed and the id;
- ``random``: drawn per run with ``env.markings.probabilities`` (default
  uniform), from the study seed and the id;
- ``fixed``: ``schedule.order``, the same for everyone.

The scenario (``runs.scenario``, :mod:`hasa_env.scenarios`) is the env
config's ``scenario`` key: its env keys lie under the study's own, so what the
study file gives wins (``[env]``, and ``[runs]`` ``speed``, ``lateral_offset``,
``heading``, which are the env config's ``initial_state`` keys and win over
``[env]``'s) and the scenario's other keys apply: a copy of
``studies/paper.toml`` with ``scenario = "late_ambiguity"`` starts at the file's
15 m/s but halfway between the hypotheses' centres (the scenario's
``initial_state.between_hypotheses``, which places the car whatever
``lateral_offset`` says, and its ``heading_toward_other``, added to the file's
``heading``), and with ``scenario = "close_hypotheses"`` it keeps
its own ``markings.hypotheses`` ([0, -1.8] m), so the scenario changes only the
start: ``hasa-drive study FILE --check`` lists such overridden keys
(:meth:`Study.scenario_overrides`). A scenario's drivers' preferred offset
(``off_centre_drivers``) is for synthetic drivers only: a human keeps their
own. The scenario is one for the whole study (the run list has no per-run
settings); the env key ``scenario`` is refused in ``[env]``.

Run seeds derive from the study seed, the participant id and the run's
position, so a resumed session drives exactly the runs it would have. Bad
input raises :class:`StudyError` naming the file, the line where it can
find the key, the key and what is allowed.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import re
import tomllib
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hasa_env.files import read_bounded_bytes
from hasa_env.render import ViewOptions
from hasa_env.scenarios import scenario_spec
from hasa_env.session.study_schema import (
    IDENTIFYING_KEYS,
    SCHEDULE_KINDS,
    SCHEMA,
    STUDY_FORMAT_VERSION,
    check_relations,
    line_of,
    study_env,
)
from hasa_env.sim.config import deep_merge, make_config
from hasa_env.validation import validate

__all__ = [
    "IDENTIFYING_KEYS",
    "MAX_STUDY_FILE_BYTES",
    "SCHEDULE_KINDS",
    "STUDY_FORMAT_VERSION",
    "MetadataField",
    "ScheduledRun",
    "Study",
    "StudyError",
    "participant_slot",
    "seed_from_entropy",
    "williams_square",
]

MAX_STUDY_FILE_BYTES = 16 * 2**20
"""Largest study file read (16 MiB; a study file is a few KB)."""


class StudyError(ValueError):
    """A study file (or participant metadata) that cannot be used; the message names the
    file, the line where the key is (when it can be found), the key and what is allowed."""


@dataclass(frozen=True)
class MetadataField:
    """One piece of participant metadata the study asks for (no names: see
    :data:`IDENTIFYING_KEYS`)."""

    key: str
    prompt: str
    kind: str = "choice"
    choices: tuple[str, ...] = ()
    low: float | None = None
    high: float | None = None
    unit: str = ""
    required: bool = True

    def question(self) -> str:
        """The prompt with what is allowed, for the experimenter's terminal."""
        if self.kind == "choice":
            allowed = " / ".join(self.choices)
        elif self.kind in ("integer", "number"):
            lo = "-inf" if self.low is None else f"{self.low:g}"
            hi = "inf" if self.high is None else f"{self.high:g}"
            allowed = f"{'an integer' if self.kind == 'integer' else 'a number'} in [{lo}, {hi}]"
            if self.unit:
                allowed += f" {self.unit}"
        else:
            allowed = "text"
        optional = "" if self.required else ", Enter to skip"
        return f"{self.prompt} ({allowed}{optional}): "

    def parse(self, value: Any) -> Any:
        """The answer ``value`` (text typed, or a value from a file) converted and checked.

        Raises:
            ValueError: naming the field and what is allowed.
        """
        text = value.strip() if isinstance(value, str) else value
        if text in ("", None):
            if self.required:
                raise ValueError(f"participant field '{self.key}' is required")
            return None
        if self.kind == "choice":
            if str(text) not in self.choices:
                raise ValueError(
                    f"participant field '{self.key}' = {text!r} is not allowed: one of "
                    f"{', '.join(repr(c) for c in self.choices)}"
                )
            return str(text)
        if self.kind == "text":
            return str(text)
        try:
            number = float(text)
        except (TypeError, ValueError):
            number = math.nan
        if not math.isfinite(number) or (self.kind == "integer" and not number.is_integer()):
            raise ValueError(
                f"participant field '{self.key}' must be "
                f"{'an integer' if self.kind == 'integer' else 'a number'}, got {text!r}"
            )
        if (self.low is not None and number < self.low) or (
            self.high is not None and number > self.high
        ):
            raise ValueError(
                f"participant field '{self.key}' = {number:g} is out of range: allowed "
                f"[{'-inf' if self.low is None else f'{self.low:g}'}, "
                f"{'inf' if self.high is None else f'{self.high:g}'}]"
                f"{' ' + self.unit if self.unit else ''}"
            )
        return int(number) if self.kind == "integer" else number


@dataclass(frozen=True)
class ScheduledRun:
    """One run of a participant's session.

    Attributes:
        position: 1-based position in the session (practice runs first).
        block: ``"practice"`` or ``"measured"``.
        number: 1-based number within its block.
        track: its road.
        bias: its true camera bias b (m); bias_index: its hypothesis' index.
        seed: its env seed.
    """

    position: int
    block: str
    number: int
    track: str
    bias: float
    bias_index: int
    seed: int

    @property
    def prefix(self) -> str:
        """Recording prefix: ``measured_03`` -> ``measured_03_000.csv`` (then ``_001``, ...
        for a repeated attempt)."""
        return f"{self.block}_{self.number:02d}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "position": self.position,
            "block": self.block,
            "number": self.number,
            "track": self.track,
            "bias": self.bias,
            "bias_index": self.bias_index,
            "seed": self.seed,
            "prefix": self.prefix,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ScheduledRun:
        fields = ("position", "block", "number", "track", "bias", "bias_index", "seed")
        return cls(**{k: data[k] for k in fields})


def williams_square(n: int) -> list[list[int]]:
    """A Williams balanced Latin square over ``n`` treatments (rows of indices).

    Every treatment appears once per row and once per position, and follows
    every other treatment equally often; n rows for even n, 2n (each row and
    its reverse) for odd n.
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    first, low, high = [0], 1, n - 1
    for i in range(1, n):
        if i % 2:
            first.append(low)
            low += 1
        else:
            first.append(high)
            high -= 1
    rows = [[(x + r) % n for x in first] for r in range(n)]
    if n % 2:
        rows += [row[::-1] for row in rows]
    return rows


def participant_slot(participant: str) -> int | None:
    """The participant's number from the digits that end the id (``P07`` -> 7), or None."""
    match = re.search(r"([0-9]+)$", participant)
    return int(match.group(1)) if match else None


@dataclass(frozen=True)
class Study:
    """A validated study (see the module docstring for the file's keys).

    Attributes:
        document: the whole validated study, defaults filled in (what a session
            file stores).
        source: the file it came from ("<memory>" if none).
        sha256: SHA-256 of the file's bytes (of the canonical JSON of
            ``document`` without a file): a resumed session checks it.
    """

    document: Mapping[str, Any]
    source: str = "<memory>"
    sha256: str = ""

    # ---------------------------------------------------------------- loading
    @classmethod
    def load(cls, path: str | Path) -> Study:
        """Read and validate a study file (``.toml``, or ``.json``): a regular file of at most
        :data:`MAX_STUDY_FILE_BYTES`, read without blocking (a FIFO or a device is refused).

        Raises:
            StudyError: naming the file, the line, the key and what is allowed.
        """
        source = str(path)
        try:
            raw = read_bounded_bytes(path, "the study file", MAX_STUDY_FILE_BYTES)
        except FileNotFoundError:
            raise StudyError(f"{source}: no such study file") from None
        except OSError as exc:  # a FIFO, a device, a directory, too large, unreadable
            raise StudyError(
                f"{source}: cannot read the study file ({exc.strerror or exc})"
            ) from None
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise StudyError(f"{source}: not a UTF-8 text file ({exc.reason})") from None
        if source.lower().endswith(".json"):
            try:
                document = json.loads(text)
            except json.JSONDecodeError as exc:
                raise StudyError(
                    f"{source}, line {exc.lineno}: not valid JSON (column {exc.colno}: {exc.msg})"
                ) from None
            except (ValueError, RecursionError) as exc:  # a huge integer, deep nesting
                raise StudyError(f"{source}: cannot be read as JSON: {_brief(exc)}") from None
        else:
            try:
                document = tomllib.loads(text)
            except tomllib.TOMLDecodeError as exc:
                raise StudyError(f"{source}: not valid TOML: {exc}") from None
            except (ValueError, RecursionError) as exc:
                raise StudyError(f"{source}: cannot be read as TOML: {_brief(exc)}") from None
        return cls.from_dict(document, source, text, hashlib.sha256(raw).hexdigest())

    @classmethod
    def from_dict(
        cls,
        document: Mapping[str, Any],
        source: str = "<memory>",
        text: str | None = None,
        sha256: str | None = None,
    ) -> Study:
        """Validate a study given as a mapping (the structure of the file).

        Raises:
            StudyError: naming ``source``, the line (with ``text``), the key and
                what is allowed.
        """

        def where(path: str) -> str:
            line = line_of(text, path) if text is not None and path else None
            return f"{source}, line {line}" if line else source

        def fail(path: str, message: str) -> StudyError:
            return StudyError(f"{where(path)}: {message}")

        doc = validate(
            document,
            SCHEMA,
            describe=lambda path: f"key '{path}'" if path else "the study",
            error=fail,
        )
        check_relations(doc, fail)
        if sha256 is None:
            canonical = json.dumps(doc, sort_keys=True, separators=(",", ":"))
            sha256 = hashlib.sha256(canonical.encode()).hexdigest()
        return cls(document=doc, source=source, sha256=sha256)

    # ------------------------------------------------------------- properties
    @property
    def name(self) -> str:
        return str(self.document["study"]["name"])

    @property
    def seed(self) -> int | None:
        """The root seed of the run seeds (None: drawn when a participant's session starts)."""
        return self.document["study"]["seed"]

    @property
    def hypotheses(self) -> list[float]:
        """The lane hypotheses (camera biases, m) of every run."""
        return [float(b) for b in self.env_config("straight")["markings"]["hypotheses"]]

    @property
    def participant_fields(self) -> list[MetadataField]:
        """The metadata asked of each participant, in the file's order."""
        out = []
        for key, f in self.document["participant"].items():
            out.append(
                MetadataField(
                    key=key,
                    prompt=f["prompt"] or key.replace("_", " "),
                    kind=f["kind"],
                    choices=tuple(f["choices"] or ()),
                    low=f["low"],
                    high=f["high"],
                    unit=f["unit"],
                    required=f["required"],
                )
            )
        return out

    @property
    def view_options(self) -> ViewOptions:
        """What the participant sees."""
        v = self.document["view"]
        return ViewOptions(
            ghosts=v["ghosts"], hud=tuple(v["hud"]), bonnet=v["bonnet"],
            road_texture=v["road_texture"],
        )  # fmt: skip

    def text(self, screen: str) -> str:
        """The ``[instructions]`` text of a screen, with ``{runs}`` and ``{seconds}`` filled in."""
        block = self.document.get(screen) if screen in ("practice", "measured") else None
        runs = block["runs"] if block else self.document["measured"]["runs"]
        template = self.document["instructions"][screen]
        try:
            return template.format(runs=runs, seconds=self.document["runs"]["seconds"])
        except (KeyError, IndexError, ValueError):
            return template

    @property
    def scenario(self) -> str:
        """The scenario of every run (``runs.scenario``, :data:`hasa_env.scenarios.SCENARIOS`)."""
        return str(self.document["runs"]["scenario"])

    def env_keys(self) -> dict[str, Any]:
        """The env configuration the study sets (:func:`~hasa_env.session.study_schema.study_env`:
        ``[env]``, the scenario, the start state of ``[runs]``), before the run's track and
        time limit are added."""
        return study_env(self.document)

    def env_config(self, track: str) -> dict[str, Any]:
        """The env configuration of a run on ``track`` (validated): the scenario's keys under
        the study's own (:meth:`env_keys`)."""
        base = {
            "track": track,
            "time_limit": self.document["runs"]["seconds"],
            "action": {"type": "physical"},
        }
        return make_config(deep_merge(base, self.env_keys()))

    def scenario_overrides(self) -> list[tuple[str, Any, Any]]:
        """The scenario's env keys the study file gives other values of its own:
        ``(the study file's key, its value, the scenario's value)`` each (``runs.speed``,
        ``env.markings.hypotheses``, ...). The study's win (:meth:`env_keys`);
        ``hasa-drive study --check`` lists them."""
        own = self.env_keys()
        runs = self.document["runs"]
        out = []
        for path, value in _leaves(scenario_spec(self.scenario).config):
            mine: Any = own
            for part in path.split("."):
                mine = mine.get(part, _ABSENT) if isinstance(mine, Mapping) else _ABSENT
            if mine is _ABSENT or mine == value:
                continue
            table, _, key = path.partition(".")
            given_in_runs = table == "initial_state" and runs.get(key) is not None
            out.append((f"runs.{key}" if given_in_runs else f"env.{path}", mine, value))
        return out

    def reset_options(self, run: ScheduledRun) -> dict[str, Any]:
        """``reset`` options of a run: the wheel centred and the run's bias. The start state
        is in the env configuration (:meth:`env_keys`), where a scenario's
        ``initial_state.between_hypotheses`` can still place the car."""
        return {"steering": 0.0, "bias": run.bias}

    def check_metadata(self, answers: Mapping[str, Any]) -> dict[str, Any]:
        """The participant's metadata, each answer checked (typed text or values).

        Raises:
            StudyError: an unknown key, a missing required answer or one that is
                not allowed (naming the field and what is allowed).
        """
        fields = {f.key: f for f in self.participant_fields}
        unknown = sorted(set(answers) - set(fields))
        if unknown:
            allowed = ", ".join(fields) or "none (the study asks for no metadata)"
            raise StudyError(f"unknown participant field {unknown[0]!r}; allowed: {allowed}")
        out = {}
        for key, f in fields.items():
            try:
                out[key] = f.parse(answers.get(key))
            except ValueError as exc:
                raise StudyError(str(exc)) from None
        return out

    # --------------------------------------------------------------- schedule
    def schedule_for(self, participant: str, slot: int | None, seed: int) -> list[ScheduledRun]:
        """The runs of ``participant``'s session: practice runs, then the measured ones.

        ``slot`` is the participant's number for the ``latin_square`` and
        ``counterbalanced`` schedules (default: from the id,
        :func:`participant_slot`); ``seed`` is the root seed (the study's, or
        the one drawn for this session).

        Raises:
            StudyError: a schedule that needs a slot the id does not give.
        """
        hypotheses = self.hypotheses
        n = len(hypotheses)
        doc = self.document
        kind = doc["schedule"]["kind"]
        if slot is None:
            slot = participant_slot(participant)
        if slot is None and kind in ("latin_square", "counterbalanced"):
            raise StudyError(
                f"the {kind} schedule needs the participant's number: give an id that ends in "
                f"one (P07) or --slot N; got the id {participant!r}"
            )
        measured = doc["measured"]["runs"]
        digest = zlib.crc32(participant.encode("utf-8"))
        rng = np.random.default_rng([seed, digest, 1])
        rows = williams_square(n)
        row = rows[(slot - 1) % len(rows)] if slot is not None else list(range(n))
        if kind == "latin_square":
            indices = [row[i % n] for i in range(measured)]
        elif kind == "counterbalanced":
            indices = [row[i % n] for i in range(measured)]
            indices = [int(i) for i in rng.permutation(indices)]
        elif kind == "random":
            probabilities = self.env_config("straight")["markings"]["probabilities"]
            indices = [int(i) for i in rng.choice(n, size=measured, p=probabilities)]
        else:
            indices = [hypotheses.index(b) for b in doc["schedule"]["order"]]
        practice_bias = doc["practice"]["bias"]
        practice_index = 0 if practice_bias is None else hypotheses.index(practice_bias)
        blocks = [("practice", practice_index)] * doc["practice"]["runs"]
        blocks += [("measured", i) for i in indices]
        runs = []
        counts = {"practice": 0, "measured": 0}
        for position, (block, index) in enumerate(blocks, start=1):
            counts[block] += 1
            state = np.random.SeedSequence([seed, digest, position]).generate_state(2, np.uint32)
            runs.append(
                ScheduledRun(
                    position=position,
                    block=block,
                    number=counts[block],
                    track=doc[block]["track"],
                    bias=hypotheses[index],
                    bias_index=index,
                    seed=int(state[0]) << 21 ^ int(state[1]),
                )
            )
        return runs

    def to_dict(self) -> dict[str, Any]:
        """The validated study (a deep copy)."""
        return copy.deepcopy(dict(self.document))


_ABSENT = object()


def _leaves(tree: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    """``(dotted key path, value)`` of every leaf of a nested mapping (a list is a leaf)."""
    out: list[tuple[str, Any]] = []
    for key, value in tree.items():
        path = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out += _leaves(value, f"{path}.")
        else:
            out.append((path, value))
    return out


def _brief(exc: BaseException) -> str:
    """Why a parser gave up, in a few words (a RecursionError's text says nothing useful)."""
    if isinstance(exc, RecursionError):
        return "nested too deeply"
    return str(exc)[:200]


def seed_from_entropy() -> int:
    """A fresh root seed (recorded in the session file when the study gives none)."""
    entropy = np.random.SeedSequence().entropy
    assert isinstance(entropy, int)  # (fresh entropy is one int)
    return entropy % 2**63
