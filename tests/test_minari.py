"""Minari export of recordings: round trip, recovered env, corrupt and mismatched files."""

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from _recording_files import crash

import hasa_env  # noqa: F401 - registers the ids
from hasa_env.recording import (
    RecordingWarning,
    RecordingWrapper,
    load_recording,
    load_recordings,
    save_recording,
)
from hasa_env.recording.export import action_columns, export_minari, observations, require_minari
from hasa_env.sim.config import deep_merge

minari = pytest.importorskip("minari")
pytest.importorskip("pyarrow")

ENV_ID = "hasa_env/LaneKeeping-v0"
CONFIG = {"time_limit": 1.0, "observation": {"type": "both"}}


def record(directory: Path, seed: int, config=CONFIG, steps: int | None = None, env_id=ENV_ID):
    """One episode with random actions; returns the env's observations (row 0 = reset)."""
    env = RecordingWrapper(gym.make(env_id, config=config), directory, seed=seed)
    obs, _ = env.reset(seed=seed)
    seen = [obs]
    rng = np.random.default_rng(seed)
    done = False
    while not done and (steps is None or len(seen) <= steps):
        obs, _, terminated, truncated, _ = env.step(rng.uniform(-0.3, 0.3, 2))
        seen.append(obs)
        done = terminated or truncated
    env.close()
    return seen


@pytest.fixture
def minari_root(tmp_path, monkeypatch):
    root = tmp_path / "minari"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    return root


def test_two_recordings_load_back_with_identical_actions_and_observations(tmp_path, minari_root):
    recs_dir = tmp_path / "recs"
    seen = [record(recs_dir, 1), record(recs_dir, 2)]
    result = export_minari(recs_dir, "hasa/test-v0")
    assert [p.name for p in result.exported] == ["run_000.csv", "run_001.csv"]
    assert result.skipped == [] and result.cut == []
    assert (minari_root / "hasa" / "test-v0").is_dir()

    dataset = minari.load_dataset("hasa/test-v0")
    assert dataset.total_episodes == 2
    recordings = load_recordings(recs_dir)
    for episode, obs, rec in zip(dataset.iterate_episodes(), seen, recordings, strict=True):
        n = rec.steps
        for key in ("sensors", "state"):  # exactly what the env returned
            np.testing.assert_array_equal(
                episode.observations[key], np.stack([o[key] for o in obs])
            )
        expected_actions = rec.data[["steering", "acceleration"]].to_numpy()[1:].astype(np.float32)
        np.testing.assert_array_equal(episode.actions, expected_actions)
        assert episode.actions.dtype == np.float32
        np.testing.assert_array_equal(episode.rewards, rec.data["reward"].to_numpy()[1:])
        np.testing.assert_array_equal(episode.terminations, rec.data["terminated"].to_numpy()[1:])
        np.testing.assert_array_equal(episode.truncations, rec.data["truncated"].to_numpy()[1:])
        assert episode.truncations[-1] and len(episode.rewards) == n
        for key in ("lateral_offset", "bias", "sensor_camera_lateral", "time"):
            np.testing.assert_array_equal(episode.infos[key], rec.data[key].to_numpy())
        np.testing.assert_array_equal(episode.infos["bias_index"], rec.data["bias_index"])
    assert dataset.observation_space == gym.make(ENV_ID, config=CONFIG).observation_space


@pytest.mark.parametrize("action_type", ["physical", "normalized"])
def test_recovered_env_replays_the_dataset(tmp_path, minari_root, action_type):
    """Recovered env + the episode's seed + the stored actions reproduce the observations."""
    config = {"time_limit": 2.0, "initial_state": {"heading_std": 0.02}}
    record(tmp_path / "recs", 5, config)
    export_minari(tmp_path / "recs", "hasa/replay-v0", action_type=action_type)
    dataset = minari.load_dataset("hasa/replay-v0")
    env = dataset.recover_environment()
    assert env.unwrapped.config["action"]["type"] == action_type
    assert env.unwrapped.config["initial_state"]["heading_std"] == 0.02
    assert env.action_space == dataset.action_space
    expected_box = (-1.0, 1.0) if action_type == "normalized" else (-0.5, 0.5)
    assert (env.action_space.low[0], env.action_space.high[0]) == expected_box
    episode = next(iter(dataset.iterate_episodes()))
    seed = dataset.storage.get_episode_metadata([0])
    seed = next(iter(seed))["seed"]
    assert seed == 5
    obs, _ = env.reset(seed=seed)
    replayed = [obs]
    for action in episode.actions:
        assert env.action_space.contains(action)
        obs, *_ = env.step(action)
        replayed.append(obs)
    # float32 actions: the trajectories agree to float32 rounding, not bit for bit
    np.testing.assert_allclose(np.stack(replayed), episode.observations, atol=2e-4)


def test_corrupt_recording_is_reported_by_name_and_the_rest_exported(tmp_path, minari_root):
    recs_dir = tmp_path / "recs"
    for seed in (1, 2, 3):
        record(recs_dir, seed)
    bad = recs_dir / "run_001.csv"
    lines = bad.read_text().splitlines(keepends=True)
    lines[5] = lines[5].replace(",", ",oops", 1)
    bad.write_text("".join(lines))
    (recs_dir / "orphan.json").write_text("{}")  # a sidecar without its CSV
    with pytest.warns(UserWarning) as caught:
        result = export_minari(recs_dir, "hasa/partial-v0")
    assert any("run_001.csv" in str(w.message) for w in caught)
    assert any("orphan.csv" in str(w.message) for w in caught)
    assert [p.name for p in result.exported] == ["run_000.csv", "run_002.csv"]
    skipped = {Path(p).name: reason for p, reason in result.skipped}
    assert set(skipped) == {"run_001.csv", "orphan.csv"}
    assert "line 6" in skipped["run_001.csv"] and "oops" in skipped["run_001.csv"]
    assert minari.load_dataset("hasa/partial-v0").total_episodes == 2


def test_what_loading_repaired_is_warned_naming_the_file(tmp_path, minari_root):
    """A recording whose writer crashed inside its last line is exported without that line;
    what loading repaired is one RecordingWarning naming the file, from a folder and from a
    list of paths alike; the complete recording beside it adds none."""
    recs_dir = tmp_path / "recs"
    record(recs_dir, 1)
    record(recs_dir, 2)
    crashed = recs_dir / "run_001.csv"
    crash(crashed)
    for source, name in ((recs_dir, "hasa/repaired-v0"), ([crashed], "hasa/repaired-v1")):
        with pytest.warns(RecordingWarning) as caught:
            result = export_minari(source, name)
        notes = [str(w.message) for w in caught if issubclass(w.category, RecordingWarning)]
        assert len(notes) == 1, notes
        assert notes[0].startswith(f"{crashed}: dropped the partly written line ")
        assert crashed in result.exported and crashed in result.cut and result.skipped == []


def test_mismatched_config_and_empty_recordings_are_skipped(tmp_path, minari_root):
    recs_dir = tmp_path / "recs"
    record(recs_dir, 1)
    record(recs_dir, 2, deep_merge(CONFIG, {"noise": {"camera": 0.2}, "render": {"fps": 60}}))
    record(recs_dir, 3, deep_merge(CONFIG, {"render": {"fps": 60}}))  # render may differ
    record(recs_dir, 4, steps=0)  # reset only
    with pytest.warns(UserWarning):
        result = export_minari(recs_dir, "hasa/mixed-v0")
    assert [p.name for p in result.exported] == ["run_000.csv", "run_002.csv"]
    skipped = {Path(p).name: reason for p, reason in result.skipped}
    assert "noise.camera" in skipped["run_001.csv"]
    assert "no steps" in skipped["run_003.csv"]


def test_a_stopped_recording_ends_truncated(tmp_path, minari_root):
    recs_dir = tmp_path / "recs"
    record(recs_dir, 1, steps=10)  # closed after 10 steps: end_reason "stopped"
    assert load_recording(recs_dir / "run_000.csv").meta["end_reason"] == "stopped"
    result = export_minari(recs_dir, "hasa/stopped-v0")
    assert [p.name for p in result.cut] == ["run_000.csv"]
    episode = next(iter(minari.load_dataset("hasa/stopped-v0").iterate_episodes()))
    assert len(episode.actions) == 10
    assert episode.truncations.tolist() == [False] * 9 + [True]
    assert not episode.terminations.any()


def test_synthetic_driver_recordings_and_list_input(tmp_path, minari_root):
    from hasa_env.drivers import SyntheticDriver, population, run_driver

    config = {"time_limit": 0.5}
    frames = run_driver(SyntheticDriver(population("paper", 0)[1]), ENV_ID, 2, 0, config)
    paths = []
    for i, frame in enumerate(frames):
        meta = {"config": frame.attrs["config"], "seed": frame.attrs["seed"], "env_id": ENV_ID}
        paths.append(save_recording(frame, tmp_path / "syn" / f"driver_{i:03d}.csv", meta))
    result = export_minari(paths, "hasa/synthetic-v0", observation_type="state")
    dataset = minari.load_dataset("hasa/synthetic-v0")
    assert dataset.total_episodes == 2
    assert result.config["observation"]["type"] == "state"
    episode = next(iter(dataset.iterate_episodes()))
    np.testing.assert_array_equal(
        episode.observations, observations(frames[0], result.config, "state")
    )
    np.testing.assert_array_equal(
        episode.actions, action_columns(frames[0], result.config, "physical")
    )


def test_existing_dataset_and_bad_arguments(tmp_path, minari_root):
    recs_dir = tmp_path / "recs"
    record(recs_dir, 1)
    export_minari(recs_dir, "hasa/again-v0")
    with pytest.raises(ValueError, match="already exists"):
        export_minari(recs_dir, "hasa/again-v0")
    export_minari(recs_dir, "hasa/again-v0", overwrite=True)
    with pytest.raises(ValueError, match="malformed"):
        export_minari(recs_dir, "no version")
    with pytest.raises(ValueError, match="action_type"):
        export_minari(recs_dir, "hasa/x-v0", action_type="degrees")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        export_minari(tmp_path / "nothing", "hasa/x-v0")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no recording to export"):
        export_minari(empty, "hasa/x-v0")


def test_data_path_argument_restores_the_environment_variable(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "elsewhere"))
    record(tmp_path / "recs", 1)
    export_minari(tmp_path / "recs", "hasa/here-v0", data_path=tmp_path / "here")
    assert (tmp_path / "here" / "hasa" / "here-v0").is_dir()
    assert not (tmp_path / "elsewhere" / "hasa" / "here-v0").exists()
    import os

    assert os.environ["MINARI_DATASETS_PATH"] == str(tmp_path / "elsewhere")


def test_missing_minari_gives_an_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "minari", None)
    with pytest.raises(ImportError, match=r"pip install 'hasa-env\[minari\]'"):
        require_minari()
