"""hasa-bench against hostile user models, bad recording folders and bad addresses.

- user models that mutate their data, hang, ``sys.exit`` or ``os._exit``: each is
  that model's failure, every other number stays what it is without them;
- recordings: quality gates, the training file, curved runs of any driver,
  degenerate runs reported and left out of the means;
- the results folder is only replaced with ``--overwrite``;
- a Dask scheduler address that is wrong or dead fails within seconds, in one line.
"""

from __future__ import annotations

import json
import socket
import sys
import textwrap
import threading
import time
from dataclasses import replace
from pathlib import Path

import pytest
from _recording_files import crash

from benchmarks.executor import SchedulerError, check_scheduler
from benchmarks.protocol import BenchmarkError, ProtocolConfig, run_protocol
from benchmarks.report import format_tables
from benchmarks.schema import folder_problems
from hasa_cli.bench import main
from hasa_env.drivers import population, run_population, save_runs

SMALL = {"seeds": (0,), "drivers": 2, "runs": 2, "ill_runs": 3, "duration": 4.0, "curved_runs": 0,
         "population": "paper-pi"}  # fmt: skip
SMALL_ARGS = ["--seeds", "0", "--population", "paper-pi", "--drivers", "2", "--runs", "2",
              "--ill-runs", "3", "--duration", "4", "--curved-runs", "0"]  # fmt: skip

HOSTILE = '''
"""User models that misbehave, for the isolation tests."""
import os
import sys
import time

from hasa_env.steering import GeneralizedModel


class Mutator(GeneralizedModel):
    """Adds 1 m to every run's lateral offset and poisons the shared config it is given."""

    model_type = "hostile_mutator"

    def __init__(self, **kwargs):
        kwargs.setdefault("name", "mutator")
        super().__init__(**kwargs)

    def features(self, run, road=None):
        if "lateral_offset" in run.columns:  # a run (scoring also passes its features)
            run.loc[:, "lateral_offset"] += 1.0
            run.loc[:, "sensor_steering"] *= 1.5
        if "config" in run.attrs:
            run.attrs["config"]["noise"]["camera"] = 3.0
        return super().features(run, road)


class SleepyFit(GeneralizedModel):
    model_type = "hostile_sleepy"

    def __init__(self, **kwargs):
        kwargs.setdefault("name", "sleepy_fit")
        super().__init__(**kwargs)

    def fit(self, runs, road=None, **kwargs):
        time.sleep(60)


class ExitInFit(GeneralizedModel):
    model_type = "hostile_exit"

    def __init__(self, **kwargs):
        kwargs.setdefault("name", "exit_in_fit")
        super().__init__(**kwargs)

    def fit(self, runs, road=None, **kwargs):
        sys.exit(3)


class HardExitInPredict(GeneralizedModel):
    model_type = "hostile_hard_exit"

    def __init__(self, **kwargs):
        kwargs.setdefault("name", "hard_exit")
        super().__init__(**kwargs)

    def predict_features(self, features):
        os._exit(7)
'''


@pytest.fixture(scope="module")
def hostile_module(tmp_path_factory: pytest.TempPathFactory) -> str:
    folder = tmp_path_factory.mktemp("hostile_models")
    (folder / "bench_hostile_models.py").write_text(textwrap.dedent(HOSTILE))
    sys.path.insert(0, str(folder))
    yield "bench_hostile_models"
    sys.path.remove(str(folder))
    sys.modules.pop("bench_hostile_models", None)


def _rows(result, models=("two_point", "generalized", "no_steering", "oracle")) -> dict:
    doc = result.to_json_dict()
    return {
        key: [r for r in doc[key] if r["model"] in models]
        for key in ("runs_steering", "runs_estimation", "steering", "estimation")
    }


@pytest.fixture(scope="module")
def reference():
    return run_protocol(ProtocolConfig(**SMALL), workers=1)


def test_a_model_that_mutates_its_data_changes_nothing_else_even_in_process(
    hostile_module, reference
):
    config = ProtocolConfig(**SMALL, model_time_limit=None)  # no isolation: in this process
    result = run_protocol(config, [f"{hostile_module}:Mutator"], workers=1)
    assert result.errors == []
    assert _rows(result) == _rows(reference)
    mutator = [r for r in result.runs_steering if r["model"] == "mutator"]
    assert mutator and all(r["rmse"] > 0 for r in mutator)


def test_hanging_and_exiting_models_fail_alone(hostile_module, reference):
    specs = [f"{hostile_module}:{name}" for name in
             ("Mutator", "SleepyFit", "ExitInFit", "HardExitInPredict")]  # fmt: skip
    started = time.perf_counter()
    result = run_protocol(ProtocolConfig(**SMALL, model_time_limit=2.0), specs, workers=1)
    assert time.perf_counter() - started < 45  # the sleeping fit was stopped at 2 s
    errors = {e["model"]: e for e in result.errors}
    assert set(errors) == {"sleepy_fit", "exit_in_fit", "hard_exit"}
    assert errors["sleepy_fit"]["stage"] == "fit"
    assert "longer than the time limit of 2 s" in errors["sleepy_fit"]["message"]
    assert errors["exit_in_fit"]["stage"] == "fit"
    assert "SystemExit: 3" in errors["exit_in_fit"]["message"]
    assert errors["hard_exit"]["stage"] == "score"
    assert "exit status 7" in errors["hard_exit"]["message"]
    assert _rows(result) == _rows(reference)
    assert {r["model"] for r in result.steering} == {
        "two_point",
        "generalized",
        "road_blind",
        "mutator",
    }


def test_a_module_that_exits_while_importing_is_an_input_error(tmp_path, capsys, monkeypatch):
    (tmp_path / "exits_on_import.py").write_text("import os\nos._exit(5)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    code = main(["score", "exits_on_import:Model", *SMALL_ARGS, "--out", str(tmp_path / "o"),
                 "--quiet", "--model-time-limit", "20"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and not (tmp_path / "o").exists()
    assert "exits_on_import:Model" in err and "exit status 5" in err and "(import)" in err


# ------------------------------------------------------------------ recordings
@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Ill: 3 runs of 3 s, one of 1 s, one incomplete; driver '1': 2 runs, one standing, one
    curved."""
    root = tmp_path_factory.mktemp("recs")
    ill, one = population("paper-pi", seed=0, size=2)
    config = {"time_limit": 3.0}
    save_runs(run_population([ill], runs=3, seed=0, config=config)["Ill"], root / "Ill", "a")
    save_runs(run_population([ill], runs=1, seed=1, config={"time_limit": 1.0})["Ill"],
              root / "Ill", "short")  # fmt: skip
    (incomplete,) = save_runs(
        run_population([ill], runs=1, seed=2, config=config)["Ill"], root / "Ill", "crash"
    )
    meta = json.loads(incomplete.with_suffix(".json").read_text())
    meta.update(complete=False, steps=None, end_reason=None, finished=None)
    incomplete.with_suffix(".json").write_text(json.dumps(meta))
    save_runs(run_population([one], runs=2, seed=3, config=config)["1"], root / "1", "a")
    standing = {"initial_state": {"speed": 0.0}, "time_limit": 3.0}
    save_runs(run_population([one], runs=1, seed=4, config=standing)["1"], root / "1", "stand")
    curved = run_population([one], runs=1, seed=5, env_id="hasa_env/LaneKeepingCurved-v0",
                            config=config)["1"]  # fmt: skip
    save_runs(curved, root / "1", "curved")
    return root


def test_recordings_quality_gates_curved_runs_and_degenerate_runs(recordings, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["paper", "--recordings", str(recordings), "--min-duration", "2",
                 "--out", str(out), "--workers", "1", "--quiet", "--no-plots"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 1
    doc = json.loads((out / "results.json").read_text())
    skipped = {Path(s["file"]).name: s["reason"] for s in doc["skipped"]}
    assert set(skipped) == {"short_000.csv", "crash_000.csv"}
    assert "lasts 1.00 s, shorter than the minimum of 2 s" in skipped["short_000.csv"]
    assert skipped["crash_000.csv"].startswith("incomplete")
    assert "short_000.csv" in err and "crash_000.csv" in err
    # the standing run is reported and left out of every mean (for every model)
    (degenerate,) = doc["degenerate"]
    assert Path(degenerate["file"]).name == "stand_000.csv"
    assert "the car stands" in degenerate["reason"] and "stand_000.csv" in err
    rows = [r for r in doc["estimation"] if r["driver"] == "1"]
    assert rows and all(r["n_runs"] == 2 and r["degenerate_runs"] == 1 for r in rows)
    # curved recordings of a driver other than the illustrative one are scored, not dropped
    assert {r["driver"] for r in doc["curved"]} == {"1"}
    assert any("trained on" in n and "a_000.csv" in n for n in doc["notes"])
    assert (out / "report.html").is_file() and folder_problems(out) == []


def test_a_repaired_recording_is_named_once_on_stderr_and_in_the_notes(tmp_path, capsys):
    """A folder of two recordings, the second's writer crashed inside its last line: it loads
    without that line and is scored (--allow-incomplete); what loading repaired is one warning
    line naming the file, --quiet or not, and a note of results.json; the complete recording
    beside it adds nothing."""
    (ill,) = population("paper-pi", seed=0, size=1)
    runs = run_population([ill], runs=2, seed=0, config={"time_limit": 3.0})["Ill"]
    good, crashed = save_runs(runs, tmp_path / "recs", "a")
    crash(crashed)
    out = tmp_path / "out"
    code = main(["paper", "--recordings", str(tmp_path / "recs"), "--min-duration", "2",
                 "--allow-incomplete", "--out", str(out), "--workers", "1", "--quiet",
                 "--no-plots"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 0, err
    (warning,) = [ln for ln in err.splitlines() if ln.startswith("hasa-bench: warning: ")]
    assert warning.startswith(f"hasa-bench: warning: {crashed}: dropped the partly written line ")
    assert str(good) not in err
    doc = json.loads((out / "results.json").read_text())
    assert doc["skipped"] == [] and sorted(doc["drivers"][0]["recordings"]) == [
        str(good),
        str(crashed),
    ]
    repaired = [n for n in doc["notes"] if "dropped the partly written line" in n]
    assert repaired == [warning.removeprefix("hasa-bench: warning: ")]


def test_the_training_file_can_be_chosen_and_a_bad_one_is_refused(recordings):
    base = ProtocolConfig(recordings=str(recordings), min_duration=2.0)
    chosen = recordings / "Ill" / "a_002.csv"
    result = run_protocol(replace(base, training_file=str(chosen)), workers=1)
    assert any(f"trained on {chosen}" in n for n in result.notes)
    assert {r["run"] for r in result.runs_steering if r["driver"] == "Ill"} == {0, 1}
    header = format_tables(result).splitlines()[0]  # (it said "run 0 of Ill (each seed's)")
    assert f"models fitted on the recording {chosen}" in header, header
    alone = format_tables(run_protocol(base, workers=1)).splitlines()[0]
    assert "models fitted on run 0 of Ill" in alone and "each seed's" not in alone, alone
    with pytest.raises(BenchmarkError, match="short_000.csv is not usable: lasts 1.00 s"):
        run_protocol(replace(base, training_file=str(recordings / "Ill" / "short_000.csv")))
    with pytest.raises(BenchmarkError, match="not one of the recordings"):
        run_protocol(replace(base, training_file=str(recordings / "nowhere.csv")))


# ------------------------------------------------------------------- the folder
def test_a_previous_result_is_only_replaced_with_overwrite(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.json").write_text('{"format": "hasa_bench.results", "old": true}')
    (out / "stale.png").write_text("old figure")
    args = ["paper", *SMALL_ARGS, "--drivers", "1", "--out", str(out), "--quiet", "--no-plots",
            "--workers", "1"]  # fmt: skip
    assert main(args) == 2
    assert "holds a previous result; --overwrite replaces it" in capsys.readouterr().err
    assert json.loads((out / "results.json").read_text())["old"] is True
    assert main([*args, "--overwrite"]) == 0
    assert "old" not in json.loads((out / "results.json").read_text())
    assert not (out / "stale.png").exists()  # the new result replaced the folder as a whole
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("keep me")
    assert main(["paper", *SMALL_ARGS, "--out", str(mine), "--overwrite", "--quiet"]) == 2
    assert "holds no hasa-bench result" in capsys.readouterr().err
    assert (mine / "thesis.tex").read_text() == "keep me"


# ------------------------------------------------------------------ scheduler
def _server(reply: bytes | None) -> int:
    """A local TCP server that sends ``reply`` to each client (None: never answers)."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(8)

    def serve() -> None:
        while True:
            conn, _ = sock.accept()
            if reply is not None:
                conn.sendall(reply)
            threading.Thread(target=lambda c=conn: time.sleep(60), daemon=True).start()

    threading.Thread(target=serve, daemon=True).start()
    return sock.getsockname()[1]


@pytest.mark.parametrize(
    ("address", "kind", "text"),
    [
        ("not-an-address", "address", "is not valid"),
        ("http://host:8786", "address", "unknown scheme 'http'"),
        ("tcp://127.0.0.1:99999", "address", "port"),
        ("tcp://127.0.0.1:9", "unreachable", "cannot connect"),
        ("tcp://no-such-host.invalid:8786", "unreachable", "cannot connect"),
    ],
)
def test_bad_scheduler_addresses_fail_at_once_in_one_line(address, kind, text):
    pytest.importorskip("distributed")
    started = time.perf_counter()
    with pytest.raises(SchedulerError, match=text) as info:
        check_scheduler(address)
    assert info.value.kind == kind and "\n" not in str(info.value)
    assert time.perf_counter() - started < 5


@pytest.mark.parametrize(
    "reply", [b"SSH-2.0-OpenSSH_9.6\r\n" * 4, b"HTTP/1.1 200 OK\r\n\r\n", None]
)
def test_a_server_that_is_no_dask_scheduler_is_named_within_the_timeout(reply):
    pytest.importorskip("distributed")
    port = _server(reply)
    started = time.perf_counter()
    with pytest.raises(SchedulerError, match="no Dask scheduler at tcp://127.0.0.1") as info:
        check_scheduler(f"127.0.0.1:{port}", timeout=1.5)
    assert info.value.kind == "not_dask"
    assert time.perf_counter() - started < 4


def test_the_cli_says_it_in_one_line_and_exits_3(tmp_path, capsys):
    pytest.importorskip("distributed")
    started = time.perf_counter()
    code = main(["paper", "--scheduler", "tcp://127.0.0.1:9", "--out", str(tmp_path / "o")])
    assert code == 3 and time.perf_counter() - started < 10
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hasa-bench: error: no Dask scheduler")
    assert main(["paper", "--scheduler", "not-an-address", "--out", str(tmp_path / "o")]) == 2
