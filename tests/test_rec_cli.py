"""``hasa-rec``: info, convert (Parquet), export-minari; their errors and exit codes."""

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from _recording_files import crash

import hasa_env  # noqa: F401 - registers the ids
from hasa_cli.rec import main
from hasa_env.recording import RecordingError, RecordingWrapper, load_recording
from hasa_env.recording.parquet import read_parquet, to_parquet
from hasa_env.recording.summary import summarize

ENV_ID = "hasa_env/LaneKeeping-v0"


def record(directory: Path, seed: int, steps: int | None = None, config=None) -> Path:
    config = config or {"time_limit": 1.0, "action_repeat": 2}
    env = RecordingWrapper(
        gym.make(ENV_ID, config=config), directory, seed=seed, metadata={"participant": "P1"}
    )
    env.reset(seed=seed, options={"bias_index": 1})
    rng = np.random.default_rng(seed)
    k = 0
    while steps is None or k < steps:
        _, _, terminated, truncated, _ = env.step(rng.uniform(-0.2, 0.2, 2))
        k += 1
        if terminated or truncated:
            break
    path = env.path
    env.close()
    return path


def corrupt(path: Path, line: int) -> None:
    """Replace the first field of a CSV line (1 = header) with text."""
    lines = path.read_text().splitlines(keepends=True)
    lines[line - 1] = "x," + lines[line - 1].split(",", 1)[1]
    path.write_text("".join(lines))


# --------------------------------------------------------------------- info
def test_info_summarises_a_valid_recording(tmp_path, capsys):
    path = record(tmp_path, 3)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    rec = load_recording(path)
    y = rec.data["lateral_offset"].to_numpy()[1:]
    assert "valid          yes (complete)" in out
    assert "50 env steps, 1.00 s (env step 0.02 s)" in out
    assert "end            truncated" in out
    assert "action_repeat 2 (50 Hz policy)" in out
    assert "b = -1.8 m (hypothesis 1)" in out
    assert f"RMSE {np.sqrt(np.mean(y * y)):.3f} m" in out
    assert "seed           3" in out and '"participant": "P1"' in out
    summary = summarize(path)
    assert summary.steps == 50 and summary.complete and summary.bias == -1.8
    assert summary.total_reward == pytest.approx(rec.data["reward"].sum())


def test_info_reports_errors_with_line_and_column(tmp_path, capsys):
    good = record(tmp_path, 1)
    bad = record(tmp_path, 2)
    corrupt(bad, 7)
    assert main(["info", str(good), str(bad)]) == 1
    captured = capsys.readouterr()
    assert "valid          yes" in captured.out and "valid          NO" in captured.out
    assert str(bad) in captured.err and "line 7" in captured.err and "'step'" in captured.err


def test_info_of_a_folder_summarises_every_recording_in_it_and_below(tmp_path, capsys):
    """A folder is its recordings, as hasa-replay and hasa-bench read one (it was taken for a
    recording named like the folder: 'no such recording')."""
    record(tmp_path / "P1", 1)
    bad = record(tmp_path / "P1", 2)
    record(tmp_path / "P2", 3)
    corrupt(bad, 7)
    assert main(["info", str(tmp_path)]) == 1
    captured = capsys.readouterr()
    assert captured.out.count("valid          yes") == 2
    assert captured.out.count("valid          NO") == 1
    assert captured.out.rstrip().endswith("3 recordings: 2 valid, 1 not")
    assert str(tmp_path / "P2" / "run_000.csv") in captured.out
    assert str(bad) in captured.err and "line 7" in captured.err
    (tmp_path / "empty").mkdir()
    assert main(["info", str(tmp_path / "empty")]) == 2
    assert "no recordings" in capsys.readouterr().err


def test_info_flags_an_incomplete_recording(tmp_path, capsys):
    path = record(tmp_path, 1, steps=5)
    sidecar = path.with_suffix(".json")
    meta = json.loads(sidecar.read_text())
    meta.update(complete=False, steps=None, end_reason=None)
    sidecar.write_text(json.dumps(meta))
    with path.open("a") as f:
        f.write("6,0.1")  # a line being written when the writer crashed
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "INCOMPLETE" in out and "5 env steps" in out
    assert f"warning        {path}: dropped the partly written line 8 " in out


def test_info_missing_sidecar(tmp_path, capsys):
    path = record(tmp_path, 1, steps=3)
    path.with_suffix(".json").unlink()
    assert main(["info", str(path)]) == 2  # nothing valid: an input error
    err = capsys.readouterr().err
    assert err.startswith("hasa-rec: error: ") and "missing sidecar" in err
    # named by the CSV the user has, not by the JSON file that is missing
    assert f"{path}: missing sidecar {path.with_suffix('.json').name}" in err, err


# ------------------------------------------------------------------ convert
def test_convert_one_file_round_trips_bit_for_bit(tmp_path, capsys):
    pytest.importorskip("pyarrow")
    path = record(tmp_path / "recs", 4)
    assert main(["convert", str(path), "-o", str(tmp_path / "out" / "one.parquet")]) == 0
    assert "one.parquet (50 steps)" in capsys.readouterr().out
    back = read_parquet(tmp_path / "out" / "one.parquet")
    original = load_recording(path)
    assert back.data.equals(original.data)
    assert list(back.data.dtypes) == list(original.data.dtypes)
    assert back.meta == original.meta
    assert main(["info", str(tmp_path / "out" / "one.parquet")]) == 0
    assert "50 env steps" in capsys.readouterr().out


def test_convert_folder_skips_corrupt_files(tmp_path, capsys):
    pytest.importorskip("pyarrow")
    recs = tmp_path / "recs"
    record(recs, 1)
    bad = record(recs, 2)
    record(recs, 3)
    corrupt(bad, 4)
    assert main(["convert", str(recs), "-o", str(tmp_path / "pq")]) == 1
    captured = capsys.readouterr()
    assert sorted(p.name for p in (tmp_path / "pq").iterdir()) == [
        "run_000.parquet",
        "run_002.parquet",
    ]
    assert "run_001.csv" in captured.err and "line 4" in captured.err
    # default output: next to the CSVs
    assert main(["convert", str(recs / "run_000.csv")]) == 0
    assert (recs / "run_000.parquet").is_file()


def _warning_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("hasa-rec: warning: ")]


def test_convert_says_what_loading_repaired_once_naming_the_file(tmp_path, capsys):
    """A folder whose second recording's writer crashed inside its last line: both convert
    (that line dropped); the note of its loading is one warning line naming the file, and
    the complete recording beside it adds none. Converted alone, the same."""
    pytest.importorskip("pyarrow")
    recs = tmp_path / "recs"
    record(recs, 1)
    crashed = record(recs, 2)
    crash(crashed)
    assert main(["convert", str(recs), "-o", str(tmp_path / "pq")]) == 0
    captured = capsys.readouterr()
    assert sorted(p.name for p in (tmp_path / "pq").iterdir()) == [
        "run_000.parquet",
        "run_001.parquet",
    ]
    (note,) = _warning_lines(captured.err)
    assert note.startswith(f"hasa-rec: warning: {crashed}: dropped the partly written line ")
    assert main(["convert", str(crashed), "-o", str(tmp_path / "one.parquet")]) == 0
    assert _warning_lines(capsys.readouterr().err) == [note]
    assert read_parquet(tmp_path / "one.parquet").complete is False


def test_convert_errors(tmp_path, capsys, monkeypatch):
    pytest.importorskip("pyarrow")
    bad = record(tmp_path, 1, steps=3)
    corrupt(bad, 3)
    assert main(["convert", str(bad)]) == 2  # the only input is invalid
    assert "line 3" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["convert", str(empty)]) == 2
    assert "no recordings" in capsys.readouterr().err
    not_ours = tmp_path / "other.parquet"
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table({"a": [1, 2]}), not_ours)
    with pytest.raises(RecordingError, match="not a hasa_env recording"):
        read_parquet(not_ours)
    assert main(["info", str(not_ours)]) == 2
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    assert main(["convert", str(tmp_path)]) == 3  # the machine lacks pyarrow
    err = capsys.readouterr().err
    assert "pip install 'hasa-env[parquet]'" in err and "pip install '.[parquet]'" in err


def test_to_parquet_rejects_a_tampered_file(tmp_path):
    pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    path = to_parquet(record(tmp_path, 1, steps=4))
    table = pq.read_table(path)
    pq.write_table(
        table.drop_columns(["reward"]).replace_schema_metadata(table.schema.metadata), path
    )
    with pytest.raises(RecordingError, match="missing \\['reward'\\]"):
        read_parquet(path)
    import pyarrow as pa

    times = table.column("time").to_numpy().copy()
    times[3] += 0.5
    shifted = table.set_column(table.column_names.index("time"), "time", pa.array(times))
    pq.write_table(shifted.replace_schema_metadata(table.schema.metadata), path)
    with pytest.raises(RecordingError, match="row 3: time"):
        read_parquet(path)


# ------------------------------------------------------------ export-minari
def test_export_minari_command(tmp_path, capsys, monkeypatch):
    minari = pytest.importorskip("minari")
    pytest.importorskip("pyarrow")
    recs = tmp_path / "recs"
    record(recs, 1)
    bad = record(recs, 2)
    record(recs, 3)
    corrupt(bad, 10)
    store = tmp_path / "store"
    argv = ["export-minari", str(recs), "hasa/cli-v0", "--data-path", str(store)]
    assert main([*argv, "--actions", "normalized"]) == 1  # exported, but one file skipped
    captured = capsys.readouterr()
    assert "exported 2 recording(s), 100 steps" in captured.out
    assert "normalized actions" in captured.out
    assert "run_001.csv" in captured.err and "line 10" in captured.err
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(store))
    dataset = minari.load_dataset("hasa/cli-v0")
    assert dataset.total_episodes == 2
    assert dataset.action_space.low.tolist() == [-1.0, -1.0]
    assert main(argv) == 2  # exists already
    assert "already exists" in capsys.readouterr().err
    assert main([*argv, "--overwrite"]) == 1
    assert main(["export-minari", str(tmp_path / "none"), "hasa/x-v0"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["export-minari", str(recs), "badname", "--data-path", str(store)]) == 2
    assert "malformed" in capsys.readouterr().err


def test_export_minari_says_what_loading_repaired_once_naming_the_file(tmp_path, capsys):
    """A folder of a complete recording, one whose writer crashed inside its last line and a
    corrupt one: the first two are exported (that line dropped), the corrupt one named and
    skipped once; what loading repaired is one warning line naming the crashed file."""
    pytest.importorskip("minari")
    pytest.importorskip("pyarrow")
    recs = tmp_path / "recs"
    record(recs, 1)
    crashed = record(recs, 2)
    crash(crashed)
    bad = record(recs, 3)
    corrupt(bad, 10)
    argv = ["export-minari", str(recs), "hasa/cut-v0", "--data-path", str(tmp_path / "store")]
    assert main(argv) == 1  # exported, but one file skipped
    captured = capsys.readouterr()
    assert "exported 2 recording(s), 99 steps" in captured.out
    note, cut = _warning_lines(captured.err)  # what loading repaired, then what the export did
    assert note.startswith(f"hasa-rec: warning: {crashed}: dropped the partly written line ")
    assert cut == (f"hasa-rec: warning: {crashed} ended without termination or truncation: "
                   "its last step is marked truncated in the dataset")  # fmt: skip
    (skipped,) = [line for line in captured.err.splitlines() if str(bad) in line]
    assert skipped.startswith(f"hasa-rec: error: skipped {bad}: ") and "line 10" in skipped


def test_convert_and_export_of_a_study_root_point_at_its_participants_folders(tmp_path, capsys):
    """Both read a folder's own recordings; a study's root holds one folder per participant,
    and "no recordings" alone left the user guessing."""
    pytest.importorskip("pyarrow")
    record(tmp_path / "study" / "P07", 1)
    assert main(["convert", str(tmp_path / "study")]) == 2
    hint = f"(its subfolders hold 1 recording(s), e.g. in {tmp_path / 'study' / 'P07'}: give"
    assert hint in capsys.readouterr().err
    pytest.importorskip("minari")
    store = tmp_path / "store"
    argv = ["export-minari", str(tmp_path / "study"), "hasa/root-v0", "--data-path", str(store)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "no recording to export" in err and hint in err, err


def test_usage_errors(capsys):
    with pytest.raises(SystemExit) as exc:
        main([])
    assert exc.value.code == 2
    with pytest.raises(SystemExit):
        main(["export-minari", "only-dir"])
    assert "NAME" in capsys.readouterr().err
