"""Hypothesis fuzzing of what a user hands the envs: configs, reset options, actions.

Single and vector env alike, every input is either accepted (and then it was a
legal input, by the documented rules) or refused with a ``ValueError`` (a
``ConfigError`` for configs) whose message names what is wrong; never another
exception, and a refused reset leaves the env exactly as it was. Bounded
(max_examples) so the suite stays quick.
"""

from __future__ import annotations

import math
import os
import re
import warnings

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hasa_env
from hasa_env import ConfigError
from hasa_env.sim.setup import RESET_OPTIONS

EXAMPLES = int(os.environ.get("HASA_FUZZ_EXAMPLES", "120"))
"""Examples per fuzz test (HASA_FUZZ_EXAMPLES=5000 for a long local run)."""
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])

_DTYPES = ["float64", "float32", "float16", "int64", "int8", "uint8", "bool", "complex128",
           "datetime64[D]", "timedelta64[s]", "U3", "S2", "object"]  # fmt: skip

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**400), 10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.complex_numbers(max_magnitude=1e3),
    st.text(max_size=6),
    st.binary(max_size=4),
    st.sampled_from(["0.1", "1e308", "nan", "ab", "", "١"]),
    st.builds(np.float32, st.floats(-2, 2, width=32)),
    st.builds(np.int64, st.integers(-5, 5)),
    st.builds(np.bool_, st.booleans()),
    st.just(np.datetime64("2020-01-01")),
    st.just(object()),
)


@st.composite
def arrays(draw, shape=None):
    """A numpy array of any dtype (possibly masked), of ``shape`` or a small random one."""
    dtype = draw(st.sampled_from(_DTYPES))
    if shape is None:
        shape = tuple(draw(st.lists(st.integers(0, 3), max_size=3)))
    size = int(np.prod(shape)) if shape else 1
    if dtype in ("float64", "float32", "float16"):
        values = draw(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=16),
                               min_size=size, max_size=size))  # fmt: skip
    elif dtype in ("int64", "int8", "uint8"):
        values = draw(st.lists(st.integers(0, 100), min_size=size, max_size=size))
    elif dtype == "bool":
        values = draw(st.lists(st.booleans(), min_size=size, max_size=size))
    elif dtype == "complex128":
        values = [complex(0.1, 1.0)] * size
    elif dtype.startswith("datetime"):
        values = ["2020-01-01"] * size
    elif dtype.startswith("timedelta"):
        values = [3] * size
    elif dtype in ("U3", "S2"):
        values = ["0.1"] * size
    else:
        values = [None] * size
    arr = np.array(values, dtype=dtype).reshape(shape)
    if draw(st.booleans()) and arr.dtype.kind in "iuf" and size:
        arr = np.ma.masked_array(arr, mask=np.zeros(shape, bool))
    return arr


hostile = st.one_of(
    scalars,
    arrays(),
    st.lists(scalars, max_size=3),
    st.lists(st.lists(scalars, max_size=2), max_size=2),
    st.dictionaries(st.text(max_size=4), scalars, max_size=2),
    st.tuples(scalars, scalars),
)


def _is_legal_action(action, shape) -> bool:
    """The documented rule: a plain (not masked) array-like of real numbers (not bool) of the
    given shape, every entry finite."""
    if isinstance(action, np.ma.MaskedArray):
        return False
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            arr = np.asarray(action)
    except (ValueError, TypeError, OverflowError):
        return False
    if arr.dtype.kind not in "iuf" or arr.shape != shape:
        return False
    with np.errstate(over="ignore"):
        return bool(np.all(np.isfinite(arr.astype(np.float64))))


legal_actions = st.lists(st.floats(-3, 3), min_size=2, max_size=2)


@pytest.fixture(scope="module")
def single():
    return hasa_env.LaneKeepingEnv()


@pytest.fixture(scope="module")
def vector():
    return gym.make_vec(
        "hasa_env/LaneKeeping-v0", num_envs=3, vectorization_mode="vector_entry_point"
    )


# ------------------------------------------------------------------- actions
@FUZZ
@given(action=st.one_of(hostile, legal_actions, arrays(shape=(2,))))
def test_fuzzed_actions_single(single, action):
    single.reset(seed=0)
    legal = _is_legal_action(action, (2,))
    try:
        _, reward, _, _, info = single.step(action)
    except ValueError as exc:
        assert not legal, f"refused a legal action {action!r}: {exc}"
        assert re.match(r"action (must|has)", str(exc)), str(exc)
        return
    assert legal, f"accepted {action!r}"
    assert math.isfinite(reward) and math.isfinite(info["steering"])


@FUZZ
@given(
    actions=st.one_of(
        hostile, arrays(shape=(3, 2)), st.lists(legal_actions, min_size=3, max_size=3)
    )
)
def test_fuzzed_actions_vector(vector, actions):
    vector.reset(seed=0)
    legal = _is_legal_action(actions, (3, 2))
    try:
        _, rewards, _, _, _ = vector.step(actions)
    except ValueError as exc:
        assert not legal, f"refused legal actions {actions!r}: {exc}"
        assert re.match(r"actions (must|has)", str(exc)), str(exc)
        return
    assert legal, f"accepted {actions!r}"
    assert np.all(np.isfinite(rewards))


# ------------------------------------------------------------- reset options
option_values = st.one_of(scalars, st.floats(-40, 40), st.integers(-2, 3))
options = st.one_of(
    st.none(),
    hostile,
    st.dictionaries(
        st.sampled_from([*RESET_OPTIONS, "colour", "reset_mask"]), option_values, max_size=3
    ),  # fmt: skip
)


def _snapshot(env) -> tuple:
    state = env.unwrapped._car.state
    return (tuple(np.atleast_1d(np.asarray(f, dtype=float)).tolist() for f in state),
            env.unwrapped.np_random.bit_generator.state["state"]["state"]
            if hasattr(env.unwrapped, "np_random") else None)  # fmt: skip


@FUZZ
@given(opts=options)
def test_fuzzed_reset_options_single(single, opts):
    single.reset(seed=5)
    before = _snapshot(single)
    try:
        _, info = single.reset(options=opts)
    except ValueError as exc:
        assert re.match(r"(unknown )?reset option(s)? ", str(exc)), str(exc)
        assert _snapshot(single) == before  # refused: nothing drawn, nothing changed
        return
    assert opts is None or isinstance(opts, dict)
    for key, value in (opts or {}).items():
        assert key in RESET_OPTIONS
        if key in ("lateral_offset", "heading", "speed", "steering"):
            assert info[key] == float(value)


@FUZZ
@given(opts=options)
def test_fuzzed_reset_options_vector(vector, opts):
    vector.reset(seed=5)
    env = vector.unwrapped
    before = ([f.copy() for f in env._car.state], [r.bit_generator.state for r in env._rngs])
    try:
        vector.reset(options=opts)
    except ValueError as exc:
        assert re.match(r"(unknown )?reset (option|options)[ ']", str(exc)), str(exc)
        after = ([f.copy() for f in env._car.state], [r.bit_generator.state for r in env._rngs])
        assert all(np.array_equal(a, b) for a, b in zip(before[0], after[0], strict=True))
        assert before[1] == after[1]
        return
    assert opts is None or isinstance(opts, dict)


def test_a_refused_first_reset_leaves_nothing_to_step():
    env = gym.make_vec(
        "hasa_env/LaneKeeping-v0", num_envs=2, vectorization_mode="vector_entry_point"
    )
    with pytest.raises(ValueError, match="reset option 'bias_index'"):
        env.reset(seed=0, options={"bias_index": 9})
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(np.zeros((2, 2)))
    single = hasa_env.LaneKeepingEnv()
    with pytest.raises(ValueError, match="reset options must be a mapping"):
        single.reset(seed=0, options="abc")
    with pytest.raises(RuntimeError, match="call reset"):
        single.step(np.zeros(2))


def test_a_refused_reset_does_not_change_the_next_episode():
    cfg = {"initial_state": {"lateral_offset_std": 0.5, "speed_std": 1.0}}
    clean = hasa_env.LaneKeepingEnv(config=cfg)
    clean.reset(seed=3)
    expected = clean.reset()[1]
    env = hasa_env.LaneKeepingEnv(config=cfg)
    env.reset(seed=3)
    for bad in ({"bias_index": 7}, {"speed": 1e9}, {"heading": "x"}, "abc", {"colour": 1}):
        with pytest.raises(ValueError):
            env.reset(options=bad)
    assert env.reset()[1] == expected


def test_stepping_past_the_end_warns_once():
    env = hasa_env.LaneKeepingEnv(config={"time_limit": 0.02})
    env.reset(seed=0)
    env.step(np.zeros(2))
    _, _, _, truncated, _ = env.step(np.zeros(2))
    assert truncated
    with pytest.warns(UserWarning, match="after the episode ended"):
        env.step(np.zeros(2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env.step(np.zeros(2))  # once per episode
        env.reset(seed=0)
        env.step(np.zeros(2))  # a new episode: no warning


# ------------------------------------------------------------------- configs
@settings(max_examples=EXAMPLES // 2, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    config=st.one_of(
        hostile,
        st.dictionaries(
            st.sampled_from(["track", "time_limit", "action_repeat", "noise", "markings",
                             "initial_state", "vehicle", "action", "nonsense"]),
            st.one_of(hostile, st.dictionaries(st.sampled_from(["camera", "hypotheses", "speed",
                      "type", "max_speed", "x"]), hostile, max_size=2)),
            max_size=3,
        ),
    ),
    vector_env=st.booleans(),
)  # fmt: skip
def test_fuzzed_configs_are_refused_naming_a_key_or_make_a_working_env(config, vector_env):
    try:
        if vector_env:
            env = gym.make_vec("hasa_env/LaneKeeping-v0", num_envs=2,
                               vectorization_mode="vector_entry_point", config=config)  # fmt: skip
        else:
            env = gym.make("hasa_env/LaneKeeping-v0", config=config)
    except ConfigError as exc:
        assert re.match(r"(unknown )?config( key| must)", str(exc)), str(exc)
        return
    assert config is None or isinstance(config, dict)
    env.reset(seed=0)
    env.step(env.action_space.sample())
    env.close()
