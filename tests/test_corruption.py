"""The corruption suite: bad recordings against every tool that reads them.

Each kind below makes one corrupt (or, for the few "benign" kinds, unusual but
valid) recording from a good one. Every kind is loaded on its own with
:func:`hasa_env.load_recording`; then all of them, mixed with good recordings in
one folder, go through the batch tools: :func:`hasa_env.recording.load_paths`,
``hasa-replay``, ``hasa-rec info`` / ``convert`` and ``hasa-bench --recordings``.
What must hold: no traceback (every tool is called in this process, so an
exception that escapes fails the test), every bad file named in the tool's
errors, every good file processed, and exit status 1 ("partial").
"""

from __future__ import annotations

import json
import os
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from benchmarks.protocol.config import ProtocolConfig
from benchmarks.protocol.plan import recording_plan
from hasa_cli.bench import main as bench_main
from hasa_cli.rec import main as rec_main
from hasa_cli.replay import main as replay_main
from hasa_env.drivers import population, run_population, save_runs
from hasa_env.recording import RecordingError, RecordingWarning, load_recording
from hasa_env.recording.reader import load_paths
from hasa_env.sim.setup import RECORDING_COLUMNS

Maker = Callable[[Path, Path], None]
"""(a good recording's CSV, the CSV path to create) -> writes the variant (CSV + sidecar)."""


# ------------------------------------------------------------------- helpers
def _copy(src: Path, dst: Path) -> None:
    shutil.copyfile(src, dst)
    shutil.copyfile(src.with_suffix(".json"), dst.with_suffix(".json"))


def _text_edit(fn: Callable[[str], str]) -> Maker:
    def make(src: Path, dst: Path) -> None:
        _copy(src, dst)
        dst.write_text(fn(src.read_text(encoding="utf-8")), encoding="utf-8", newline="")

    return make


def _bytes_edit(fn: Callable[[bytes], bytes]) -> Maker:
    def make(src: Path, dst: Path) -> None:
        _copy(src, dst)
        dst.write_bytes(fn(src.read_bytes()))

    return make


def _line_edit(line: int, fn: Callable[[str], str]) -> Maker:
    """Edit line ``line`` (1 = header; negative: from the end, -1 = the last row)."""

    def edit(text: str) -> str:
        lines = text.split("\n")[:-1]
        lines[line - 1 if line > 0 else line] = fn(lines[line - 1 if line > 0 else line])
        return "\n".join(lines) + "\n"

    return _text_edit(edit)


def _cell(line: int, column: str, value: str) -> Maker:
    j = RECORDING_COLUMNS.index(column)

    def fn(text: str) -> str:
        fields = text.split(",")
        fields[j] = value
        return ",".join(fields)

    return _line_edit(line, fn)


def _lines_edit(fn: Callable[[list[str]], list[str]]) -> Maker:
    return _text_edit(lambda t: "\n".join(fn(t.split("\n")[:-1])) + "\n")


def _sidecar(fn: Callable[[dict], object]) -> Maker:
    """Replace the sidecar by ``fn(its JSON)`` (a dict edited in place, or a new document)."""

    def make(src: Path, dst: Path) -> None:
        _copy(src, dst)
        meta = json.loads(src.with_suffix(".json").read_text())
        new = fn(meta)
        dst.with_suffix(".json").write_text(json.dumps(meta if new is None else new))

    return make


def _sidecar_text(fn: Callable[[str], str | bytes]) -> Maker:
    def make(src: Path, dst: Path) -> None:
        _copy(src, dst)
        new = fn(src.with_suffix(".json").read_text())
        side = dst.with_suffix(".json")
        if isinstance(new, bytes):
            side.write_bytes(new)
        else:
            side.write_text(new, encoding="utf-8")

    return make


def _set(**changes: object) -> Maker:
    return _sidecar(lambda meta: meta.update(changes))


def _incomplete(meta: dict) -> None:
    meta.update(complete=False, steps=None, end_reason=None, finished=None)


def _nested(depth: int) -> object:
    value: object = 1
    for _ in range(depth):
        value = {"a": value}
    return value


def _replace_csv(fn: Callable[[Path], None]) -> Maker:
    """Keep the sidecar, put something else at the CSV's path."""

    def make(src: Path, dst: Path) -> None:
        shutil.copyfile(src.with_suffix(".json"), dst.with_suffix(".json"))
        fn(dst)

    return make


def _replace_sidecar(fn: Callable[[Path], None]) -> Maker:
    def make(src: Path, dst: Path) -> None:
        shutil.copyfile(src, dst)
        fn(dst.with_suffix(".json"))

    return make


def _parquet(edit: Callable[[object], object] | None, raw: Callable[[bytes], bytes] | None = None):
    """A Parquet copy (no CSV beside it) of the recording, its table edited or its bytes."""

    def make(src: Path, dst: Path) -> None:
        pytest.importorskip("pyarrow")
        import pyarrow.parquet as pq

        from hasa_env.recording.parquet import to_parquet

        target = dst.with_suffix(".parquet")
        to_parquet(load_recording(src), target)
        if edit is not None:
            table = pq.read_table(target)
            pq.write_table(edit(table), target)
        if raw is not None:
            target.write_bytes(raw(target.read_bytes()))

    return make


def _table_set(column: str, row: int, value: float):
    def edit(table):
        import pyarrow as pa

        values = table.column(column).to_numpy().copy()
        values[row] = value
        i = table.column_names.index(column)
        return table.set_column(i, column, pa.array(values)).replace_schema_metadata(
            table.schema.metadata
        )

    return edit


def _table_cast(column: str, type_name: str):
    def edit(table):
        import pyarrow as pa

        i = table.column_names.index(column)
        cast = table.column(column).cast(getattr(pa, type_name)())
        return table.set_column(i, column, cast).replace_schema_metadata(table.schema.metadata)

    return edit


def _not_ours(table):
    import pyarrow as pa

    return pa.table({"a": [1, 2, 3]})


def _swap_columns(text: str) -> str:
    """Columns 'speed' and 'heading' exchanged in the header and in every row (valid)."""
    a, b = RECORDING_COLUMNS.index("speed"), RECORDING_COLUMNS.index("heading")
    out = []
    for line in text.split("\n")[:-1]:
        fields = line.split(",")
        fields[a], fields[b] = fields[b], fields[a]
        out.append(",".join(fields))
    return "\n".join(out) + "\n"


def _cut_incomplete(src: Path, dst: Path) -> None:
    _sidecar(_incomplete)(src, dst)
    text = dst.read_text()
    dst.write_text(text[: text.rindex(",", 0, len(text) - 10)])  # the row being written


def _drop_row(i: int) -> Callable[[list[str]], list[str]]:
    return lambda lines: lines[:i] + lines[i + 1 :]


# ------------------------------------------------------------------- the kinds
BAD: dict[str, Maker] = {
    # whole file
    "empty file": _text_edit(lambda t: ""),
    "header only": _text_edit(lambda t: t.split("\n")[0] + "\n"),
    "header cut": _text_edit(lambda t: t[:30]),
    "binary garbage": _bytes_edit(lambda b: bytes(range(256)) * 8),
    "nul bytes": _bytes_edit(lambda b: b[:500] + b"\x00" * 40 + b[540:]),
    "latin-1 byte": _bytes_edit(lambda b: b.replace(b"0.0", "0.\xe9".encode("latin-1"), 1)),
    "utf-16": _bytes_edit(lambda b: b.decode().encode("utf-16")),
    "CR-only line ends": _text_edit(lambda t: t.replace("\n", "\r")),
    "U+2028 line ends": _text_edit(lambda t: t.replace("\n", "\u2028")),
    "utf-8 BOM": _bytes_edit(lambda b: b"\xef\xbb\xbf" + b),
    "semicolons": _text_edit(lambda t: t.replace(",", ";")),
    "tabs in a row": _line_edit(4, lambda s: s.replace(",", "\t", 3)),
    # header
    "missing column": _line_edit(1, lambda s: s.replace("lateral_velocity,", "")),
    "unknown column": _line_edit(1, lambda s: s.replace("reward", "rewrd")),
    "duplicated column": _line_edit(1, lambda s: s.replace("station", "speed")),
    "header with spaces": _line_edit(1, lambda s: s.replace(",", ", ")),
    "upper-case header": _line_edit(1, str.upper),
    # rows and fields
    "row cut short": _line_edit(5, lambda s: s[: s.index(",", 40)]),
    "extra field": _line_edit(4, lambda s: s + ",1.0"),
    "empty line": _line_edit(6, lambda s: ""),
    "blank line at the end": _text_edit(lambda t: t + "\n"),
    "last row cut inside the last float": _text_edit(
        lambda t: t[: t.rindex(",", 0, t.rindex(",", 0, len(t) - 2)) - 3]
    ),
    "last row cut (no newline)": _text_edit(lambda t: t[:-9]),
    "last row's newline removed": _text_edit(lambda t: t[:-1]),
    "rows deleted at the end": _lines_edit(lambda ls: ls[:-3]),
    "row appended": _lines_edit(lambda ls: ls + [ls[-1]]),
    "row deleted in the middle": _lines_edit(_drop_row(8)),
    "rows swapped": _lines_edit(lambda ls: ls[:5] + [ls[6], ls[5]] + ls[7:]),
    "row duplicated in the middle": _lines_edit(lambda ls: ls[:7] + [ls[6]] + ls[7:]),
    "quoted field": _cell(3, "speed", '"15.0"'),
    "comma decimal": _cell(3, "speed", "15,0"),
    # numbers
    "not a number": _cell(6, "speed", "15.0x"),
    "text cell": _cell(6, "heading", "abc"),
    "empty cell": _cell(3, "bias", ""),
    "NaN": _cell(7, "heading", "nan"),
    "NaN upper": _cell(7, "heading", "NaN"),
    "infinity": _cell(3, "sensor_imu_lateral", "inf"),
    "minus infinity": _cell(3, "sensor_imu_lateral", "-inf"),
    "1e400 (overflows to inf)": _cell(5, "lateral_offset", "1e400"),
    "1e308 (finite but absurd)": _cell(5, "lateral_offset", "1e308"),
    "-1e300 in a sensor": _cell(9, "sensor_camera_lateral", "-1e300"),
    "1e7 in a steering cell": _cell(9, "steering", "1e7"),
    "arabic-indic digits": _cell(4, "speed", "١٥.٠"),
    "fullwidth digits": _cell(4, "speed", "１５.０"),
    "devanagari digits": _cell(4, "bias", "-१.८"),
    "underscore in a number": _cell(4, "station", "1_0.0"),
    "leading space": _cell(4, "speed", " 15.0"),
    "trailing space": _cell(4, "speed", "15.0 "),
    "hex float": _cell(4, "speed", "0x1.ep+3"),
    "huge field": _cell(4, "speed", "9" * 100_000),
    # integers and flags
    "step as a float": _cell(3, "step", "1.0"),
    "negative step": _cell(2, "step", "-1"),
    "step gap": _cell(9, "step", "8"),
    "huge step": _cell(4, "step", "99999999999999999999999"),
    "bias_index 0.5": _cell(2, "bias_index", "0.5"),
    "huge bias_index": _cell(2, "bias_index", "123456789012345678901234567890"),
    "flag as 1": _cell(8, "terminated", "1"),
    "flag as yes": _cell(8, "truncated", "yes"),
    "flag empty": _cell(8, "truncated", ""),
    # physically impossible or inconsistent rows (issue 22 item 8)
    "bias_index outside the hypotheses": _cell(2, "bias_index", "7"),
    "bias_index changes mid-run": _cell(6, "bias_index", "-1"),
    "bias changes mid-run": _cell(6, "bias", "0.9"),
    "terminated mid-run, then more rows": _cell(5, "terminated", "true"),
    "truncated mid-run, then more rows": _cell(5, "truncated", "true"),
    "negative speed": _cell(5, "speed", "-3.0"),
    "speed above max_speed": _cell(5, "speed", "61.0"),
    "y = 1e5 m": _cell(5, "lateral_offset", "1e5"),
    # time
    "time mismatch": _cell(9, "time", "0.5"),
    "time NaN": _cell(9, "time", "nan"),
    "time of another rate": _text_edit(
        lambda t: (
            "\n".join(
                ",".join([f[0], repr(float(f[1]) * 2)] + f[2:] if i else f)
                for i, f in enumerate(ln.split(",") for ln in t.split("\n")[:-1])
            )
            + "\n"
        )
    ),
    # the CSV is not a file
    "CSV is a FIFO": _replace_csv(lambda p: os.mkfifo(p)),
    "CSV is a directory": _replace_csv(lambda p: p.mkdir()),
    "CSV is a symlink to /dev/zero": _replace_csv(lambda p: p.symlink_to("/dev/zero")),
    "CSV is a dangling symlink": _replace_csv(lambda p: p.symlink_to(p.with_name("nowhere.csv"))),
    # sidecar: file
    "missing sidecar": lambda src, dst: shutil.copyfile(src, dst),
    "empty sidecar": _sidecar_text(lambda t: ""),
    "sidecar not JSON": _sidecar_text(lambda t: "schema_version: 1"),
    "sidecar cut": _sidecar_text(lambda t: t[: len(t) // 2]),
    "sidecar with a BOM": _sidecar_text(lambda t: b"\xef\xbb\xbf" + t.encode()),
    "sidecar in latin-1": _sidecar_text(
        lambda t: t.replace("hasa_env", "h\xe4sa_env").encode("latin-1")
    ),
    "sidecar is a FIFO": _replace_sidecar(lambda p: os.mkfifo(p)),
    "sidecar is a directory": _replace_sidecar(lambda p: p.mkdir()),
    "sidecar an array": _sidecar(lambda meta: [1, 2]),
    "sidecar null": _sidecar_text(lambda t: "null"),
    "sidecar a string": _sidecar_text(lambda t: '"run"'),
    "sidecar deeply nested": _sidecar_text(lambda t: "[" * 100_000 + "]" * 100_000),
    "sidecar huge integer": _sidecar_text(
        lambda t: t.replace('"seed": ', '"seed": ' + "9" * 5000 + ', "x": ', 1)
    ),
    "sidecar NaN": _sidecar_text(lambda t: t.replace('"seed": ', '"seed": NaN, "y": ', 1)),
    # sidecar: fields
    "schema_version 2": _set(schema_version=2),
    "schema_version as text": _set(schema_version="1"),
    "schema_version true": _set(schema_version=True),
    "no schema_version": _sidecar(lambda meta: meta.pop("schema_version") and None),
    "no config": _sidecar(lambda meta: meta.pop("config") and None),
    "config a string": _set(config="track"),
    "config with a typo": _sidecar(lambda meta: meta["config"].update(sim_frequncy=100.0)),
    "config out of range": _sidecar(lambda meta: meta["config"].update(sim_frequency=-1.0)),
    "config hypotheses a dict": _sidecar(
        lambda meta: meta["config"]["markings"].update(hypotheses={"a": 0.0})
    ),
    "complete as text": _set(complete="yes"),
    "no complete": _sidecar(lambda meta: meta.pop("complete") and None),
    "negative seed": _set(seed=-3),
    "float seed": _set(seed=1.5),
    "seed as text": _set(seed="7"),
    "metadata a string": _set(metadata="P07"),
    "metadata null": _set(metadata=None),
    "metadata a list": _set(metadata=[1, 2]),
    "metadata deeply nested": _set(metadata=_nested(400)),
    "reset_options a list": _set(reset_options=[1, 2]),
    "reset_options a string": _set(reset_options="bias"),
    "columns reordered": _sidecar(lambda meta: meta["columns"].reverse()),
    "columns a string": _set(columns="step,time"),
    "steps disagree": _set(steps=3),
    "steps as text": _set(steps="many"),
    "unknown end_reason": _set(end_reason="crashed"),
    "unknown sidecar field": _set(colour="red"),
    "env_id a number": _set(env_id=7),
    "versions a list": _set(versions=["1.0"]),
    # Parquet files (hasa-rec convert's output; read by hasa-replay, hasa-rec, hasa-bench)
    "parquet of another program": _parquet(_not_ours),
    "parquet garbage": _parquet(None, raw=lambda b: b"PAR1" + bytes(range(200)) + b"PAR1"),
    "parquet cut": _parquet(None, raw=lambda b: b[: len(b) // 2]),
    "parquet NaN cell": _parquet(_table_set("lateral_offset", 4, float("nan"))),
    "parquet 1e308 cell": _parquet(_table_set("speed", 4, 1e308)),
    "parquet float32 column": _parquet(_table_cast("speed", "float32")),
    "parquet step gap": _parquet(_table_set("step", 3, 7)),
}
"""Corrupt recordings: every reader must refuse them, naming the file."""

BENIGN: dict[str, Maker] = {
    "CRLF line ends": _text_edit(lambda t: t.replace("\n", "\r\n")),
    "flags in capitals": _text_edit(lambda t: t.replace("false", "FALSE")),
    "columns in another order": _text_edit(_swap_columns),
    "incomplete (its writer crashed)": _sidecar(_incomplete),
    "incomplete, last row partly written": _cut_incomplete,
    "parquet copy": _parquet(None),
}
"""Unusual but valid recordings: every reader must load them."""


def _stem(name: str, prefix: str) -> str:
    return prefix + "".join(c if c.isalnum() else "_" for c in name).strip("_").lower()


# ------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Three good 2.5 s recordings of the illustrative driver (straight track)."""
    folder = tmp_path_factory.mktemp("good")
    drivers = population("paper", seed=0, size=1)
    runs = run_population(drivers, runs=3, seed=0, config={"time_limit": 2.5})
    return [Path(p) for p in save_runs(runs["Ill"], folder, prefix="good")]


@pytest.fixture(scope="module")
def batch(tmp_path_factory: pytest.TempPathFactory, good: list[Path]) -> dict[str, object]:
    """One folder with every bad and benign kind plus the good recordings."""
    folder = tmp_path_factory.mktemp("batch")
    for path in good:
        _copy(path, folder / path.name)
    bad = {}
    for name, make in BAD.items():
        stem = _stem(name, "bad_")
        make(good[0], folder / f"{stem}.csv")
        bad[name] = stem
    benign = {}
    for name, make in BENIGN.items():
        stem = _stem(name, "ok_")
        make(good[1], folder / f"{stem}.csv")
        benign[name] = stem
    return {"folder": folder, "bad": bad, "benign": benign, "good": [p.stem for p in good]}


def test_the_suite_has_at_least_60_kinds():
    assert len(BAD) >= 60, len(BAD)
    assert len(set(_stem(n, "") for n in BAD)) == len(BAD)  # unique file names


# ------------------------------------------------------------ one at a time
@pytest.mark.parametrize("name", list(BAD))
def test_load_recording_refuses_and_names_the_file(name: str, good: list[Path], tmp_path: Path):
    dst = tmp_path / f"{_stem(name, 'bad_')}.csv"
    BAD[name](good[0], dst)
    target = dst.with_suffix(".parquet") if name.startswith("parquet") else dst
    with pytest.raises(RecordingError) as info:
        load_paths_or_recording(target)
    err = info.value
    assert err.path is not None and err.path.stem == dst.stem, str(err)
    assert dst.stem in str(err)


def load_paths_or_recording(path: Path):
    """A Parquet file through the tools' loader, a CSV through load_recording."""
    if path.suffix == ".parquet":
        loaded = load_paths([path])
        if loaded.errors:
            raise loaded.errors[0]
        return loaded[0]
    return load_recording(path)


@pytest.mark.parametrize("name", list(BENIGN))
def test_benign_variants_load_like_the_original(name: str, good: list[Path], tmp_path: Path):
    dst = tmp_path / f"{_stem(name, 'ok_')}.csv"
    BENIGN[name](good[1], dst)
    target = dst.with_suffix(".parquet") if name.startswith("parquet") else dst
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordingWarning)
        rec = load_paths_or_recording(target)
    original = load_recording(good[1])
    n = len(rec.data)
    assert n >= len(original.data) - 1
    assert rec.data.equals(original.data.iloc[:n])


# ------------------------------------------------------------- batch tools
def _named(text: str, stems: dict[str, str]) -> list[str]:
    """The kinds whose file is not named in ``text``."""
    return [name for name, stem in stems.items() if stem not in text]


def test_load_paths_names_every_bad_file_and_loads_every_good_one(batch):
    loaded = load_paths([batch["folder"]])
    errors = "\n".join(str(e) for e in loaded.errors)
    assert not _named(errors, batch["bad"])
    stems = {Path(r.path).stem for r in loaded}
    assert stems == set(batch["good"]) | set(batch["benign"].values())


def test_hasa_replay_names_every_bad_file_and_replays_every_good_one(batch, capsys):
    code = replay_main([str(batch["folder"])])
    out, err = capsys.readouterr()
    assert code == 1
    assert not _named(err, batch["bad"])
    cut = batch["folder"] / f"{batch['benign']['incomplete, last row partly written']}.csv"
    (note,) = [ln for ln in err.splitlines() if ln.startswith("hasa-replay: warning: ")]
    assert note.startswith(f"hasa-replay: warning: {cut}: dropped the partly written line ")
    assert all(
        line.startswith("hasa-replay: error: ")
        for line in err.splitlines()
        if line[:1] != " " and line != note
    )
    for stem in [*batch["good"], *batch["benign"].values()]:
        line = next(ln for ln in out.splitlines() if f"{stem}." in ln)
        assert "replay matches the recording bit for bit" in line, line


def test_hasa_rec_info_names_every_bad_file(batch, capsys):
    folder = batch["folder"]
    files = [
        str(folder / f"{stem}.parquet")
        if (folder / f"{stem}.parquet").exists() and not (folder / f"{stem}.csv").exists()
        else str(folder / f"{stem}.csv")
        for stem in [*batch["bad"].values(), *batch["benign"].values(), *batch["good"]]
    ]
    code = rec_main(["info", *files])
    out, err = capsys.readouterr()
    assert code == 1
    assert not _named(err, batch["bad"])
    assert out.count("valid          yes") == len(batch["good"]) + len(batch["benign"])
    assert out.count("valid          NO") == len(batch["bad"])


def test_hasa_rec_convert_converts_every_good_file(batch, tmp_path, capsys):
    pytest.importorskip("pyarrow")
    code = rec_main(["convert", str(batch["folder"]), "-o", str(tmp_path)])
    out, err = capsys.readouterr()
    assert code == 1
    csv_bad = {n: s for n, s in batch["bad"].items() if not n.startswith("parquet")}
    assert not _named(err, csv_bad)
    written = {p.stem for p in tmp_path.glob("*.parquet")}
    csv_ok = {s for n, s in batch["benign"].items() if not n.startswith("parquet")}
    assert written == set(batch["good"]) | csv_ok


@pytest.mark.slow
def test_hasa_bench_skips_and_names_every_bad_file_and_scores_the_rest(batch, tmp_path, capsys):
    out = tmp_path / "out"
    args = ["paper", "--recordings", str(batch["folder"]), "--min-duration", "0.5",
            "--allow-incomplete", "--out", str(out), "--workers", "1", "--quiet", "--no-plots"]  # fmt: skip
    code = bench_main(args)
    err = capsys.readouterr().err
    assert code == 1, err
    assert not _named(err, batch["bad"])
    doc = json.loads((out / "results.json").read_text())
    skipped = "\n".join(s["file"] for s in doc["skipped"])
    assert not _named(skipped, batch["bad"])
    assert all(s["reason"] for s in doc["skipped"])
    scored = {Path(p).stem for d in doc["drivers"] for p in d["recordings"]}
    assert scored == set(batch["good"]) | set(batch["benign"].values())
    runs = {(r["driver"], r["run"]) for r in doc["runs_estimation"] if r["model"] == "oracle"}
    assert len(runs) == len(scored) - 1  # every run but the training run is estimated
    assert all(np.isfinite(r["lateral_rmse"]) for r in doc["runs_estimation"])


def test_hasa_bench_names_the_line_and_column_of_a_skipped_recording(good, tmp_path):
    """hasa-bench's list of skipped recordings says where in the file, as hasa-rec and
    hasa-replay do (it said the reason alone)."""
    for path in good:
        _copy(path, tmp_path / path.name)
    BAD["not a number"](good[0], tmp_path / "bad_speed.csv")
    config = ProtocolConfig(recordings=str(tmp_path), min_duration=0.5, allow_incomplete=True)
    plan = recording_plan(config)
    (skip,) = [s for s in plan.skipped if "bad_speed" in s["file"]]
    assert skip["reason"] == "line 6, column 'speed': not a number: '15.0x'", skip
    assert f"skipped {skip['file']}: line 6, column 'speed': " in "\n".join(plan.notes)


def test_other_json_documents_in_a_folder_are_not_taken_for_orphan_sidecars(good, tmp_path):
    _copy(good[0], tmp_path / good[0].name)
    (tmp_path / "session.json").write_text('{"format": "hasa_env study session", "runs": []}')
    (tmp_path / "orphan.json").write_text('{"schema_version": 1}')
    loaded = load_paths([tmp_path])
    assert len(loaded) == 1
    assert [e.path.name for e in loaded.errors] == ["orphan.csv"]
