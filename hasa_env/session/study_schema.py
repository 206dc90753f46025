"""The schema of study files and the checks that relate their keys to each other.

:data:`SCHEMA` is the shared validator's description of every key of a study
file (:mod:`hasa_env.validation`: defaults, units, ranges, allowed values);
:func:`check_relations` checks what one key alone cannot say (a choice needs
its answers, a fixed schedule one bias per measured run, no identifying
metadata, ...); :func:`line_of` finds the line of a key in a TOML text for the
messages. :mod:`hasa_env.session.study` documents the keys.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from hasa_env.render import HUD_ITEMS
from hasa_env.scenarios import SCENARIOS
from hasa_env.session.settings import START_KEYS, scenario_env
from hasa_env.sim.config import ConfigError, deep_merge, make_config
from hasa_env.validation import ANY_JSON, Field, schema, version

__all__ = ["IDENTIFYING_KEYS", "SCHEDULE_KINDS", "SCHEMA", "START_KEYS", "STUDY_FORMAT_VERSION",
           "check_relations", "line_of", "study_env"]  # fmt: skip

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
SCHEMA = schema(
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
            "scenario": Field("choice", "paper", "The scenario of every run "
                              "(hasa_env.scenarios): env keys under the study's own.",
                              choices=tuple(SCENARIOS)),
            "speed": Field("number", None, "Start speed (null: the scenario's, paper 15 m/s).",
                           unit="m/s", low=0.0, high=60.0, optional=True),
            "lateral_offset": Field("number", None, "Start lateral offset y (null: the "
                                    "scenario's, paper -0.5 m).", unit="m", low=-5.0, high=5.0,
                                    optional=True),
            "heading": Field("number", None, "Start heading (null: the scenario's, paper 0).",
                             unit="rad", low=-0.5, high=0.5, optional=True),
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


def study_env(doc: Mapping[str, Any]) -> dict[str, Any]:
    """The env configuration a validated study ``doc`` sets (without track, time limit and
    action, which are the study's own): ``[env]``, ``scenario`` = ``runs.scenario``, and the
    start state ``[runs]`` gives (``speed``, ``lateral_offset``, ``heading``) as the
    ``initial_state`` keys of the same names, over ``[env]``'s. The scenario's keys lie
    under all of these (:func:`hasa_env.sim.config.make_config`): a key the study file
    gives wins, the scenario's others apply. A start key ``[runs]`` leaves out (null)
    is the scenario's (paper: 15 m/s, -0.5 m, 0 rad); ``initial_state.between_hypotheses``
    of a scenario places the car whatever ``lateral_offset`` says. (The same
    :func:`hasa_env.session.settings.scenario_env` makes a drive's env keys.)
    """
    runs = doc["runs"]
    start = {key: runs.get(key) for key in START_KEYS}
    return scenario_env(runs.get("scenario", "paper"), doc["env"], start)


def line_of(text: str, path: str) -> int | None:
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
        return line_of(text, ".".join(parts[:-1]))
    return found


def check_relations(doc: dict[str, Any], fail: Any) -> None:
    """The checks that relate keys to each other (the schema checks each key alone);
    ``fail(path, message)`` builds the error to raise."""
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
                            ("time_limit", "runs.seconds"), ("action", "the study"),
                            ("scenario", "runs.scenario")):  # fmt: skip
        if reserved in env:
            raise fail(f"env.{reserved}", f"key 'env.{reserved}' is set by {owner}; remove it "
                       "from [env]")  # fmt: skip
    try:
        config = make_config(deep_merge({"action": {"type": "physical"}}, study_env(doc)))
    except ConfigError as exc:
        path = re.search(r"config key '([^']+)'", str(exc))
        key = path.group(1) if path else ""
        table, _, leaf = key.partition(".")
        if table == "initial_state" and leaf in START_KEYS and doc["runs"][leaf] is not None:
            raise fail(f"runs.{leaf}", f"in [runs]: {exc}") from None
        raise fail(f"env.{key}" if key else "env", f"in [env]: {exc}") from None
    hypotheses = [float(b) for b in config["markings"]["hypotheses"]]
    runs = doc["runs"]
    speed = config["initial_state"]["speed"]
    if runs["min_speed"] > speed:
        given = "runs.speed" if runs["speed"] is not None else "of the env config (initial_state)"
        raise fail("runs.min_speed", f"key 'runs.min_speed' = {runs['min_speed']:g} m/s is "
                   f"above the start speed {given} = {speed:g} m/s")  # fmt: skip
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
