"""Odd, inconsistent and unreadable recordings and study folders (issue 22, round 2).

Each test is a regression test of one item of the issue: it failed on the main branch
before the fix. Command-line tools run as a user runs them (a subprocess) where the item
is about what the user sees; library functions are called in this process otherwise.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from _programs import run_program

from hasa_env.drivers import population, run_population, save_runs
from hasa_env.recording import RecordingError, load_recording
from hasa_env.sim.setup import RECORDING_COLUMNS

ROOT = Path(__file__).resolve().parents[1]


def run_cli(module: str, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``hasa-<module> ARGS`` as a user runs it (:func:`_programs.run_program`: headless,
    this tree's code), in ``cwd`` (default: the repository)."""
    return run_program(f"hasa-{module}", *args, cwd=cwd or ROOT)


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two good 2.5 s recordings (100 Hz, straight track) of the illustrative driver."""
    folder = tmp_path_factory.mktemp("good")
    drivers = population("paper", seed=0, size=1)
    runs = run_population(drivers, runs=2, seed=0, config={"time_limit": 2.5})
    return [Path(p) for p in save_runs(runs["Ill"], folder, prefix="good")]


def copy(src: Path, dst: Path) -> Path:
    """The recording ``src`` (CSV and sidecar) copied to ``dst`` (a CSV path)."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)
    shutil.copyfile(src.with_suffix(".json"), dst.with_suffix(".json"))
    return dst


def set_cell(path: Path, line: int, column: str, value: str) -> None:
    """Set one CSV cell (line 1 = the header)."""
    lines = path.read_text().split("\n")
    fields = lines[line - 1].split(",")
    fields[RECORDING_COLUMNS.index(column)] = value
    lines[line - 1] = ",".join(fields)
    path.write_text("\n".join(lines))


# ---------------------------------------------------------------- item 8
IMPOSSIBLE = {
    "bias_index_7": (2, "bias_index", "7", "is none of the config's 2 hypotheses"),
    "bias_changes": (6, "bias", "0.9", "cannot change"),
    "terminated_early": (5, "terminated", "true", "terminated = true before the last row"),
    "negative_speed": (5, "speed", "-3.0", "outside [0, 60] m/s"),
    "y_1e5": (5, "lateral_offset", "1e5", "farther from the lane centre"),
}


def test_impossible_recordings_are_refused_with_row_and_reason(good, tmp_path):
    files = []
    for stem, (line, column, value, _) in IMPOSSIBLE.items():
        path = copy(good[0], tmp_path / f"{stem}.csv")
        set_cell(path, line, column, value)
        files.append(str(path))
        with pytest.raises(RecordingError) as info:
            load_recording(path)
        assert (info.value.line, info.value.column) == (line, column), str(info.value)
    done = run_cli("rec", "info", *files)
    assert done.returncode == 2, done.stderr  # no input is valid
    assert "valid          yes" not in done.stdout
    for stem, (line, column, _, reason) in IMPOSSIBLE.items():
        assert f"{stem}.csv, line {line}, column {column!r}: " in done.stderr
        assert reason in done.stderr


# ---------------------------------------------------------------- item 18
@pytest.mark.parametrize("newline", ["\r", "\u2028"])
def test_an_error_quotes_a_bounded_part_of_the_file(good, tmp_path, newline):
    path = copy(good[0], tmp_path / "one_line.csv")
    text = good[0].read_text()
    path.write_text(text.replace("\n", newline), encoding="utf-8", newline="")
    with pytest.raises(RecordingError) as info:
        load_recording(path)
    message = str(info.value)
    assert len(message) < 2000, len(message)  # was 242 KB: every cell of the file
    assert "carriage return or a Unicode line separator" in message
    # the one line's cells are no columns: none is quoted as duplicated, unknown or missing
    assert info.value.line == 1 and info.value.column is None, message
    assert "duplicated" not in message and "unknown column" not in message


def test_the_cli_error_line_of_a_one_line_file_is_short(good, tmp_path):
    path = copy(good[0], tmp_path / "cr.csv")
    path.write_text(good[0].read_text().replace("\n", "\r"), newline="")
    done = run_cli("rec", "info", str(path))
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and len(lines[0]) < 2000 and lines[0].startswith("hasa-rec: error: ")


# ---------------------------------------------------------------- item 9
def test_a_steering_ratio_that_is_no_positive_number_is_a_usage_error(good):
    from benchmarks.recordings import ModelSetupError, prepare_model
    from hasa_env.recording.reader import load_paths

    recordings = load_paths([good[0]])
    for bad in (float("nan"), 0.0, -15.0, float("inf"), 1e300):
        with pytest.raises(ModelSetupError, match="steering ratio must be a number in"):
            prepare_model("two-point", recordings, steering_ratio=bad)
    done = run_cli("replay", str(good[0]), "--model", "two-point", "--steering-ratio", "nan")
    assert done.returncode == 2 and "rmse" not in done.stdout, done.stdout  # was: exit 0, rmse nan
    assert "--steering-ratio must be a number in (0, 10000]" in done.stderr


# ---------------------------------------------------------------- item 15
@pytest.fixture(scope="module")
def other_rates(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """A 50 Hz recording and one at 100 Hz with action_repeat 2 (both an env step of 0.02 s)."""
    folder = tmp_path_factory.mktemp("rates")
    drivers = population("paper", seed=0, size=1)
    out = []
    for prefix, config in (("r50", {"sim_frequency": 50.0}), ("ar2", {"action_repeat": 2})):
        runs = run_population(drivers, runs=1, seed=0, config={"time_limit": 2.5, **config})
        out += [Path(p) for p in save_runs(runs["Ill"], folder, prefix=prefix)]
    return out


@pytest.mark.slow
def test_hasa_bench_skips_recordings_of_another_sample_time_in_one_line_each(
    good, other_rates, tmp_path, capsys
):
    from hasa_cli.bench import main as bench_main

    folder = tmp_path / "mixed"
    for path in good + other_rates:
        copy(path, folder / path.name)
    out = tmp_path / "out"
    code = bench_main(["paper", "--recordings", str(folder), "--min-duration", "0.5", "--out",
                       str(out), "--workers", "1", "--quiet", "--no-plots", "--curved-runs", "0"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 1, err  # partial: was a traceback (a model's coefficients at another Ts)
    doc = json.loads((out / "results.json").read_text())
    skipped = {Path(s["file"]).name: s["reason"] for s in doc["skipped"]}
    assert set(skipped) == {p.name for p in other_rates}
    assert all("sampled every 0.02 s" in reason for reason in skipped.values())
    scored = {Path(p).name for d in doc["drivers"] for p in d["recordings"]}
    assert scored == {p.name for p in good}


def test_hasa_replay_names_a_recording_of_another_sample_time_and_goes_on(
    good, other_rates, capsys
):
    from hasa_cli.replay import main as replay_main

    r50 = str(other_rates[0])
    code = replay_main([r50, str(good[0]), "--model", "generalized"])
    out, err = capsys.readouterr()
    assert code == 1, err  # was a traceback
    assert f"{r50}: cannot score model generalized: " in err
    assert f"{good[0]}: model generalized: rmse" in out  # the other one is scored
    code = replay_main([r50, "--model", "generalized", "--fit"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "cannot fit generalized on" in err


# ---------------------------------------------------------------- item 6
def _study(good: list[Path], root: Path) -> Path:
    """A study folder: P1 a folder, P2 a symlink to a folder elsewhere, P3 a folder."""
    copy(good[0], root / "study" / "P1" / "run_000.csv")
    copy(good[1], root / "elsewhere" / "run_000.csv")
    (root / "study" / "P2").symlink_to(root / "elsewhere", target_is_directory=True)
    copy(good[1], root / "study" / "P3" / "run_000.csv")
    return root / "study"


def test_a_participant_folder_linked_into_the_study_is_analysed(good, tmp_path, capsys):
    from hasa_cli.replay import main as replay_main

    study = _study(good, tmp_path)
    (study / "loop").symlink_to(study, target_is_directory=True)  # a cycle ends at once
    assert replay_main([str(study)]) == 0
    out = capsys.readouterr().out
    assert out.count("replay matches") == 3 and "P2/run_000.csv" in out  # was: P2 left out


def test_an_unreadable_participant_folder_is_named(good, tmp_path, monkeypatch, capsys):
    from hasa_cli.replay import main as replay_main
    from hasa_env.recording.reader import load_paths

    study = _study(good, tmp_path)
    real_scandir = os.scandir

    def scandir(path):  # what a normal user meets in a folder of mode 000
        if Path(path).name == "P3":
            raise PermissionError(13, "Permission denied", str(path))
        return real_scandir(path)

    monkeypatch.setattr(os, "scandir", scandir)
    loaded = load_paths([study])
    assert len(loaded) == 2
    assert [(e.path.name, e.reason) for e in loaded.errors] == [
        ("P3", "cannot read this folder: Permission denied")
    ]  # was: left out without a word, exit 0
    assert replay_main([str(study)]) == 1
    assert "P3: cannot read this folder: Permission denied" in capsys.readouterr().err


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads folders of any mode")
def test_folders_of_mode_000_and_0644_are_named_as_a_user_meets_them(good, tmp_path):
    study = _study(good, tmp_path)
    (study / "P3").chmod(0o000)
    (study / "P1").chmod(0o644)  # listed but not searchable
    try:
        done = run_cli("replay", str(study))
    finally:
        (study / "P3").chmod(0o755)
        (study / "P1").chmod(0o755)
    assert done.returncode == 1, done.stderr
    assert "P3: cannot read this folder" in done.stderr
    assert "P1: cannot search this folder" in done.stderr
    assert "no such recording" not in done.stderr


# ---------------------------------------------------------------- items 7 and 14
def _session_doc() -> dict:
    """A valid session file of participant P2: a practice run, then a measured run."""
    runs = [
        {"position": i, "block": block, "number": 1, "track": "straight", "bias": 0.0,
         "bias_index": 0, "seed": 7 + i, "prefix": f"{block}_01"}
        for i, block in enumerate(("practice", "measured"))
    ]  # fmt: skip
    attempts = [
        {"position": i, "block": r["block"], "number": 1, "attempt": 0,
         "file": f"{r['prefix']}_000.csv", "status": "completed", "end_reason": "truncated",
         "steps": 250}
        for i, r in enumerate(runs)
    ]  # fmt: skip
    return {
        "format": "hasa_env.study_session", "format_version": 1,
        "study": {"name": "s", "spec": {"runs": {"repeat_aborted": False}}},
        "participant": {"id": "P2", "slot": None, "metadata": {}},
        "seed": 3, "hypotheses": [0.0, -1.8], "schedule": runs, "attempts": attempts,
        "sessions": [], "state": "complete",
    }  # fmt: skip


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth


BAD_SESSIONS = {
    "seed NaN": lambda text: text.replace('"seed": 3', '"seed": NaN'),
    "nested 5000 levels": lambda text: text.replace(
        '"sessions": []', '"sessions": ' + _nested(5000)
    ),
    "5000-digit integer": lambda text: text.replace('"seed": 3', '"seed": ' + "9" * 5000),
    "attempts not objects": lambda text: text.replace('"sessions": []', '"sessions": []').replace(
        '"attempts": [', '"attempts": [1, '
    ),
}


@pytest.mark.parametrize("kind", list(BAD_SESSIONS))
def test_a_session_file_that_cannot_be_used_is_named_and_its_folder_skipped(
    good, tmp_path, kind, capsys
):
    from benchmarks.protocol.config import ProtocolConfig
    from benchmarks.protocol.plan import recording_plan
    from hasa_env.session import SessionError, SessionFile

    study = tmp_path / "study"
    for i, path in enumerate(good):
        copy(path, study / "P1" / f"run_{i:03d}.csv")
    copy(good[0], study / "P2" / "practice_01_000.csv")
    copy(good[1], study / "P2" / "measured_01_000.csv")
    text = json.dumps(_session_doc())
    (study / "P2" / "session.json").write_text(text)
    assert SessionFile.open(study / "P2" / "session.json").participant == "P2"  # valid
    (study / "P2" / "session.json").write_text(BAD_SESSIONS[kind](text))
    if kind != "attempts not objects":
        with pytest.raises(SessionError, match="session.json"):
            SessionFile.open(study / "P2" / "session.json")  # was RecursionError, ValueError
    plan = recording_plan(ProtocolConfig(recordings=str(study), min_duration=0.5))
    scored = {Path(r.path).relative_to(study).as_posix() for r in plan.main + plan.curved}
    assert scored == {"P1/run_000.csv", "P1/run_001.csv"}  # was: P2's practice run scored too
    skipped = {Path(s["file"]).name: s["reason"] for s in plan.skipped}
    assert set(skipped) == {"practice_01_000.csv", "measured_01_000.csv"}
    assert all("session file cannot be used" in r for r in skipped.values())
    assert any(n.startswith("skipped the session file") for n in plan.notes)


def test_deeply_nested_and_huge_study_files_are_one_line_errors(tmp_path):
    from hasa_env.session.study import Study, StudyError

    cases = {
        "deep.json": '{"a": ' + _nested(5000) + "}",
        "huge.json": '{"seed": ' + "9" * 5000 + "}",
        "deep.toml": "a = " + _nested(5000) + "\n",
    }
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(StudyError, match=name):  # was RecursionError / ValueError
            Study.load(tmp_path / name)


# ---------------------------------------------------------------- item 10
@pytest.mark.parametrize("how", ["raises ENOSPC", "writes too little"])
def test_an_export_cut_by_a_full_disk_leaves_no_dataset_behind(
    good, tmp_path, monkeypatch, capsys, how
):
    minari = pytest.importorskip("minari")
    from hasa_cli.rec import main as hasa_rec
    from hasa_env.recording.export import export_minari

    folder = tmp_path / "recs"
    for path in good:
        copy(path, folder / path.name)
    real = minari.create_dataset_from_buffers

    def cut(**kwargs):  # the first episode fits on the disk, the second does not
        dataset = real(**{**kwargs, "buffer": kwargs["buffer"][:1]})
        if how == "raises ENOSPC":
            raise OSError(28, "No space left on device")
        return dataset

    monkeypatch.setattr(minari, "create_dataset_from_buffers", cut)
    with pytest.raises(OSError, match="No space left|a full disk"):
        export_minari(folder, "hasa/full-v0", data_path=tmp_path / "data")
    assert not (tmp_path / "data" / "hasa" / "full-v0").exists()  # was: a 1-episode dataset
    # hasa-rec says so in one line and exits 3, as every program on a full disk (was: 2)
    capsys.readouterr()
    status = hasa_rec(["export-minari", str(folder), "hasa/full-v0", "--data-path",
                       str(tmp_path / "data")])  # fmt: skip
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert status == 3, line
    assert line.startswith("hasa-rec: error: cannot export 'hasa/full-v0': ")
    assert ("No space left" if how == "raises ENOSPC" else "a full disk?") in line
    assert line.endswith("nothing was kept")
    assert not (tmp_path / "data" / "hasa" / "full-v0").exists()
    monkeypatch.setattr(minari, "create_dataset_from_buffers", real)
    result = export_minari(folder, "hasa/full-v0", data_path=tmp_path / "data")  # not blocked
    assert result.dataset.total_episodes == 2


# ---------------------------------------------------------------- item 19
def _long_recording(good: Path, target: Path, rows: int) -> Path:
    """A valid recording of ``rows`` steps: the good one's rows repeated, steps and times
    renumbered."""
    lines = good.read_text().split("\n")[:-1]
    body = [line.split(",") for line in lines[1:]]
    body[-1][-2:] = ["false", "false"]
    with open(target, "w") as f:
        f.write(lines[0] + "\n")
        for k in range(rows + 1):
            fields = body[k % len(body)]
            f.write(",".join([str(k), repr(k * (1.0 / 100.0)), *fields[2:]]) + "\n")
    meta = json.loads(good.with_suffix(".json").read_text())
    meta["steps"] = rows
    target.with_suffix(".json").write_text(json.dumps(meta))
    return target


def test_an_ordinary_file_is_read_by_the_fast_parser_with_the_exact_values(good, tmp_path):
    import pandas as pd

    from hasa_env.recording import reader

    data = good[0].read_bytes()
    fast = reader._fast_frame(data, good[0])
    assert fast is not None  # an ordinary recording takes the fast path
    exact = reader._exact_frame(data, {"complete": True}, good[0], [])
    pd.testing.assert_frame_equal(fast, exact, check_exact=True)  # bit for bit, same dtypes
    for edit in (b"1.0,", b"1e0,", b"01,"):  # a step written as a float: refused; leading 0 fine
        odd = data.replace(b"\n1,", b"\n" + edit, 1)
        assert (reader._fast_frame(odd, good[0]) is None) == (edit != b"01,")


@pytest.mark.slow
def test_a_long_recording_loads_in_bounded_memory(good, tmp_path):
    path = _long_recording(good[0], tmp_path / "long.csv", 100_000)
    size = path.stat().st_size
    script = (
        "import resource, sys\n"
        "from hasa_env.recording import load_recording\n"
        "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "rec = load_recording(sys.argv[1])\n"
        "after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "print(rec.steps, (after - before) * 1024)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True,
                          text=True, timeout=120, env=env)  # fmt: skip
    assert done.returncode == 0, done.stderr
    steps, grown = (int(v) for v in done.stdout.split())
    assert steps == 100_000
    assert grown < 3.0 * size, grown / size  # was 5.4 x the file


def test_deeply_nested_and_huge_model_files_are_model_file_errors(tmp_path):
    from hasa_env.steering import ModelFileError, SteeringModel
    from hasa_env.steering.loading import load_model

    for name, text in {"deep.json": '{"a": ' + _nested(5000) + "}",
                       "huge.json": '{"a": ' + "9" * 5000 + "}"}.items():  # fmt: skip
        (tmp_path / name).write_text(text)
        with pytest.raises(ModelFileError, match=name):  # was RecursionError / ValueError
            load_model(str(tmp_path / name))
        with pytest.raises(ModelFileError):
            SteeringModel.from_json(text)
