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
    speed = 15.0                        # start speed, [0, 60] m/s
    lateral_offset = -0.5               # start y, [-5, 5] m
    heading = 0.0                       # start heading, [-0.5, 0.5] rad
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

from hasa_env.render import HUD_ITEMS, ViewOptions
from hasa_env.sim.config import ConfigError, deep_merge, make_config
from hasa_env.validation import ANY_JSON, Field, schema, validate, version

__all__ = [
    "IDENTIFYING_KEYS",
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

STUDY_FORMAT_VERSION = 1
SCHEDULE_KINDS = ("latin_square", "counterbalanced", "random", "fixed")
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]*")
_KEY = re.compile(r"[a-z][a-z0-9_]*")
IDENTIFYING_KEYS = (
    "name", "first_name", "last_name", "surname", "full_name", "email", "phone", "address",
    "birthday", "birth_date", "date_of_birth", "dob",
)  # fmt: skip
"""Participant-metadata keys refused: a session file holds no names or contact details."""

_DEFAULT_TEXT = {
    "welcome": "Welcome, and thank you for taking part.\n"
    "Drive in the middle of your lane, as you normally would.",
    "practice": "First, {runs} practice run(s) of {seconds:g} s to get used to the car.",
    "measured": "Now the {runs} measured runs of {seconds:g} s each.",
    "break": "Time for a break. Let go of the wheel and relax.",
    "end": "That is all. Thank you for taking part!",
}

_TRACK = ("straight", "curved")
_METADATA_FIELD = Field(
    "mapping",
    fields={
        "prompt": Field("string", None, "The question (default: the key).", optional=True),
        "kind": Field(
            "choice",
            "choice",
            "The answer's kind.",
            choices=("choice", "integer", "number", "text"),
        ),
        "choices": Field(
            "strings",
            None,
            "Allowed answers of a choice.",
            optional=True,
            unique=True,
            non_empty=True,
        ),  # fmt: skip
        "low": Field("number", None, "Smallest number allowed.", optional=True),
        "high": Field("number", None, "Largest number allowed.", optional=True),
        "unit": Field("string", "", "Unit of a number, shown with the question."),
        "required": Field("bool", True, "Must be answered."),
    },
)
_SCHEMA = schema(
    {
        "format_version": version(STUDY_FORMAT_VERSION, default=STUDY_FORMAT_VERSION),
        "study": Field("mapping", fields={
            "name": Field("string", doc="The study's name.", max_length=64, pattern=_NAME,
                          pattern_doc="letters, digits, '_', '-', '.', starting with a letter "
                          "or digit"),
            "title": Field("string", "", "A title."),
            "description": Field("string", "", "What the study is."),
            "seed": Field("integer", None, "Root seed of the run seeds (null: drawn per "
                          "participant, recorded).", low=0, high=2**63 - 1, optional=True),
        }),
        "participant": Field("mapping", {}, "Metadata asked for.", each=_METADATA_FIELD,
                             max_length=32),
        "runs": {
            "seconds": Field("number", 30.0, "Length of a run.", unit="s", low=0.0, high=3600.0,
                             low_open=True),
            "speed": Field("number", 15.0, "Start speed.", unit="m/s", low=0.0, high=60.0),
            "lateral_offset": Field("number", -0.5, "Start lateral offset y.", unit="m",
                                    low=-5.0, high=5.0),
            "heading": Field("number", 0.0, "Start heading.", unit="rad", low=-0.5, high=0.5),
            "speed_control": Field("choice", "free", "'free': the pedals set the speed; "
                                   "'constant': cruise control.", choices=("free", "constant")),
            "min_speed": Field("number", 0.0, "No stopping: the brake stops here.", unit="m/s",
                               low=0.0, high=60.0),
            "countdown": Field("number", 3.0, "Countdown before a run.", unit="s", low=0.0,
                               high=60.0),
            "repeat_aborted": Field("bool", True, "Drive an aborted run again."),
        },
        "practice": {
            "runs": Field("integer", 0, "Practice runs.", low=0, high=100),
            "track": Field("choice", "straight", "Their road.", choices=_TRACK),
            "bias": Field("number", None, "Their camera bias (default: the first hypothesis).",
                          unit="m", low=-20.0, high=20.0, optional=True),
        },
        "measured": {
            "runs": Field("integer", 10, "Measured runs.", low=1, high=1000),
            "track": Field("choice", "straight", "Their road.", choices=_TRACK),
            "break_every": Field("integer", 0, "A break after every this many measured runs "
                                 "(0: none).", low=0, high=1000),
            "break_seconds": Field("number", 0.0, "Shortest break.", unit="s", low=0.0,
                                   high=3600.0),
        },
        "schedule": {
            "kind": Field("choice", "latin_square", "How the bias of each measured run is "
                          "chosen.", choices=SCHEDULE_KINDS),
            "order": Field("numbers", None, "kind = 'fixed': the bias of each measured run.",
                           unit="m", low=-20.0, high=20.0, optional=True),
        },
        "env": Field("mapping", {}, "Env configuration (deep-merged).", each=ANY_JSON),
        "view": {
            "view": Field("choice", "driver", "The view.", choices=("driver", "top_down")),
            "ghosts": Field("bool", False, "Ghost markings of the wrong hypotheses."),
            "hud": Field("strings", [], "HUD items.", unique=True),
            "bonnet": Field("bool", True, "Bonnet and dashboard silhouette."),
            "road_texture": Field("bool", True, "Road and grass bands."),
            "show_points": Field("bool", False, "Near and far points."),
        },
        "instructions": {
            key: Field("string", text, f"The {key} screen.", max_length=2000)
            for key, text in _DEFAULT_TEXT.items()
        },
    }
)  # fmt: skip


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


def _line_of(text: str, path: str) -> int | None:
    """The line (1-based) where a TOML key path is written, or that of its table (best effort)."""
    parts = path.split(".")
    table: list[str] = []
    found: int | None = None
    header = re.compile(r"^\s*\[\[?\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
    assignment = re.compile(r"^\s*([A-Za-z0-9_\-.\"' ]+?)\s*=")
    for number, line in enumerate(text.splitlines(), start=1):
        m = header.match(line)
        if m:
            table = [p.strip().strip("\"'") for p in m.group(1).split(".")]
            if table == parts:
                found = found or number
            continue
        m = assignment.match(line)
        if m:
            keys = table + [p.strip().strip("\"'") for p in m.group(1).split(".")]
            if keys == parts:
                return number
            if found is None and len(keys) <= len(parts) and parts[: len(keys)] == keys:
                found = number  # e.g. `markings.hypotheses = ...` under [env] for env.markings
    if found is None and len(parts) > 1:
        return _line_of(text, ".".join(parts[:-1]))
    return found


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
        """Read and validate a study file (``.toml``, or ``.json``).

        Raises:
            StudyError: naming the file, the line, the key and what is allowed.
        """
        source = str(path)
        try:
            raw = Path(path).read_bytes()
        except FileNotFoundError:
            raise StudyError(f"{source}: no such study file") from None
        except OSError as exc:
            raise StudyError(f"{source}: cannot read the study file ({exc.strerror})") from None
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
        else:
            try:
                document = tomllib.loads(text)
            except tomllib.TOMLDecodeError as exc:
                raise StudyError(f"{source}: not valid TOML: {exc}") from None
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
            line = _line_of(text, path) if text is not None and path else None
            return f"{source}, line {line}" if line else source

        def fail(path: str, message: str) -> StudyError:
            return StudyError(f"{where(path)}: {message}")

        doc = validate(
            document,
            _SCHEMA,
            describe=lambda path: f"key '{path}'" if path else "the study",
            error=fail,
        )
        _check(doc, fail)
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

    def env_config(self, track: str) -> dict[str, Any]:
        """The env configuration of a run on ``track`` (validated)."""
        base = {
            "track": track,
            "time_limit": self.document["runs"]["seconds"],
            "action": {"type": "physical"},
        }
        return make_config(deep_merge(base, self.document["env"]))

    def reset_options(self, run: ScheduledRun) -> dict[str, Any]:
        """``reset`` options of a run: the study's start state and the run's bias."""
        r = self.document["runs"]
        return {
            "lateral_offset": r["lateral_offset"],
            "heading": r["heading"],
            "speed": r["speed"],
            "steering": 0.0,
            "bias": run.bias,
        }

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


def _check(doc: dict[str, Any], fail: Any) -> None:
    """The checks that relate keys to each other (the schema checks each key alone)."""
    for key, f in doc["participant"].items():
        here = f"participant.{key}"
        if not _KEY.fullmatch(key):
            raise fail(here, f"participant field key {key!r} must be lower-case letters, digits "
                       "and '_', starting with a letter")  # fmt: skip
        if key in IDENTIFYING_KEYS:
            raise fail(
                here,
                f"participant field {key!r} would identify the participant; a session file "
                "holds no names or contact details (ask for an age band, not a birth date)",
            )
        if f["kind"] == "choice" and not f["choices"]:
            raise fail(f"{here}.choices", f"key '{here}.choices' is missing: a choice needs "
                       "its answers")  # fmt: skip
        if f["kind"] != "choice" and f["choices"] is not None:
            raise fail(f"{here}.choices", f"key '{here}.choices' is for kind = 'choice' only")
        if f["kind"] not in ("integer", "number") and (f["low"], f["high"]) != (None, None):
            raise fail(here, f"keys '{here}.low'/'high' are for kind = 'integer' or 'number'")
        if f["low"] is not None and f["high"] is not None and f["low"] > f["high"]:
            raise fail(f"{here}.low", f"key '{here}.low' = {f['low']:g} is above high = "
                       f"{f['high']:g}")  # fmt: skip
    env = doc["env"]
    for reserved, owner in (("track", "practice.track / measured.track"),
                            ("time_limit", "runs.seconds"), ("action", "the study")):  # fmt: skip
        if reserved in env:
            raise fail(f"env.{reserved}", f"key 'env.{reserved}' is set by {owner}; remove it "
                       "from [env]")  # fmt: skip
    try:
        config = make_config(deep_merge({"action": {"type": "physical"}}, env))
    except ConfigError as exc:
        path = re.search(r"config key '([^']+)'", str(exc))
        raise fail(f"env.{path.group(1)}" if path else "env", f"in [env]: {exc}") from None
    hypotheses = [float(b) for b in config["markings"]["hypotheses"]]
    runs = doc["runs"]
    if runs["min_speed"] > runs["speed"]:
        raise fail("runs.min_speed", f"key 'runs.min_speed' = {runs['min_speed']:g} m/s is "
                   f"above the start speed runs.speed = {runs['speed']:g} m/s")  # fmt: skip
    bias = doc["practice"]["bias"]
    if bias is not None and bias not in hypotheses:
        raise fail("practice.bias", f"key 'practice.bias' = {bias:g} is not allowed: one of the "
                   f"hypotheses {hypotheses} (env.markings.hypotheses)")  # fmt: skip
    schedule = doc["schedule"]
    if schedule["kind"] == "fixed":
        order = schedule["order"]
        if order is None:
            raise fail("schedule.kind", "key 'schedule.order' is missing: kind = 'fixed' needs "
                       "one bias per measured run")  # fmt: skip
        if len(order) != doc["measured"]["runs"]:
            raise fail("schedule.order", f"key 'schedule.order' has {len(order)} biases for "
                       f"measured.runs = {doc['measured']['runs']} runs")  # fmt: skip
        for i, b in enumerate(order):
            if b not in hypotheses:
                raise fail("schedule.order", f"key 'schedule.order[{i}]' = {b:g} is not allowed: "
                           f"one of the hypotheses {hypotheses} (env.markings.hypotheses)")  # fmt: skip
    elif schedule["order"] is not None:
        raise fail("schedule.order", "key 'schedule.order' is for kind = 'fixed' only")
    for item in doc["view"]["hud"]:
        if item not in HUD_ITEMS:
            raise fail("view.hud", f"key 'view.hud' has the unknown item {item!r}; allowed: "
                       f"{', '.join(HUD_ITEMS)}")  # fmt: skip


def seed_from_entropy() -> int:
    """A fresh root seed (recorded in the session file when the study gives none)."""
    return int(np.random.SeedSequence().entropy % 2**63)
