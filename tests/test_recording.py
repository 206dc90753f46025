"""The recording format: round trip, crash safety, replay, validation of corrupt files."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from _recording_files import crash
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hasa_env  # noqa: F401 - registers the ids
from hasa_env.recording import (
    COLUMN_UNITS,
    SCHEMA_VERSION,
    Recording,
    RecordingError,
    RecordingWarning,
    RecordingWrapper,
    compare_recordings,
    load_recording,
    load_recordings,
    replay,
    replay_actions,
    save_recording,
)
from hasa_env.recording.format import MAX_MAGNITUDE
from hasa_env.sim.setup import RECORDING_COLUMNS, recording_row

ENV_ID = "hasa_env/LaneKeeping-v0"


def _frame(rows: list[list]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=list(RECORDING_COLUMNS))


def _record(directory: Path, n_steps: int = 40, seed: int = 0, close: bool = True, **make_kwargs):
    """Record one episode of small random actions; return (wrapper, in-memory rows)."""
    env = RecordingWrapper(gym.make(ENV_ID, **make_kwargs), directory)
    _, info = env.reset(seed=seed)
    rows = [recording_row(0, info, 0.0, False, False)]
    rng = np.random.default_rng(seed)
    for k in range(1, n_steps + 1):
        _, r, te, tr, info = env.step(rng.uniform(-0.05, 0.05, 2).astype(np.float32))
        rows.append(recording_row(k, info, r, te, tr))
        if te or tr:
            break
    if close:
        env.close()
    return env, rows


def test_units_cover_every_column():
    assert list(COLUMN_UNITS) == list(RECORDING_COLUMNS)


# ----------------------------------------------------------------- round trip
configs = st.fixed_dictionaries(
    {
        "track": st.sampled_from(["straight", "curved"]),
        "sim_frequency": st.sampled_from([100.0, 50.0, 30.0, 250.0]),
        "action_repeat": st.integers(1, 3),
        "time_limit": st.sampled_from([0.25, 1.0, 30.0]),
        "initial_state": st.fixed_dictionaries(
            {
                "lateral_offset_std": st.floats(0.0, 0.5),
                "heading_std": st.floats(0.0, 0.05),
                "speed_std": st.floats(0.0, 3.0),
            }
        ),
        "markings": st.fixed_dictionaries(
            {"hypotheses": st.lists(st.floats(-3.0, 3.0), min_size=1, max_size=3, unique=True)}
        ),
        "noise": st.fixed_dictionaries(
            {"camera": st.floats(0.0, 0.5), "block_size": st.sampled_from([1, 7, 1000])}
        ),
        "action": st.fixed_dictionaries({"type": st.sampled_from(["normalized", "physical"])}),
        "observation": st.fixed_dictionaries(
            {"type": st.sampled_from(["sensors", "state", "both"])}
        ),
    }
)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    config=configs,
    seed=st.integers(0, 2**32 - 1),
    n_steps=st.integers(0, 60),
    steer_scale=st.sampled_from([0.01, 0.3, 1.0]),
    bias_option=st.sampled_from([None, "index", "value"]),
)
def test_round_trip_and_replay_are_bit_exact(config, seed, n_steps, steer_scale, bias_option):
    with tempfile.TemporaryDirectory() as tmp:
        env = RecordingWrapper(gym.make(ENV_ID, config=config), tmp, metadata={"synthetic": True})
        options = {"index": {"bias_index": 0}, "value": {"bias": 0.7}, None: None}[bias_option]
        _, info = env.reset(seed=seed, options=options)
        rows = [recording_row(0, info, 0.0, False, False)]
        rng = np.random.default_rng(seed)
        low, high = env.action_space.low, env.action_space.high
        for k in range(1, n_steps + 1):
            action = rng.uniform(low, high) * np.array([steer_scale, 1.0])
            _, r, te, tr, info = env.step(action)
            rows.append(recording_row(k, info, r, te, tr))
            if te or tr:
                break
        env.close()
        rec = load_recording(env.path)
        assert compare_recordings(_frame(rows), rec.data) is None  # bit-exact floats
        assert rec.meta["complete"] and rec.meta["steps"] == len(rows) - 1
        assert rec.seed == seed and rec.meta["reset_options"] == options
        assert rec.meta["metadata"] == {"synthetic": True}
        # replay reproduces everything, true state and (seeded) sensors alike
        assert compare_recordings(rec, replay(rec)) is None
        assert replay_actions(rec).shape == (len(rows) - 1, 2)


# every float a recording may hold: finite, |x| <= MAX_MAGNITUDE (larger is corruption)
finite = st.floats(-MAX_MAGNITUDE, MAX_MAGNITUDE, allow_nan=False, allow_infinity=False)


@settings(max_examples=30, deadline=None)
@given(data=st.data(), n=st.integers(1, 8), action_repeat=st.integers(1, 4))
def test_save_recording_round_trips_any_plausible_float(data, n, action_repeat):
    config = {"action_repeat": action_repeat, "sim_frequency": 60.0}
    columns = {}
    index = data.draw(st.integers(-1, 1))  # drawn once per episode: -1 or a default hypothesis
    for c in RECORDING_COLUMNS:
        if c in ("terminated", "truncated"):  # an episode ends at its last row
            columns[c] = [False] * (n - 1) + [data.draw(st.booleans())]
        elif c == "bias_index":
            columns[c] = [index] * n
        elif c == "bias":
            bias = data.draw(finite) if index == -1 else (0.0, -1.8)[index]
            columns[c] = [bias] * n
        elif c == "speed":  # within [0, vehicle.max_speed]
            columns[c] = data.draw(st.lists(st.floats(0.0, 60.0), min_size=n, max_size=n))
        elif c == "lateral_offset":  # within the reach of a reset and one step
            columns[c] = data.draw(st.lists(st.floats(-30.0, 30.0), min_size=n, max_size=n))
        else:
            columns[c] = data.draw(st.lists(finite, min_size=n, max_size=n))
    columns["step"] = list(range(n))
    columns["time"] = [(k * action_repeat) * (1.0 / 60.0) for k in range(n)]
    frame = pd.DataFrame(columns)[list(RECORDING_COLUMNS[::-1])]  # any column order
    with tempfile.TemporaryDirectory() as tmp:
        path = save_recording(frame, Path(tmp) / "synthetic", {"config": config, "seed": 5})
        assert path.name == "synthetic.csv"
        rec = load_recording(path)
        assert list(rec.data.columns) == list(RECORDING_COLUMNS)
        assert compare_recordings(frame, rec) is None
        assert rec.meta["config"]["action_repeat"] == action_repeat


def test_loaded_dtypes_and_row_zero(tmp_path):
    env, rows = _record(tmp_path, 5)
    rec = load_recording(env.path)
    assert rec.data["step"].dtype == np.int64 and rec.data["bias_index"].dtype == np.int64
    assert rec.data["terminated"].dtype == bool and rec.data["speed"].dtype == np.float64
    row0 = rec.data.iloc[0]
    assert row0["step"] == 0 and row0["time"] == 0.0 and row0["acceleration"] == 0.0
    assert row0["reward"] == 0.0 and not row0["terminated"] and not row0["truncated"]
    np.testing.assert_array_equal(
        replay_actions(rec), rec.data[["steering", "acceleration"]].to_numpy()[1:]
    )


def test_sidecar_fields(tmp_path):
    env, _ = _record(tmp_path, 3)
    meta = json.loads(env.path.with_suffix(".json").read_text())
    assert meta["schema_version"] == SCHEMA_VERSION == 1
    assert meta["env_id"] == ENV_ID and meta["csv"] == "run_000.csv"
    assert meta["config"] == env.unwrapped.config
    assert set(meta["versions"]) >= {"hasa_env", "gymnasium", "numpy", "python"}
    assert meta["columns"] == list(RECORDING_COLUMNS) and meta["units"]["speed"] == "m/s"
    assert meta["complete"] is True and meta["steps"] == 3 and meta["end_reason"] == "stopped"
    assert meta["created"] and meta["finished"]


# --------------------------------------------------------------- wrapper life
def test_episode_end_new_reset_and_close_finalize(tmp_path):
    env = RecordingWrapper(gym.make(ENV_ID, config={"time_limit": 0.05}), tmp_path, prefix="drv")
    env.reset(seed=1)
    for _ in range(5):
        *_, te, tr, _ = env.step(np.zeros(2))
    assert tr and not env.recording
    with pytest.warns(UserWarning, match="not recorded"):
        env.step(np.zeros(2))
    env.reset(seed=2)
    env.step(np.zeros(2))
    env.reset()  # finalizes drv_001 as stopped
    env.close()
    env.close()  # idempotent
    recs = load_recordings(tmp_path)
    assert [r.path.name for r in recs] == ["drv_000.csv", "drv_001.csv", "drv_002.csv"]
    assert [r.meta["end_reason"] for r in recs] == ["truncated", "stopped", "stopped"]
    assert [r.steps for r in recs] == [5, 1, 0]
    assert all(r.complete for r in recs) and recs.errors == []


def test_existing_recordings_are_never_overwritten(tmp_path):
    _record(tmp_path, 2)
    _record(tmp_path, 2)
    (tmp_path / "run_007.json").write_text("{}")  # even a stray sidecar reserves its number
    env, _ = _record(tmp_path, 2)
    assert env.path.name == "run_008.csv"


def test_seeds_are_explicit_and_reproducible(tmp_path):
    def seeds(first=None, **kw):  # noqa: ANN001
        env = RecordingWrapper(gym.make(ENV_ID), tmp_path, **kw)
        out = []
        env.reset(seed=first)
        out.append(env.episode_seed)
        for _ in range(3):
            env.reset()
            out.append(env.episode_seed)
        env.close()
        return out

    a, b = seeds(seed=7), seeds(seed=7)
    assert a == b and len(set(a)) == 4
    c, d = seeds(first=11), seeds(first=11)
    assert c == d and c[0] == 11
    fresh = seeds()
    assert all(isinstance(s, int) and 0 <= s < 2**53 for s in fresh)
    metas = [r.meta for r in load_recordings(tmp_path)]
    assert all(m["seed"] is not None for m in metas)
    assert {m["seed_source"] for m in metas} == {"reset", "wrapper"}


def test_wrapper_rejects_other_envs_and_bad_arguments(tmp_path):
    with pytest.raises(TypeError, match="LaneKeepingEnv"):
        RecordingWrapper(gym.make("Pendulum-v1"), tmp_path)
    with pytest.raises(ValueError, match="JSON"):
        RecordingWrapper(gym.make(ENV_ID), tmp_path, metadata={"x": object()})
    with pytest.raises(ValueError, match="prefix"):
        RecordingWrapper(gym.make(ENV_ID), tmp_path, prefix="a/b")
    with pytest.raises(ValueError, match="non-negative"):
        RecordingWrapper(gym.make(ENV_ID), tmp_path, seed=-1)


# --------------------------------------------------------------- crash safety
def test_unclosed_wrapper_leaves_every_row_on_disk(tmp_path):
    env, rows = _record(tmp_path, 30, close=False)
    rec = load_recording(env.path)  # while the writer is still open
    assert not rec.complete and rec.meta["steps"] is None
    assert compare_recordings(_frame(rows), rec) is None
    assert compare_recordings(rec, replay(rec)) is None


def test_exception_in_step_keeps_rows_and_episode(tmp_path):
    env = RecordingWrapper(gym.make(ENV_ID), tmp_path)
    env.reset(seed=0)
    env.step(np.zeros(2))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0]))
    assert load_recording(env.path).steps == 1
    env.step(np.zeros(2))
    env.close()
    rec = load_recording(env.path)
    assert rec.complete and rec.steps == 2
    assert compare_recordings(rec, replay(rec)) is None


def test_killed_process_loses_no_written_row(tmp_path):
    script = textwrap.dedent(
        f"""
        import os, signal
        import numpy as np, gymnasium as gym
        import hasa_env
        from hasa_env.recording import RecordingWrapper
        env = RecordingWrapper(gym.make("{ENV_ID}"), {str(tmp_path)!r})
        env.reset(seed=3)
        for _ in range(100):
            env.step(np.array([0.01, 0.0], dtype=np.float32))
        os.kill(os.getpid(), signal.SIGKILL)
        """
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, timeout=120)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()
    rec = load_recording(tmp_path / "run_000.csv")
    assert not rec.complete and rec.steps == 100
    assert compare_recordings(rec, replay(rec)) is None


def test_partly_written_last_line_of_a_crashed_recording_is_dropped(tmp_path):
    env, rows = _record(tmp_path, 10, close=False)
    with open(env.path, "a") as f:
        f.write("11,0.11,1.6")  # the step being written when the process died
    with pytest.warns(RecordingWarning, match="line 13"):
        rec = load_recording(env.path)
    assert rec.steps == 10 and rec.warnings


# ------------------------------------------------------------ corrupt files
def _replace_line(path: Path, line: int, fn) -> None:  # noqa: ANN001
    lines = path.read_text().split("\n")
    lines[line - 1] = fn(lines[line - 1])
    path.write_text("\n".join(lines))


def _set_field(column: str, value: str):  # noqa: ANN202
    j = RECORDING_COLUMNS.index(column)

    def fn(line: str) -> str:
        fields = line.split(",")
        fields[j] = value
        return ",".join(fields)

    return fn


def _edit_sidecar(fn):  # noqa: ANN001, ANN202
    def edit(csv: Path) -> None:
        side = csv.with_suffix(".json")
        side.write_text(fn(side.read_text()))

    return edit


def _json_edit(**changes):  # noqa: ANN202
    def fn(text: str) -> str:
        meta = json.loads(text)
        meta.update(changes)
        return json.dumps(meta)

    return fn


CORRUPTIONS = {
    "truncated line": (
        lambda p: _replace_line(p, 5, lambda s: s[: s.index(",", 40)]),
        5,
        None,
        "the line ends before this column",
    ),
    "extra field": (lambda p: _replace_line(p, 4, lambda s: s + ",1.0"), 4, "truncated", "extra"),
    "bad number": (
        lambda p: _replace_line(p, 6, _set_field("speed", "15.0x")),
        6,
        "speed",
        "not a number",
    ),
    "NaN": (
        lambda p: _replace_line(p, 7, _set_field("heading", "nan")),
        7,
        "heading",
        "non-finite",
    ),
    "infinity": (
        lambda p: _replace_line(p, 3, _set_field("sensor_imu_lateral", "-inf")),
        3,
        "sensor_imu_lateral",
        "non-finite",
    ),
    "empty field": (
        lambda p: _replace_line(p, 3, _set_field("bias", "")),
        3,
        "bias",
        "not a number",
    ),
    "bad bool": (
        lambda p: _replace_line(p, 8, _set_field("terminated", "1")),
        8,
        "terminated",
        "true or false",
    ),
    "bad int": (
        lambda p: _replace_line(p, 2, _set_field("bias_index", "0.5")),
        2,
        "bias_index",
        "integer",
    ),
    "missing column": (
        lambda p: _replace_line(p, 1, lambda s: s.replace("lateral_velocity,", "")),
        1,
        "lateral_velocity",
        "missing column",
    ),
    "unknown column": (
        lambda p: _replace_line(p, 1, lambda s: s.replace("reward", "rewrd")),
        1,
        "rewrd",
        "unknown column",
    ),
    "duplicated column": (
        lambda p: _replace_line(p, 1, lambda s: s.replace("station", "speed")),
        1,
        "speed",
        "duplicated column",
    ),
    "step gap": (lambda p: _replace_line(p, 9, _set_field("step", "8")), 9, "step", "expected 7"),
    "time mismatch": (
        lambda p: _replace_line(p, 9, _set_field("time", "0.5")),
        9,
        "time",
        "does not match",
    ),
    "emptied line": (lambda p: _replace_line(p, 10, lambda s: ""), 10, "step", "empty line"),
}


@pytest.mark.parametrize("name", list(CORRUPTIONS))
def test_corrupt_csv_errors_name_file_line_and_column(tmp_path, name):
    corrupt, line, column, text = CORRUPTIONS[name]
    env, rows = _record(tmp_path, 12)
    corrupt(env.path)
    with pytest.raises(RecordingError) as info:
        load_recording(env.path)
    err = info.value
    assert err.path == env.path and err.line == line
    assert str(env.path) in str(err) and f"line {line}" in str(err)
    if name == "truncated line":
        column = err.column
        assert column in RECORDING_COLUMNS
    assert err.column == column and repr(column) in str(err)
    if text:
        assert text in str(err)


def test_deleting_the_last_rows_of_a_complete_recording_is_caught(tmp_path):
    env, _ = _record(tmp_path, 12)
    lines = env.path.read_text().splitlines(keepends=True)
    env.path.write_text("".join(lines[:-3]))
    with pytest.raises(RecordingError, match="steps = 12 but the CSV has 9 rows") as info:
        load_recording(env.path)
    assert info.value.column == "steps"


SIDECAR_CORRUPTIONS = {
    "missing sidecar": (lambda p: p.with_suffix(".json").unlink(), "missing sidecar"),
    "not JSON": (_edit_sidecar(lambda t: t[: len(t) // 2]), "not valid JSON"),
    "unknown schema": (
        _edit_sidecar(_json_edit(schema_version=2)),
        "sidecar field 'schema_version' = 2 is not allowed: only 1",
    ),
    "no schema": (
        _edit_sidecar(lambda t: t.replace('"schema_version"', '"schema"')),
        "sidecar field 'schema_version' is missing",
    ),
    "bad config": (_edit_sidecar(_json_edit(config={"sim_frequncy": 100.0})), "sim_frequncy"),
    "not an object": (_edit_sidecar(lambda t: "[1, 2]"), "JSON object"),
    "bad complete": (_edit_sidecar(_json_edit(complete="yes")), "true or false"),
    "missing csv": (lambda p: p.unlink(), "missing CSV"),
}


@pytest.mark.parametrize("name", list(SIDECAR_CORRUPTIONS))
def test_bad_sidecar_errors_name_the_file(tmp_path, name):
    corrupt, text = SIDECAR_CORRUPTIONS[name]
    env, _ = _record(tmp_path, 3)
    corrupt(env.path)
    with pytest.raises(RecordingError, match=text) as info:
        load_recording(env.path.with_suffix(".json") if name == "missing csv" else env.path)
    assert info.value.path.stem == "run_000" and "run_000" in str(info.value)


def test_truncated_last_line_of_a_complete_recording_is_an_error(tmp_path):
    env, _ = _record(tmp_path, 5)
    text = env.path.read_text()
    env.path.write_text(text[:-9])  # cut inside the last row
    with pytest.raises(RecordingError, match="line 7"):
        load_recording(env.path)


def test_load_recordings_reports_the_corrupt_file_and_loads_the_rest(tmp_path):
    for seed in range(3):
        _record(tmp_path, 4, seed=seed)
    bad = tmp_path / "run_001.csv"
    _replace_line(bad, 3, _set_field("speed", "NaN"))
    (tmp_path / "orphan.json").write_text("{}")
    with pytest.warns(RecordingWarning) as caught:
        recs = load_recordings(tmp_path)
    assert [r.path.name for r in recs] == ["run_000.csv", "run_002.csv"]
    assert sorted(e.path.name for e in recs.errors) == ["orphan.csv", "run_001.csv"]
    messages = " ".join(str(w.message) for w in caught)
    assert "run_001.csv, line 3, column 'speed'" in messages and "orphan" in messages
    with pytest.raises(RecordingError, match="2 corrupt") as info:
        load_recordings(tmp_path, strict=True)
    assert "run_001.csv, line 3" in str(info.value) and len(info.value.loaded) == 2
    with pytest.raises(FileNotFoundError):
        load_recordings(tmp_path / "nope")


def test_load_recordings_warns_what_loading_repaired_from_the_callers_line(tmp_path):
    """A crashed recording's note (its cut last line, dropped) is one RecordingWarning naming
    the file, shown at the line that called load_recordings (hasa_env.recording.warn_load_notes);
    the complete recording beside it adds none."""
    for seed in range(2):
        _record(tmp_path, 4, seed=seed)
    crashed = tmp_path / "run_001.csv"
    crash(crashed)
    with pytest.warns(RecordingWarning) as caught:
        recs = load_recordings(tmp_path)
    (note,) = [w for w in caught if issubclass(w.category, RecordingWarning)]
    assert str(note.message) == recs[1].warnings[0]
    assert str(note.message).startswith(f"{crashed}: dropped the partly written line ")
    assert note.filename == __file__


# --------------------------------------------------------- save and compare
def test_save_recording_validates_the_frame(tmp_path):
    env, rows = _record(tmp_path, 5)
    frame = _frame(rows)
    out = tmp_path / "out" / "copy.csv"
    with pytest.raises(ValueError, match="unknown meta key 'driver'"):
        save_recording(frame, out, {"driver": "x"})
    bad = frame.copy()
    bad.loc[3, "speed"] = np.nan
    with pytest.raises(RecordingError, match="row 3.*non-finite") as info:
        save_recording(bad, out)
    assert info.value.column == "speed"
    bad = frame.astype({"bias_index": float})
    bad.loc[2, "bias_index"] = 0.5
    with pytest.raises(RecordingError, match="row 2.*integer"):
        save_recording(bad, out)
    with pytest.raises(RecordingError, match="missing column"):
        save_recording(frame.drop(columns="reward"), out)
    with pytest.raises(RecordingError, match="does not match"):
        save_recording(frame, out, {"config": {"sim_frequency": 50.0}})
    assert not out.exists()
    save_recording(
        frame, out, {"config": env.unwrapped.config, "seed": 0, "metadata": {"driver": "x"}}
    )
    rec = load_recording(out)
    assert rec.meta["end_reason"] == "stopped" and rec.meta["metadata"] == {"driver": "x"}
    assert compare_recordings(rec, replay(rec)) is None


def test_compare_recordings_finds_the_first_divergence(tmp_path):
    env, rows = _record(tmp_path, 20)
    rec = load_recording(env.path)
    other = rec.data.copy()
    other.loc[7, "sensor_speed"] = np.nextafter(other.loc[7, "sensor_speed"], np.inf)
    other.loc[9, "station"] += 1.0
    assert compare_recordings(rec, other) == (7, "sensor_speed")
    assert compare_recordings(rec, other, atol=1e-9) == (9, "station")
    assert compare_recordings(rec, other, columns=["lateral_offset"]) is None
    assert compare_recordings(rec, rec.data.iloc[:12]) == (12, "step")
    flipped = rec.data.copy()
    flipped.loc[0, "heading"] = -0.0
    assert compare_recordings(rec, flipped) == (0, "heading")  # bit-exact
    assert compare_recordings(rec, flipped, atol=1e-300) is None


def test_replay_detects_a_changed_action_and_needs_a_seed(tmp_path):
    env, _ = _record(tmp_path, 20)
    rec = load_recording(env.path)
    changed = rec.data.copy()
    changed.loc[10, "steering"] += 1e-6
    diverged = compare_recordings(changed, replay(Recording(changed, rec.meta)))
    assert diverged == (10, "station")
    with pytest.raises(ValueError, match="no seed"):
        replay(Recording(rec.data, {**rec.meta, "seed": None}))


def test_recordings_readme_documents_every_column():
    readme = Path(__file__).resolve().parents[1] / "recordings" / "README.md"
    text = readme.read_text()
    for column in RECORDING_COLUMNS:
        assert f"`{column}`" in text, column


def test_no_warnings_on_a_clean_round_trip(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env, _ = _record(tmp_path, 3)
        load_recordings(tmp_path)
    assert not [name for name in os.listdir(tmp_path) if name.endswith(".tmp")]


def test_loaded_frames_carry_the_config_for_downstream_code(tmp_path):
    """Estimators and steering features read the track and hypotheses from frame.attrs."""
    from estimators.offline import hypotheses_of

    cfg = {"track": "curved", "markings": {"hypotheses": [0.0, 1.8, -1.8]}}
    env = RecordingWrapper(gym.make("hasa_env/LaneKeeping-v0", config=cfg), tmp_path, seed=3)
    env.reset()
    for _ in range(5):
        env.step(np.zeros(2))
    env.close()
    rec = load_recording(env.paths[0])
    assert rec.data.attrs["track"] == "curved"
    assert hypotheses_of(rec.data) == (0.0, 1.8, -1.8)


@pytest.mark.slow
def test_the_sample_recording_is_what_its_documented_command_makes(tmp_path):
    """recordings/sample/README.md's command, run as a user would in a fresh folder, makes
    the shipped files: the CSV byte for byte, the raw inputs but for their wall-clock column,
    the sidecar but for its timestamps and the installed versions."""
    import shlex

    from _programs import ROOT, run_program

    sample = ROOT / "recordings" / "sample"
    (command,) = [
        line.strip() for line in (sample / "README.md").read_text().splitlines()
        if line.strip().startswith("hasa-drive synthetic")
    ]  # fmt: skip
    words = shlex.split(command)
    done = run_program(words[0], *words[1:], cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    made = tmp_path / "recordings" / "sample"
    assert (made / "run_000.csv").read_bytes() == (sample / "run_000.csv").read_bytes()

    def without_wall_clock(path):
        rows = [line.split("\t") for line in path.read_text().splitlines()]
        return [row[:2] + row[3:] for row in rows]

    assert without_wall_clock(made / "run_000.inputs.tsv") == without_wall_clock(
        sample / "run_000.inputs.tsv"
    )

    def sidecar(path):
        doc = json.loads(path.read_text())
        return {k: v for k, v in doc.items() if k not in ("created", "finished", "versions")}

    assert sidecar(made / "run_000.json") == sidecar(sample / "run_000.json")
