"""The shared validator (hasa_env.validation) and fuzzing of the env configuration through it."""

from __future__ import annotations

import json
import re

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hasa_env  # noqa: F401  (registers the env ids)
from hasa_env.sim.config import _SCHEMA, ConfigError, default_config, make_config
from hasa_env.validation import (
    ABSENT,
    ANY_JSON,
    REQUIRED,
    Field,
    schema,
    show,
    validate,
    version,
)


class Bad(ValueError):
    """The caller's error class of these tests; keeps the path it was raised for."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(message)
        self.path = path


def check(value, spec, path=""):
    return validate(
        value, spec, describe=lambda p: f"key '{p}'" if p else "doc", error=Bad, path=path
    )


def message(value, spec, path="x"):
    with pytest.raises(Bad) as info:
        check(value, spec, path)
    assert info.value.path.startswith(path)
    return str(info.value)


# ------------------------------------------------------------------ numbers
def test_numbers_accept_python_and_numpy_numbers_and_return_floats():
    spec = Field("number", low=0.0, high=10.0, unit="m")
    for value in (1, 2.5, np.float32(0.5), np.float64(3.0), np.int64(4), np.uint8(7)):
        out = check(value, spec, "x")
        assert type(out) is float and out == float(value)


@pytest.mark.parametrize(
    "value",
    [True, np.bool_(False), "1", None, [1.0], float("nan"), float("inf"), -float("inf"),
     np.float64("nan"), np.array(0.5), np.array([0.5]), 1 + 2j, {"a": 1}],
)  # fmt: skip
def test_numbers_reject_bools_strings_non_finite_values_and_arrays(value):
    text = message(value, Field("number", low=0.0, high=10.0, unit="m"))
    assert text.startswith("key 'x' must be a finite number in [0, 10] m, got ")


def test_two_sided_bounds_are_a_range_one_sided_bounds_part_of_the_kind():
    both = Field("number", low=0.0, high=10.0, unit="m")
    assert message(20, both) == "key 'x' = 20 is out of range: allowed [0, 10] m"
    assert message(-1.0, both) == "key 'x' = -1.0 is out of range: allowed [0, 10] m"
    half_open = Field("number", low=0.5, high=1.0, high_open=True)
    assert message(1.0, half_open) == "key 'x' = 1.0 is out of range: allowed [0.5, 1)"
    assert check(0.5, half_open, "x") == 0.5
    positive = Field("number", low=0.0, low_open=True, unit="s")
    assert message(-0.01, positive) == "key 'x' must be a finite positive number, got -0.01"
    assert message(0, positive) == "key 'x' must be a finite positive number, got 0"
    at_least = Field("number", low=1.0, unit="s")
    assert message(0.1, at_least) == "key 'x' must be a finite number >= 1 s, got 0.1"
    below = Field("number", high=3.0, high_open=True)
    assert message(3, below) == "key 'x' must be a finite number < 3, got 3"
    assert check(-1e300, below, "x") == -1e300


def test_integers_beyond_the_float_range_are_out_of_range_not_an_overflow():
    huge = 10**400
    text = message(huge, Field("number", low=0.0, high=10.0))
    assert "is out of range: allowed [0, 10]" in text and "about 401 digits" in text
    text = message(-huge, Field("number"))
    assert "is out of range" in text and "float range" in text
    assert "is out of range: allowed integers [1, 1000]" in message(
        huge, Field("integer", low=1, high=1000)
    )
    assert "float range" in message(huge, Field("integer", low=0))
    assert check(2**80, Field("integer", low=0), "x") == 2**80
    assert check(10**300, Field("number"), "x") == 1e300


def test_integers_accept_integral_floats_and_numpy_integers_and_return_ints():
    spec = Field("integer", low=0, high=63)
    for value, expected in ((3, 3), (3.0, 3), (np.int32(5), 5), (np.float64(6.0), 6)):
        out = check(value, spec, "x")
        assert type(out) is int and out == expected
    for value in (1.5, True, np.bool_(True), "3", float("nan"), float("inf"), None):
        assert message(value, spec).startswith("key 'x' must be an integer in [0, 63], got ")
    assert message(64, spec) == "key 'x' = 64 is out of range: allowed integers [0, 63]"
    assert message(-1, Field("integer", low=0)) == "key 'x' must be a non-negative integer, got -1"
    assert message(0, Field("integer", low=1)) == "key 'x' must be a positive integer, got 0"
    assert message(1, Field("integer", low=2)) == "key 'x' must be an integer >= 2, got 1"
    assert message(0, Field("integer", low=0, low_open=True)).startswith(
        "key 'x' must be a positive integer"
    )


# ------------------------------------------------- bools, choices, strings
def test_bools_are_only_true_and_false():
    spec = Field("bool")
    assert check(np.bool_(True), spec, "x") is True and check(False, spec, "x") is False
    for value in (0, 1, 1.0, "true", None):
        assert message(value, spec).startswith("key 'x' must be true or false, got ")


def test_choices_match_type_and_value_and_an_array_is_not_a_choice():
    spec = Field("choice", choices=("straight", "curved"))
    assert check(np.str_("curved"), spec, "x") == "curved"
    assert type(check(np.str_("curved"), spec, "x")) is str
    expected = "key 'x' = 'oval' is not allowed: one of 'straight', 'curved'"
    assert message("oval", spec) == expected
    text = message(np.array(["straight", "curved"]), spec)
    assert text.startswith("key 'x' = array(") and "is not allowed: one of" in text
    one = Field("choice", choices=(1,))
    assert check(np.int64(1), one, "x") == 1
    for value in (True, 1.0, "1", [1]):
        assert message(value, one).endswith("is not allowed: only 1")


def test_strings_with_length_pattern_and_non_empty_rules():
    spec = Field("string", max_length=5, pattern=re.compile("[a-z]+"), pattern_doc="a-z only")
    assert check("abc", spec, "x") == "abc"
    assert message("abcdef", spec) == (
        "key 'x' must be a string of at most 5 characters (a-z only), got 'abcdef' (6 characters)"
    )
    assert message("AB", spec).endswith("got 'AB'")
    assert message(3, spec).endswith("got 3")
    assert (
        message("", Field("string", non_empty=True)) == "key 'x' must be a non-empty string, got ''"
    )


# -------------------------------------------------------------------- lists
def test_number_lists_convert_tuples_and_1d_arrays_and_reject_strings_and_dicts():
    spec = Field("numbers", low=-20.0, high=20.0, unit="m", non_empty=True, unique=True)
    assert check((0, np.float32(-1.5)), spec, "h") == [0.0, -1.5]
    assert check(np.array([1.0, 2.0]), spec, "h") == [1.0, 2.0]
    allowed = "a non-empty list of distinct finite numbers in [-20, 20] m"
    assert message("ab", spec, "h") == f"key 'h' must be {allowed}, got 'ab'"
    assert message({0: 1.0}, spec, "h") == f"key 'h' must be {allowed}, got {{0: 1.0}}"
    assert message(np.zeros((2, 2)), spec, "h").startswith(f"key 'h' must be {allowed}, got array(")
    assert message([], spec, "h") == f"key 'h' must be {allowed}, got an empty list"
    assert message([1.0, "a"], spec, "h") == (
        "key 'h[1]' must be a finite number in [-20, 20] m, got 'a'"
    )
    assert message([0.0, 30.0], spec, "h") == (
        "key 'h[1]' = 30.0 is out of range: allowed [-20, 20] m"
    )
    assert message([0, -0.0], spec, "h") == (
        "key 'h' has the entry 0.0 twice (at [0] and [1]); entries must be distinct"
    )
    assert check(None, Field("numbers", optional=True), "h") is None
    assert message([1.0] * 4, Field("numbers", max_length=3), "h").endswith("a list of 4 entries")


def test_integer_lists():
    spec = Field("integers", low=0, non_empty=True, unique=True)
    assert check((np.int64(3), 4.0), spec, "s") == [3, 4]
    assert spec.allowed() == "a non-empty list of distinct non-negative integers"
    assert message([1, 1.5], spec, "s") == "key 's[1]' must be a non-negative integer, got 1.5"
    assert message([2, 2], spec, "s").startswith("key 's' has the entry 2 twice")
    assert message([], spec, "s").endswith("got an empty list")
    assert message(3, spec, "s") == f"key 's' must be {spec.allowed()}, got 3"


def test_string_lists():
    spec = Field("strings", non_empty=True)
    assert check(("a", np.str_("b")), spec, "k") == ["a", "b"]
    assert message("G29", spec, "k") == (
        "key 'k' must be a non-empty list of non-empty strings, got 'G29'"
    )
    assert message(["a", ""], spec, "k") == "key 'k[1]' must be a non-empty string, got ''"
    assert message(["a", "a"], Field("strings", unique=True), "k").startswith(
        "key 'k' has the entry 'a' twice"
    )


# ----------------------------------------------------------------- mappings
SPEC = schema(
    {
        "a": Field("number", 1.0, low=0.0, high=2.0),
        "b": Field("integer", REQUIRED, low=0),
        "c": Field("string", ABSENT),
        "d": Field("numbers", [1.0, 2.0]),
        "g": {"x": Field("bool", False), "y": Field("choice", "p", choices=("p", "q"))},
    }
)


def test_mappings_fill_defaults_omit_absent_keys_and_build_fresh_values():
    out = check({"b": 3}, SPEC)
    assert out == {"a": 1.0, "b": 3, "d": [1.0, 2.0], "g": {"x": False, "y": "p"}}
    out["d"].append(3.0)
    assert check({"b": 3}, SPEC)["d"] == [1.0, 2.0]
    given = {"b": 3, "c": "z", "g": {"y": "q"}}
    assert check(given, SPEC)["c"] == "z" and check(given, SPEC)["g"] == {"x": False, "y": "q"}
    assert given == {"b": 3, "c": "z", "g": {"y": "q"}}


def test_mapping_errors_name_the_key_path():
    assert message({}, SPEC, "") == "key 'b' is missing"
    assert message({"b": 1, "zz": 2}, SPEC, "") == (
        "unknown key 'zz' (allowed keys here: a, b, c, d, g)"
    )
    assert message({"b": 1, "g": {"z": 1}}, SPEC, "") == (
        "unknown key 'g.z' (allowed keys here: x, y)"
    )
    assert message({"b": 1, 7: 2}, SPEC, "").startswith("unknown key '[7]'")
    assert message({"b": 1, "g": {"": 2}}, SPEC, "").startswith("unknown key 'g['']'")
    assert message({"b": 1, "a.b": 2}, SPEC, "").startswith("unknown key '['a.b']'")
    assert message("track", SPEC, "") == "doc must be a mapping (JSON object), got 'track'"
    assert message({"b": 1, "g": [1]}, SPEC, "") == (
        "key 'g' must be a mapping (JSON object), got [1]"
    )


def test_mappings_with_free_keys():
    spec = Field("mapping", each=Field("number", low=0.0), optional=True)
    assert check({"k": np.float32(0.5)}, spec, "m") == {"k": 0.5}
    assert check(None, spec, "m") is None
    assert message({"k": -1}, spec, "m") == "key 'm.k' must be a finite non-negative number, got -1"
    assert message({1: 1.0}, spec, "m") == "key 'm' has a key that is not a string: 1"
    assert message("P07", spec, "m").startswith("key 'm' must be a mapping (JSON object) of string")


# ---------------------------------------------------------------- free JSON
def test_free_json_converts_numpy_and_tuples_and_rejects_what_json_cannot_hold():
    out = check({"a": (1, np.float32(0.5)), "b": np.arange(2), "c": np.bool_(True)}, ANY_JSON, "j")
    assert out == {"a": [1, 0.5], "b": [0, 1], "c": True}
    assert json.loads(json.dumps(out)) == out
    assert message({"a": float("nan")}, ANY_JSON, "j").startswith("key 'j.a' must be JSON data")
    assert message({"a": [object()]}, ANY_JSON, "j").startswith("key 'j.a[0]' must be JSON data")
    assert message({1: 2}, ANY_JSON, "j") == "key 'j' has a key that is not a string: 1"
    assert message({"a": 10**400}, ANY_JSON, "j").startswith("key 'j.a' must be JSON data")


def test_free_json_caps_the_depth_instead_of_a_recursion_error():
    deep = 1.0
    for _ in range(10_000):
        deep = [deep]
    assert message({"a": deep}, ANY_JSON, "j") == "key 'j.a" + "[0]" * 15 + (
        "' is nested more than 16 levels deep"
    )
    shallow = Field("json", max_depth=2)
    assert check({"a": [1]}, shallow, "j") == {"a": [1]}
    assert "nested more than 2 levels" in message({"a": [[1]]}, shallow, "j")
    text = message(deep, Field("number"))
    assert text.startswith("key 'x' must be a finite number, got [[[") and len(text) < 200


def test_free_json_size_cap():
    spec = Field("json", max_length=3)
    assert check([1, 2], spec, "j") == [1, 2]
    assert "more than 3 values" in message([1, 2, 3], spec, "j")


# --------------------------------------------------------------- the specs
def test_allowed_texts():
    assert Field("number", low=0.0, high=10.0, unit="m").allowed() == (
        "a finite number in [0, 10] m"
    )
    assert Field("number", low=0.0, low_open=True).allowed() == "a finite positive number"
    assert Field("integer", low=0).allowed() == "a non-negative integer"
    assert Field("numbers", low=0.0, high=1.0, optional=True).allowed() == (
        "a list of finite numbers in [0, 1] or null"
    )
    assert Field("choice", choices=("a", "b")).allowed() == "one of 'a', 'b'"
    assert version(1).allowed() == "only 1"
    assert "16 levels deep" in ANY_JSON.allowed()
    assert [p for p, _ in SPEC.leaves()] == ["a", "b", "c", "d", "g.x", "g.y"]


def test_hints_follow_every_message_about_the_value():
    spec = schema({"v": version(1)})
    assert message({"v": 2}, spec, "") == (
        "key 'v' = 2 is not allowed: only 1 (the version this hasa_env reads)"
    )
    assert message({}, spec, "") == "key 'v' is missing"


@pytest.mark.parametrize(
    "kwargs",
    [
        {"kind": "float"},
        {"kind": "mapping"},
        {"kind": "number", "fields": {}},
        {"kind": "mapping", "fields": {}, "each": ANY_JSON},
        {"kind": "choice"},
        {"kind": "number", "choices": (1,)},
        {"kind": "number", "low": 2.0, "high": 1.0},
    ],
)
def test_inconsistent_specs_are_refused_when_written(kwargs):
    with pytest.raises(ValueError, match="Field"):
        Field(**kwargs)


def test_show_is_short_and_never_raises():
    class Hostile:
        def __repr__(self):
            raise RuntimeError("no")

    assert show(Hostile()).startswith("<Hostile")
    assert len(show("x" * 10_000)) < 80
    assert show(-(10**5000)) == "<an integer of about 5001 digits>"
    assert show(0.1) == "0.1"


# ----------------------------------------------------- the env configuration
def test_config_regressions_found_by_fuzzing():
    with pytest.raises(ConfigError, match=r"'noise.camera' = <an integer .* out of range"):
        make_config({"noise": {"camera": 10**400}})
    with pytest.raises(ConfigError, match=r"'track' = array\(.*is not allowed: one of"):
        make_config({"track": np.array(["curved", "straight"])})
    for env_id in ("hasa_env/LaneKeeping-v0", "hasa_env/LaneKeepingCurved-v0"):
        with pytest.raises(ConfigError, match=r"^config must be a mapping \(JSON object\)"):
            gym.make(env_id, config="track")
    with pytest.raises(ConfigError, match=r"^config must be a mapping"):
        make_config(["track"])
    cfg = make_config({"noise": {"camera": np.float32(0.5)}, "action_repeat": np.int64(2)})
    assert cfg["noise"]["camera"] == 0.5 and type(cfg["noise"]["camera"]) is float
    assert cfg["action_repeat"] == 2 and type(cfg["action_repeat"]) is int
    with pytest.raises(ConfigError, match=r"'markings.hypotheses' must be a non-empty list"):
        make_config({"markings": {"hypotheses": {"a": 1.0}}})
    with pytest.raises(ConfigError, match=r"'markings.hypotheses' has the entry 0.0 twice"):
        make_config({"markings": {"hypotheses": [0, 0]}})
    with pytest.raises(
        ConfigError, match=r"'initial_state.speed' = 100.0 m/s is above 'vehicle.max_speed'"
    ):
        make_config({"initial_state": {"speed": 100.0}})
    with pytest.raises(ConfigError, match=r"'initial_state.speed' = 15.0 m/s is above"):
        make_config({"vehicle": {"max_speed": 10.0}})
    deep = 0.1
    for _ in range(10_000):
        deep = {"a": deep}
    with pytest.raises(ConfigError, match=r"^config key 'noise.camera' must be a finite number"):
        make_config({"noise": {"camera": deep}})
    assert make_config({"initial_state": {"speed": 60.0}})["initial_state"]["speed"] == 60.0


HOSTILE = st.one_of(
    st.integers(min_value=-(10**400), max_value=10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(width=32).map(np.float32),
    st.integers(min_value=-(2**63), max_value=2**63 - 1).map(np.int64),
    st.booleans().map(np.bool_),
    st.lists(st.floats(-30, 30), max_size=3).map(np.array),
    st.text(max_size=8),
    st.sampled_from(["straight", "curved", "physical", "both", "driver"]),
    st.none(),
    st.booleans(),
    st.lists(st.one_of(st.floats(-30, 30), st.integers(-3, 3), st.text(max_size=2)), max_size=4),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


def _valid(spec: Field) -> st.SearchStrategy:
    """A value the field accepts on its own (so that some fuzzed configs pass)."""
    if spec.kind == "choice":
        return st.sampled_from(spec.choices)
    if spec.kind == "bool":
        return st.booleans()
    if spec.kind == "integer":
        return st.integers(int(spec.low), int(spec.high))
    if spec.kind == "number":
        return st.floats(spec.low, spec.high, exclude_min=spec.low_open)
    return st.just(spec.default)


@st.composite
def documents(draw, spec: Field = _SCHEMA, depth: int = 0, hostility: int | None = None):
    """A partial config built from the schema's keys; ``hostility`` in 20ths: how often a value
    is hostile (drawn once per document: 0 makes a config that mostly passes)."""
    if hostility is None:
        hostility = draw(st.sampled_from([0, 0, 1, 6]))
    out = {}
    assert spec.fields is not None
    for key, sub in spec.fields.items():
        if not draw(st.booleans()):
            continue
        hostile = draw(st.integers(0, 19)) < hostility
        if hostile:
            out[key] = draw(HOSTILE)
        elif sub.fields is not None:
            out[key] = draw(documents(sub, depth + 1, hostility)) if depth < 3 else {}
        else:
            out[key] = draw(_valid(sub))
    if draw(st.integers(0, 19)) < hostility:
        out[draw(st.text(max_size=5))] = draw(HOSTILE)
    return out


def _key_paths(document, prefix=""):
    for key, value in document.items():
        path = f"{prefix}{key}"
        yield path
        if isinstance(value, dict):
            yield from _key_paths(value, path + ".")


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(documents())
def test_fuzzed_configs_are_accepted_and_stable_or_refused_naming_a_key(document):
    try:
        cfg = make_config(document)
    except ConfigError as exc:
        text = str(exc)
        named = re.match(r"(unknown )?config keys? '(.*?)'( =| is| must| has| and|$| \()", text)
        assert named, text
        path = named.group(2)
        known = set(_key_paths(document)) | {p for p, _ in _SCHEMA.leaves()}
        assert (
            path in known or re.sub(r"\[\d+\]$", "", path) in known or "['" in path or '["' in path
        ), text
        return
    assert make_config(cfg) == cfg
    assert json.loads(json.dumps(cfg, allow_nan=False)) == cfg
    for path, spec in _SCHEMA.leaves():
        value = cfg
        for part in path.split("."):
            value = value[part]
        if spec.kind == "number":
            assert type(value) is float
        elif spec.kind == "integer":
            assert type(value) is int


def test_default_config_passes_its_own_schema():
    assert make_config(default_config()) == default_config()


# ------------------------------------------------------ recording sidecars
@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    from hasa_env.recording import RecordingWrapper

    directory = tmp_path_factory.mktemp("rec")
    env = RecordingWrapper(gym.make("hasa_env/LaneKeeping-v0"), directory, metadata={"p": "P07"})
    env.reset(seed=1, options={"speed": 14.0})
    for _ in range(3):
        env.step(np.zeros(2, dtype=np.float32))
    env.close()
    return env.path


def _deep(levels: int, leaf: object = 0) -> object:
    for _ in range(levels):
        leaf = [leaf]
    return leaf


@pytest.mark.parametrize(
    ("edit", "column", "text"),
    [
        ({"metadata": "P07"}, "metadata", "must be a mapping (JSON object), got 'P07'"),
        ({"metadata": None}, "metadata", "must be a mapping (JSON object), got None"),
        (
            {"metadata": {"a": _deep(500)}},
            "metadata.a" + "[0]" * 16,
            "is nested more than 16 levels deep",
        ),
        ({"reset_options": [1, 2]}, "reset_options", "must be a mapping (JSON object)"),
        ({"seed": "7"}, "seed", "must be a non-negative integer or null, got '7'"),
        ({"seed": -1}, "seed", "must be a non-negative integer or null, got -1"),
        ({"steps": 2.5}, "steps", "must be a non-negative integer or null, got 2.5"),
        ({"end_reason": "crashed"}, "end_reason", "= 'crashed' is not allowed: one of"),
        ({"env_id": 3}, "env_id", "must be a string or null, got 3"),
        ({"versions": {"numpy": 2}}, "versions.numpy", "must be a string, got 2"),
        ({"columns": "step,time"}, "columns", "must be a list of non-empty strings"),
        ({"config": "default"}, "config", "must be a mapping (JSON object), got 'default'"),
        ({"driver": "x"}, "driver", "unknown sidecar field 'driver' (allowed keys here: columns"),
        ({"complete": 1}, "complete", "must be true or false, got 1"),
    ],
)
def test_wrong_typed_sidecar_fields_are_recording_errors_naming_the_field(
    recorded, tmp_path, edit, column, text
):
    from hasa_env.recording import RecordingError, load_recording

    meta = json.loads(recorded.with_suffix(".json").read_text())
    meta.update(edit)
    csv = tmp_path / recorded.name
    csv.write_text(recorded.read_text())
    csv.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(RecordingError) as info:
        load_recording(csv)
    assert info.value.column == column and text in str(info.value)
    assert str(csv.with_suffix(".json")) in str(info.value)


def test_unreadable_sidecar_json_is_a_recording_error(recorded, tmp_path):
    from hasa_env.recording import RecordingError, load_recording

    csv = tmp_path / recorded.name
    csv.write_text(recorded.read_text())
    side = csv.with_suffix(".json")
    for text in ("[" * 100_000 + "]" * 100_000, '{"seed": ' + "9" * 5000 + "}"):
        side.write_text(text)
        with pytest.raises(RecordingError, match="sidecar cannot be read as JSON"):
            load_recording(csv)


def test_a_loaded_sidecar_keeps_its_fields_and_converts_nothing_it_does_not_know(recorded):
    from hasa_env.recording import load_recording

    raw = json.loads(recorded.with_suffix(".json").read_text())
    meta = load_recording(recorded).meta
    assert set(meta) == set(raw) and meta["metadata"] == {"p": "P07"}
    assert meta["reset_options"] == {"speed": 14.0} and meta["config"] == raw["config"]
    assert "seed_sequence_entropy" in meta and meta["seed"] == 1


def test_writer_checks_run_on_the_validator():
    from hasa_env.recording.format import check_json_able, check_seed

    assert check_json_able("metadata", {"a": (np.float32(0.5), np.int64(2))}) == {"a": [0.5, 2]}
    with pytest.raises(ValueError, match=r"^metadata.a\[0\] must be JSON data"):
        check_json_able("metadata", {"a": [float("nan")]})
    with pytest.raises(ValueError, match="nested more than 16 levels"):
        check_json_able("metadata", {"a": _deep(5000)})
    assert check_seed(np.int64(3), "seed") == 3
    with pytest.raises(ValueError, match=r"^seed must be a non-negative integer, got True"):
        check_seed(True, "seed")


# ------------------------------------------------------- protocol settings
def test_protocol_settings_convert_numpy_values_and_name_the_setting(tmp_path):
    from benchmarks.protocol import BenchmarkError, ProtocolConfig

    config = ProtocolConfig(
        drivers=np.int64(3), noise={"camera": np.float32(0.25)}, seeds=np.arange(2)
    )
    assert type(config.drivers) is int and config.noise == {"camera": 0.25}
    assert config.seeds == (0, 1) and type(config.seeds[0]) is int
    assert ProtocolConfig(recordings=tmp_path).recordings == str(tmp_path)
    for kwargs, text in (
        ({"noise": "camera"}, "protocol setting 'noise' must be a mapping (JSON object)"),
        ({"noise": {"camera": -1.0}}, "'noise.camera' must be a finite non-negative number"),
        ({"runs": 10**400}, "'runs' = <an integer of about 401 digits> is out of range"),
        ({"weight_threshold": 1.0}, "'weight_threshold' = 1.0 is out of range: allowed [0.5, 1)"),
        (
            {"track": np.array(["curved"])},
            "'track' = array(['curved'], dtype='<U6') is not allowed",
        ),
        ({"seeds": (0, 1.5)}, "'seeds[1]' must be a non-negative integer, got 1.5"),
        ({"seeds": (3, 3)}, "'seeds' has the entry 3 twice (at [0] and [1])"),
        ({"seeds": ()}, "'seeds' must be a non-empty list of distinct non-negative integers"),
        ({"seeds": "012"}, "'seeds' must be a non-empty list of distinct non-negative integers"),
    ):
        with pytest.raises(BenchmarkError) as info:
            ProtocolConfig(**kwargs)
        assert text in str(info.value)


# ---------------------------------------------------------- drive settings
def test_drive_settings_convert_numpy_values_and_refuse_bad_ones_early(tmp_path):
    from hasa_env.session.settings import DriveSettings

    s = DriveSettings(participant="P07", runs=np.int64(2), bias=np.float32(-1.5), output=tmp_path)
    assert type(s.runs) is int and s.bias == -1.5 and s.output == tmp_path
    for kwargs, text in (
        ({"bias": 25.0}, "drive setting 'bias' = 25.0 is out of range: allowed [-20, 20] m"),
        (
            {"seconds": float("nan")},
            "drive setting 'seconds' must be a finite number in (0, 1e+06]",
        ),
        ({"seed": -1}, "drive setting 'seed' must be a non-negative integer or null, got -1"),
        ({"fsync": "yes"}, "drive setting 'fsync' must be true or false, got 'yes'"),
        ({"config": "curved"}, "drive setting 'config' must be a mapping (JSON object)"),
        ({"config": {"noise": {"cam": 1}}}, "unknown config key 'noise.cam'"),
        ({"participant": "é"}, "drive setting 'participant' must be a string of at most 64"),
    ):
        with pytest.raises(ValueError) as info:
            DriveSettings(**{"participant": "P07", "output": tmp_path, **kwargs})
        assert text in str(info.value)


# ---------------------------------------- dataclasses and infinite numbers
def test_infinite_numbers_when_the_field_allows_them():
    spec = Field("number", low=0.0, low_open=True, infinite=True, unit="m/s^2")
    assert check(float("inf"), spec, "x") == float("inf")
    assert message(float("nan"), spec) == "key 'x' must be a positive number or inf, got nan"
    assert message(-float("inf"), spec) == "key 'x' must be a positive number or inf, got -inf"
    capped = Field("number", low=0.0, high=10.0, infinite=True)
    assert message(float("inf"), capped) == "key 'x' = inf is out of range: allowed [0, 10]"
    assert capped.allowed() == "a number in [0, 10] (infinities included)"


def test_validate_fields_stores_converted_values_also_on_frozen_dataclasses():
    import dataclasses

    from hasa_env.validation import validate_fields

    @dataclasses.dataclass(frozen=True)
    class Settings:
        runs: int = 1
        gain: float = 0.5

        def __post_init__(self):
            validate_fields(
                self,
                {"runs": Field("integer", low=1), "gain": Field("number", low=0.0, high=1.0)},
                describe=lambda p: f"Settings.{p}",
                error=lambda p, m: ValueError(m),
            )

    s = Settings(runs=np.int64(3), gain=np.float32(0.25))
    assert type(s.runs) is int and s.runs == 3 and type(s.gain) is float
    with pytest.raises(ValueError, match=r"^Settings.runs must be a positive integer, got 0$"):
        Settings(runs=0)


# The specs FilterSettings (estimators/settings.py) and TwoPointParams / SpeedProfile /
# MotorParams (hasa_env/drivers) will be migrated to: they must accept what the classes accept and
# refuse what they refuse (both checked here against the classes' own validation).
def _positive(unit: str = "") -> Field:
    return Field("number", unit=unit, low=0.0, low_open=True)


def _non_negative(unit: str = "") -> Field:
    return Field("number", unit=unit, low=0.0)


SPEED_PROFILE = schema(
    {
        "target_speed": Field("number", unit="m/s", low=0.0, high=150.0, optional=True),
        "start_time": _non_negative("s"),
        "ramp_rate": _positive("m/s^2"),
        "gain": _positive("1/s"),
        "max_lateral_acceleration": Field(
            "number", unit="m/s^2", low=0.0, low_open=True, infinite=True
        ),
        "comfortable_deceleration": _positive("m/s^2"),
        "max_acceleration": _positive("m/s^2"),
    }
)
MOTOR_PARAMS = schema(
    {
        "command_std": Field("number", unit="rad", low=0.0, high=0.1),
        "command_time_constant": Field("number", unit="s", low=0.0, high=10.0),
        "broadband_std": Field("number", unit="rad", low=0.0, high=0.05),
        "broadband_time_constant": Field("number", unit="s", low=0.0, high=10.0),
        "tremor_std": Field("number", unit="rad", low=0.0, high=0.05),
        "tremor_frequency": Field("number", unit="Hz", low=0.5, high=40.0),
        "tremor_damping": Field("number", low=0.0, high=1.0, low_open=True),
        "signal_dependent_gain": Field("number", unit="s", low=0.0, high=1.0),
        "steering_ratio": Field("number", low=1.0, high=100.0),
        "wheel_resolution": Field("number", unit="rad", low=0.0, high=0.1),
    }
)
DRIVER_PARAMS = schema(
    {
        "name": Field("string"),
        **{k: _positive("s") for k in ("near_time", "far_time")},
        **{k: Field("number") for k in ("near_gain", "far_gain", "integral_gain")},
        "reference_speed": _positive("m/s"),
        "speed_exponent": Field("number"),
        "delay": _non_negative("s"),
        "neuromuscular_frequency": _positive("rad/s"),
        "neuromuscular_damping": _positive(),
        "noise_std": _non_negative("rad"),
        "noise_time_constant": _non_negative("s"),
        "speed": SPEED_PROFILE,
        "max_steering": _positive("rad"),
        "motor": MOTOR_PARAMS,
    }
)


def _accepts(spec: Field, values: dict) -> bool:
    """Whether ``spec`` accepts ``values``, restricted to the spec's keys (a field the class
    gains later does not make the comparison fail)."""

    def restrict(spec: Field, values: dict) -> dict:
        assert spec.fields is not None
        return {
            k: restrict(f, values[k]) if f.fields is not None else values[k]
            for k, f in spec.fields.items()
        }

    try:
        check(restrict(spec, values), spec)
    except Bad:
        return False
    return True


def _constructs(build) -> bool:
    try:
        build()
    except ValueError:
        return False
    return True


@pytest.mark.parametrize(
    ("name", "value", "ok"),
    [
        ("speed_noise_std", 0.0, False),
        ("speed_noise_std", 0.1, True),
        ("speed_noise_std", np.float32(0.1), True),
        ("camera_noise_std", float("nan"), False),
        ("bias_std", -1e-3, False),
        ("bias_std", 0.0, True),
        ("memory_std", True, False),
        ("initial_lateral_std", None, True),
        ("initial_lateral_std", 0.2, True),
        ("prune_threshold", 1.0, False),
        ("prune_threshold", 0.5, True),
        ("steering_ratio", float("inf"), False),
        ("innovation_gate", float("inf"), True),
        ("innovation_gate", 0.0, False),
        ("max_acceleration", float("nan"), False),
        ("min_speed", float("inf"), False),
        ("min_speed", 0.0, True),
        ("evidence_checks", 1, False),
        ("forgetting_time", float("inf"), True),
        ("forgetting_time", 0.0, False),
        ("mismatch_model_error", 1.0, False),
        ("decision_threshold", 1.0, False),
        ("decision_threshold", 0.95, True),
        ("weight_floor", 0.01, False),
    ],
)
def test_filter_settings_run_on_the_shared_validator(name, value, ok):
    from estimators.settings import FilterSettings

    assert _constructs(lambda: FilterSettings(**{name: value})) == ok
    if not ok:
        with pytest.raises(ValueError, match=rf"^FilterSettings\.{name} "):
            FilterSettings(**{name: value})


@pytest.mark.parametrize(
    ("where", "name", "value"),
    [
        ("driver", "near_time", 0.0),
        ("driver", "near_gain", -0.1),
        ("driver", "speed_exponent", float("inf")),
        ("driver", "delay", -0.01),
        ("driver", "noise_std", 0.0),
        ("speed", "target_speed", 200.0),
        ("speed", "target_speed", None),
        ("speed", "max_lateral_acceleration", float("inf")),
        ("speed", "max_lateral_acceleration", 0.0),
        ("speed", "start_time", float("nan")),
        ("speed", "ramp_rate", 2.0),
        ("motor", "tremor_damping", 0.0),
        ("motor", "tremor_damping", 1.0),
        ("motor", "steering_ratio", 0.5),
        ("motor", "wheel_resolution", float("inf")),
    ],
)
def test_the_driver_params_spec_agrees_with_driver_params(where, name, value):
    import dataclasses

    from hasa_env.drivers.base import SpeedProfile
    from hasa_env.drivers.motor import MotorParams
    from hasa_env.drivers.two_point import TwoPointParams

    values = dataclasses.asdict(TwoPointParams())
    assert _accepts(DRIVER_PARAMS, values)
    part = {"speed": SpeedProfile, "motor": MotorParams}.get(where)
    if part is not None:
        values[where][name] = value
        accepted = _constructs(lambda: TwoPointParams(**{where: part(**{name: value})}))
    else:
        values[name] = value
        accepted = _constructs(lambda: TwoPointParams(**{name: value}))
    assert _accepts(DRIVER_PARAMS, values) == accepted


# --------------------------------------------- model files and calibrations
@pytest.mark.parametrize(
    ("edit", "text"),
    [
        (lambda d: d.update(dt=10**400), "field 'dt' = <an integer of about 401 digits> is out"),
        (lambda d: d.update(features="near"), "field 'features' must be a mapping (JSON object)"),
        (lambda d: d.update(parameters=[0.1, 0.2]), "field 'parameters' must be a mapping"),
        (lambda d: d.update(type=np.array(["two_point"])), "field 'type' = array(['two_point']"),
        (lambda d: d["structure"].update(parameters={}), "field 'structure' is not valid"),
        (lambda d: d["structure"].update(nb=_deep(500)), "'structure.nb[0]"),
        (lambda d: d["features"].update(steering_signal="wheel"), "'features.steering_signal' ="),
    ],
)
def test_hostile_model_documents_are_model_file_errors(edit, text):
    from hasa_env.steering import GeneralizedModel, ModelFileError, SteeringModel

    document = GeneralizedModel.paper().to_dict()
    edit(document)
    with pytest.raises(ModelFileError, match=r"^m\.json: ") as info:
        SteeringModel.from_dict(document, "m.json")
    assert text in str(info.value)


def test_model_documents_accept_numpy_values():
    from hasa_env.steering import GeneralizedModel, SteeringModel

    model = GeneralizedModel.paper()
    document = model.to_dict()
    document["dt"] = np.float64(document["dt"])
    document["parameters"] = {k: np.float32(v) for k, v in document["parameters"].items()}
    document["features"]["decision_lag"] = np.int64(1)
    again = SteeringModel.from_dict(document, "m.json")
    assert again.dt == model.dt and type(again.decision_lag) is int


@pytest.mark.parametrize(
    ("edit", "field", "text"),
    [
        (lambda d: d.update(device=np.array(["keyboard"])), "device", "is not allowed: one of"),
        (lambda d: d["steering"].update(axis=10**400), "steering.axis", "is out of range"),
        (lambda d: d.update(steering=[0, 1]), "steering", "must be a mapping (JSON object)"),
        (lambda d: d.update(notes=None), "notes", "must be a string, got None"),
        (lambda d: d.update(match_names=["G29", 29]), "match_names[1]", "non-empty string"),
    ],
)
def test_hostile_calibrations_are_calibration_errors(edit, field, text):
    from hasa_env.devices.calibration import (
        CalibrationError,
        parse_calibration,
        shipped_calibration,
    )

    data = shipped_calibration("g29").to_dict()
    edit(data)
    with pytest.raises(CalibrationError) as info:
        parse_calibration(data, "w.json")
    assert info.value.field == field and text in str(info.value)
    assert str(info.value).startswith(f"w.json: field '{field}' ")
