"""Study files, schedules, session files and the study session (headless, virtual wheel)."""

from __future__ import annotations

import hashlib
import json
import os
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from _input_helpers import virtual_or_skip

from hasa_env.devices import InputManager, JoystickCalibration
from hasa_env.devices.calibration import shipped_calibration
from hasa_env.devices.virtual import VirtualJoystick
from hasa_env.drivers import SyntheticDriver, population
from hasa_env.envs.lane_keeping import LaneKeepingEnv
from hasa_env.recording import load_recording
from hasa_env.scenarios import SCENARIOS
from hasa_env.session import (
    DriveSettings,
    SessionError,
    SessionFile,
    Study,
    StudyError,
    StudySession,
    VirtualWheelDriver,
)
from hasa_env.session.session_file import SessionLock
from hasa_env.session.study import participant_slot, williams_square

PAPER = Path(__file__).resolve().parents[1] / "studies" / "paper.toml"
LANE_SHIFT = PAPER.with_name("lane_shift.toml")


def small(**sections) -> Study:
    doc = {
        "study": {"name": "small", "seed": 3},
        "runs": {"seconds": 1.0, "countdown": 0.0},
        "practice": {"runs": 1},
        "measured": {"runs": 4},
    }
    for key, value in sections.items():
        doc[key] = {**doc.get(key, {}), **value}
    return Study.from_dict(doc)


def write(tmp_path: Path, text: str, name: str = "study.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# ------------------------------------------------------------------ study files
def test_the_paper_study_is_the_papers_protocol():
    study = Study.load(PAPER)
    doc = study.document
    assert doc["measured"]["runs"] == 10 and doc["runs"]["seconds"] == 30.0
    assert doc["runs"]["speed"] == 15.0 and doc["runs"]["lateral_offset"] == -0.5
    assert doc["runs"]["speed_control"] == "free" and doc["runs"]["min_speed"] > 0  # no stopping
    assert study.hypotheses == [0.0, -1.8]  # two lane hypotheses 1.8 m apart
    assert study.view_options.ghosts is False and study.view_options.hud == ()
    config = study.env_config("straight")
    assert config["time_limit"] == 30.0 and config["track"] == "straight"
    runs = study.schedule_for("P07", None, study.seed)
    measured = [r for r in runs if r.block == "measured"]
    assert len(measured) == 10 and Counter(r.bias for r in measured) == {0.0: 5, -1.8: 5}
    assert all(r.track == "straight" for r in runs)
    # the start state is the env config's (where a scenario's keys can still apply)
    assert study.reset_options(measured[0]) == {"steering": 0.0, "bias": measured[0].bias}
    assert config["scenario"] == "paper" and study.scenario_overrides() == []
    init = config["initial_state"]
    assert (init["lateral_offset"], init["speed"], init["heading"]) == (-0.5, 15.0, 0.0)
    assert not init["between_hypotheses"] and init["lateral_offset_std"] == 0.0


def test_the_lane_shift_study_is_the_paper_protocol_in_the_lane_shift_scenario():
    paper, shift = Study.load(PAPER), Study.load(LANE_SHIFT)
    assert shift.scenario == "lane_shift" and shift.scenario_overrides() == []
    config = shift.env_config("straight")
    assert config["scenario"] == "lane_shift"
    assert config["road"]["lane_shifts"] == SCENARIOS["lane_shift"].config["road"]["lane_shifts"]
    assert config == paper.env_config("straight") | {
        "scenario": "lane_shift", "road": config["road"]}  # fmt: skip
    # the same protocol: every key but the name, the texts and the scenario
    same = ("format_version", "participant", "practice", "measured", "schedule", "env", "view")
    assert {k: shift.document[k] for k in same} == {k: paper.document[k] for k in same}
    assert {**shift.document["runs"], "scenario": "paper"} == paper.document["runs"]
    assert [(r.bias, r.seed) for r in shift.schedule_for("P03", None, 1)] == [
        (r.bias, r.seed) for r in paper.schedule_for("P03", None, 1)]  # fmt: skip
    env = LaneKeepingEnv(config=config)
    try:
        _, info = env.reset(
            seed=1, options=shift.reset_options(shift.schedule_for("P01", None, 1)[1])
        )
    finally:
        env.close()
    assert info["lateral_offset"] == -0.5 and info["speed"] == 15.0


def _paper_in(tmp_path: Path, scenario: str, drop: tuple[str, ...] = ()) -> Study:
    """studies/paper.toml with ``runs.scenario`` = ``scenario`` and the ``[runs]`` or
    ``[env]`` lines starting with ``drop`` left out."""
    lines = [line for line in PAPER.read_text().splitlines()
             if not line.startswith(drop or ("\0",))]  # fmt: skip
    text = "\n".join(lines).replace("[runs]\n", f'[runs]\nscenario = "{scenario}"\n', 1)
    return Study.load(write(tmp_path, text + "\n"))


def _start(study: Study, bias: float) -> dict:
    env = LaneKeepingEnv(config=study.env_config("straight"))
    try:
        run = next(r for r in study.schedule_for("P01", None, 1) if r.bias == bias)
        return env.reset(seed=run.seed, options=study.reset_options(run))[1]
    finally:
        env.close()


def test_a_scenario_applies_under_the_study_files_own_keys(tmp_path):
    # late_ambiguity in a copy of paper.toml: the file's speed and lateral_offset are
    # given, yet the car starts halfway between the hypotheses' centres
    late = _paper_in(tmp_path, "late_ambiguity")
    assert late.env_config("straight")["initial_state"]["between_hypotheses"] is True
    for bias, halfway in ((0.0, -0.9), (-1.8, 0.9)):
        info = _start(late, bias)
        assert info["lateral_offset"] == pytest.approx(halfway) and info["speed"] == 15.0
    assert late.scenario_overrides() == [("runs.speed", 15.0, 25.0)]
    # without [runs] speed, the scenario's 25 m/s
    assert _start(_paper_in(tmp_path, "late_ambiguity", ("speed =",)), 0.0)["speed"] == 25.0
    # close_hypotheses: paper.toml's hypotheses and start win (and are listed) ...
    close = _paper_in(tmp_path, "close_hypotheses")
    assert close.hypotheses == [0.0, -1.8]
    assert {k for k, _, _ in close.scenario_overrides()} == {
        "env.markings.hypotheses", "runs.lateral_offset"}  # fmt: skip
    # ... and without them the scenario's: its hypotheses schedule the runs, its start
    bare = _paper_in(tmp_path, "close_hypotheses", ("lateral_offset", "markings.hypotheses"))
    assert bare.hypotheses == [0.0, -0.3] and bare.scenario_overrides() == []
    biases = {r.bias for r in bare.schedule_for("P01", None, 1) if r.block == "measured"}
    assert biases == {0.0, -0.3}
    init = bare.env_config("straight")["initial_state"]
    assert (init["lateral_offset"], init["lateral_offset_std"]) == (0.0, 0.25)
    # off_centre_drivers: only the hypotheses are env keys (the offsets are drivers')
    off = _paper_in(tmp_path, "off_centre_drivers", ("markings.hypotheses",))
    assert off.hypotheses == [0.0, -0.8]


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("seconds = 30.0", "seconds = -3.0",
         r"study.toml, line \d+: key 'runs.seconds' = -3.0 is out of range: allowed \(0, 3600\] s"),
        ('kind = "latin_square"', 'kind = "latin"',
         r"line \d+: key 'schedule.kind' = 'latin' is not allowed: one of 'latin_square'"),
        ("break_every = 5", "break_evry = 5",
         r"unknown key 'measured.break_evry' \(allowed keys here: break_every, break_seconds"),
        ("markings.hypotheses = [0.0, -1.8]", "markings.hypotheses = [0.0, -31.8]",
         r"line \d+: in \[env\]: config key 'markings.hypotheses\[1\]' = -31.8 is out of range"),
        ("[participant.age_band]", "[participant.name]",
         r"participant field 'name' would identify the participant"),
        ("min_speed = 10.0", "min_speed = 20.0",
         r"'runs.min_speed' = 20 m/s is above the start speed runs.speed = 15 m/s"),
        ("break_every = 5", "break_every = 5 5", r"not valid TOML: .*\(at line \d+, column \d+\)"),
        ("[env]", "[env]\ntrack = 'curved'", r"'env.track' is set by practice.track"),
        ('hud = []', 'hud = ["clock"]', r"key 'view.hud' has the unknown item 'clock'"),
        ("seconds = 30.0", 'seconds = 30.0\nscenario = "lane_shif"',
         r"study.toml, line \d+: key 'runs.scenario' = 'lane_shif' is not allowed: one of "
         r"'paper', 'lane_shift', 'late_ambiguity', 'close_hypotheses', 'off_centre_drivers', "
         r"'lane_change'"),
        ("[env]", '[env]\nscenario = "lane_shift"', r"line \d+: key 'env.scenario' is set by "
         r"runs.scenario; remove it from \[env\]"),
        ("lateral_offset = -0.5", "lateral_offset = 5.5",
         r"line \d+: key 'runs.lateral_offset' = 5.5 is out of range: allowed \[-5, 5\] m"),
    ],
)  # fmt: skip
def test_bad_study_files_name_file_line_key_and_range(tmp_path, old, new, message):
    text = PAPER.read_text()
    assert old in text
    path = write(tmp_path, text.replace(old, new, 1))
    with pytest.raises(StudyError, match=message):
        Study.load(path)


def test_the_line_named_is_the_keys_line(tmp_path):
    text = PAPER.read_text().replace("seconds = 30.0", "seconds = -3.0")
    line = next(i for i, t in enumerate(text.splitlines(), 1) if t.startswith("seconds = -3"))
    with pytest.raises(StudyError, match=rf"study.toml, line {line}: key 'runs.seconds'"):
        Study.load(write(tmp_path, text))


def test_json_study_files_and_missing_files(tmp_path):
    path = write(tmp_path, json.dumps({"study": {"name": "j", "seed": 1}}), "s.json")
    study = Study.load(path)
    assert study.document["measured"]["runs"] == 10 and study.sha256
    with pytest.raises(StudyError, match=r"s2.json, line 1: not valid JSON"):
        Study.load(write(tmp_path, "{nope", "s2.json"))
    with pytest.raises(StudyError, match="no such study file"):
        Study.load(tmp_path / "missing.toml")
    with pytest.raises(StudyError, match=r"key 'study.name' must be a string .*letters, digits"):
        Study.from_dict({"study": {"name": "../x"}})
    with pytest.raises(StudyError, match="key 'study' is missing"):
        Study.from_dict({})


def test_participant_metadata_is_checked():
    study = Study.load(PAPER)
    answers = study.check_metadata({"age_band": "25-34", "licence_years": "12",
                                    "simulator_experience": "none"})  # fmt: skip
    assert answers == {"age_band": "25-34", "licence_years": 12, "simulator_experience": "none"}
    with pytest.raises(StudyError, match=r"'age_band' = '30' is not allowed: one of '18-24'"):
        study.check_metadata({**answers, "age_band": "30"})
    with pytest.raises(
        StudyError, match=r"'licence_years' = 90 is out of range: allowed \[0, 80\]"
    ):
        study.check_metadata({**answers, "licence_years": "90"})
    with pytest.raises(StudyError, match="'licence_years' must be an integer, got '1.5'"):
        study.check_metadata({**answers, "licence_years": "1.5"})
    with pytest.raises(StudyError, match="participant field 'age_band' is required"):
        study.check_metadata({"licence_years": 3, "simulator_experience": "some"})
    with pytest.raises(StudyError, match="unknown participant field 'name'"):
        study.check_metadata({**answers, "name": "Ann"})
    (field,) = [f for f in study.participant_fields if f.key == "licence_years"]
    assert field.question() == "Years since the driving licence (an integer in [0, 80] years): "


# -------------------------------------------------------------------- schedules
def test_williams_squares_are_balanced():
    for n in (2, 3, 4, 5):
        rows = williams_square(n)
        assert len(rows) == (n if n % 2 == 0 else 2 * n)
        assert all(sorted(r) == list(range(n)) for r in rows)  # each row a permutation
        for position in range(n):  # each treatment equally often at each position
            assert len(set(Counter(r[position] for r in rows).values())) == 1
        pairs = Counter((r[i], r[i + 1]) for r in rows for i in range(n - 1))
        assert len(pairs) == n * (n - 1) and len(set(pairs.values())) == 1  # carry-over


def test_schedules_balance_biases_within_and_across_participants():
    study = small(measured={"runs": 4})
    first = [r.bias for r in study.schedule_for("P01", None, 3) if r.block == "measured"]
    second = [r.bias for r in study.schedule_for("P02", None, 3) if r.block == "measured"]
    assert first == [0.0, -1.8, 0.0, -1.8] and second == [-1.8, 0.0, -1.8, 0.0]
    assert participant_slot("P07") == 7 and participant_slot("anon") is None
    with pytest.raises(StudyError, match="needs the participant's number: .* --slot N"):
        study.schedule_for("anon", None, 3)
    assert study.schedule_for("anon", 2, 3)[1].bias == -1.8
    counter = small(schedule={"kind": "counterbalanced"}, measured={"runs": 6})
    for who in ("P01", "P02", "P03"):
        biases = [r.bias for r in counter.schedule_for(who, None, 3) if r.block == "measured"]
        assert Counter(biases) == {0.0: 3, -1.8: 3}
    random = small(schedule={"kind": "random"}, measured={"runs": 20})
    drawn = [r.bias for r in random.schedule_for("x", None, 3)]
    assert drawn == [r.bias for r in random.schedule_for("x", None, 3)]  # reproducible
    assert drawn != [r.bias for r in random.schedule_for("y", None, 3)]
    fixed = small(schedule={"kind": "fixed", "order": [-1.8, -1.8, 0.0, 0.0]})
    assert [r.bias for r in fixed.schedule_for("x", None, 3)][1:] == [-1.8, -1.8, 0.0, 0.0]
    with pytest.raises(StudyError, match=r"'schedule.order' has 2 biases for measured.runs = 4"):
        small(schedule={"kind": "fixed", "order": [0.0, 0.0]})
    with pytest.raises(StudyError, match=r"'schedule.order\[0\]' = -1 is not allowed: one of"):
        small(schedule={"kind": "fixed", "order": [-1.0, 0.0, 0.0, 0.0]})


def test_run_seeds_depend_on_study_seed_participant_and_position():
    study = small()
    a = study.schedule_for("P01", None, 3)
    assert [r.seed for r in a] == [r.seed for r in study.schedule_for("P01", None, 3)]
    assert len({r.seed for r in a}) == len(a)
    assert a[0].seed != study.schedule_for("P02", None, 3)[0].seed
    assert a[0].seed != study.schedule_for("P01", None, 4)[0].seed
    assert [r.prefix for r in a] == ["practice_01"] + [f"measured_0{i}" for i in range(1, 5)]


def test_no_stopping_and_constant_speed():
    free = DriveSettings(participant="p", min_speed=10.0)
    assert free.applied_acceleration(-5.0, 15.0, 0.01) == -5.0
    assert free.applied_acceleration(-5.0, 10.02, 0.01) == pytest.approx(-2.0)  # stops at 10
    assert free.applied_acceleration(-5.0, 10.0, 0.01) == 0.0
    assert free.applied_acceleration(2.0, 9.0, 0.01) == 2.0  # throttle is free below too
    constant = DriveSettings(participant="p", speed_control="constant")
    assert constant.applied_acceleration(3.0, 15.0, 0.01) == 0.0
    with pytest.raises(ValueError, match="'speed_control' = 'cruise' is not allowed"):
        DriveSettings(participant="p", speed_control="cruise")


# ------------------------------------------------------------------ session file
def test_session_file_recovery_and_lock(tmp_path):
    study = small()
    schedule = study.schedule_for("P01", None, 3)
    record = SessionFile.create(tmp_path / "P01", study, "P01", 1, {}, 3, schedule)
    with pytest.raises(SessionError, match="a session file exists already"):
        SessionFile.create(tmp_path / "P01", study, "P01", 1, {}, 3, schedule)
    a = record.start_attempt(schedule[0], "keyboard")
    record.finish_attempt(a, "truncated", 100)
    b = record.start_attempt(schedule[1], "keyboard")
    assert [r.position for r in record.remaining()] == [2, 3, 4, 5]
    again = SessionFile.open(record.path)  # as a new process finds it after a kill
    (marked,) = again.recover()
    assert marked["status"] == "aborted" and marked["end_reason"] == "interrupted"
    assert [r.position for r in again.remaining()] == [2, 3, 4, 5]  # repeat_aborted
    again.doc["study"]["spec"]["runs"]["repeat_aborted"] = False
    assert [r.position for r in again.remaining()] == [3, 4, 5]  # or go on after it
    assert b["position"] == 2
    # the lock (flock): a holder refuses a second one; released, it can be taken again
    holder = SessionLock(record.path.parent)
    holder.acquire()
    assert holder.path.read_text().split()[0] == str(os.getpid())
    with pytest.raises(SessionError, match=rf"another program \(process {os.getpid()}\) is run"):
        again.acquire()
    holder.release()
    assert not holder.path.exists()
    holder.path.write_text("1 otherhost\n")  # a file left behind locks nothing
    again.acquire()
    assert again.lock_path.read_text().split()[0] == str(os.getpid())
    again.release()
    assert not again.lock_path.exists()
    record.path.write_text('{"format": "hasa_env.study_session", "format_version": 2}')
    with pytest.raises(SessionError, match="field 'format_version' = 2 is not allowed"):
        SessionFile.open(record.path)


# ------------------------------------------------------------- study sessions
def _wheel_session(tmp_path, pg, study, participant="P01", hook_extra=None, **kw):
    wheel = virtual_or_skip(VirtualJoystick.g29)
    g29 = shipped_calibration("g29")
    fields = {k: getattr(g29, k) for k in g29.__dataclass_fields__ if k != "device"}
    profile = JoystickCalibration(**{**fields, "match_names": (wheel.name,)})
    inputs = InputManager(profiles=[profile], pygame_module=pg)
    params = {p.name: p for p in population("paper", seed=0)}["2"]
    driver = VirtualWheelDriver(wheel, SyntheticDriver(params), profile)

    def hook(session):
        driver(session)
        if hook_extra is not None:
            hook_extra(session)

    session = StudySession(study, participant, inputs, output=tmp_path, realtime=False,
                           hook=hook, log=lambda m: None, **kw)  # fmt: skip
    return session, wheel


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_stopped_session_resumes_at_the_next_run_and_overwrites_nothing(tmp_path, pg):
    study = small(runs={"seconds": 1.0, "min_speed": 14.9})
    stop = {"done": False}

    def escape_in_measured_run_2(session):
        if (not stop["done"] and session.state == "driving" and session.run_index == 2
                and session.steps == 40):  # fmt: skip
            pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_ESCAPE, mod=0))
            stop["done"] = True

    session, wheel = _wheel_session(tmp_path, pg, study, hook_extra=escape_in_measured_run_2)
    try:
        outcome = session.run()
    finally:
        session.close()
        wheel.detach()
    assert outcome.state == "quit" and not outcome.resumed
    folder = tmp_path / "P01"
    kept = {p.name: _digest(p) for p in folder.iterdir() if p.suffix in (".csv", ".json", ".tsv")
            and p.name != "session.json"}  # fmt: skip
    assert "measured_02_000.csv" in kept
    stopped = load_recording(folder / "measured_02_000.csv")
    assert stopped.steps == 40 and stopped.meta["end_reason"] == "stopped"
    meta = stopped.meta["metadata"]
    assert meta["study"]["block"] == "measured" and meta["study"]["number"] == 2
    assert meta["view"]["ghosts"] is False and meta["participant"] == "P01"
    assert stopped.meta["reset_options"]["bias"] == meta["study"]["bias"] == -1.8

    session, wheel = _wheel_session(tmp_path, pg, study)
    try:
        resumed = session.run()
    finally:
        session.close()
        wheel.detach()
    assert resumed.state == "complete" and resumed.resumed
    assert [r.path.name for r in resumed.results] == [
        "measured_02_001.csv", "measured_03_000.csv", "measured_04_000.csv"]  # fmt: skip
    for name, digest in kept.items():  # nothing recorded before was touched
        assert _digest(folder / name) == digest, name
    doc = json.loads((folder / "session.json").read_text())
    statuses = [(a["block"], a["number"], a["attempt"], a["status"], a["end_reason"])
                for a in doc["attempts"]]  # fmt: skip
    assert statuses == [
        ("practice", 1, 0, "completed", "truncated"),
        ("measured", 1, 0, "completed", "truncated"),
        ("measured", 2, 0, "aborted", "stopped"),
        ("measured", 2, 1, "completed", "truncated"),
        ("measured", 3, 0, "completed", "truncated"),
        ("measured", 4, 0, "completed", "truncated"),
    ]
    assert doc["state"] == "complete" and [s["ended"] for s in doc["sessions"]] == [
        "quit",
        "complete",
    ]
    assert doc["sessions"][0]["devices"]["source_at_start"].startswith("joystick:")
    assert doc["sessions"][1]["resumed"] is True
    # the repeated run is the same run: same seed, same bias, same start
    again = load_recording(folder / "measured_02_001.csv")
    assert again.meta["seed"] == stopped.meta["seed"] and again.steps == 100
    # no stopping: the brake never took the car below min_speed
    speeds = np.concatenate([load_recording(folder / a["file"]).data["speed"].to_numpy()
                             for a in doc["attempts"]])  # fmt: skip
    assert speeds.min() >= 14.9 - 1e-9
    assert not (folder / "session.lock").exists()


@pytest.mark.parametrize(
    "stop, note",
    [(KeyboardInterrupt, "interrupted by Ctrl-C (SIGINT)"),
     (lambda: SystemExit(143), "stopped by a signal (exit status 143)")],
)  # fmt: skip
def test_ctrl_c_or_a_signal_in_a_run_is_recorded_as_interrupted(tmp_path, pg, stop, note):
    """The session file says a run stopped by Ctrl-C or SIGTERM was interrupted, as it says
    of a SIGKILL's at the next start (it said "error", with the exception's name)."""
    study = small(runs={"seconds": 1.0, "min_speed": 14.9})

    def interrupt(session):
        if session.state == "driving" and session.run_index == 1 and session.steps == 20:
            raise stop()

    session, wheel = _wheel_session(tmp_path, pg, study, hook_extra=interrupt)
    try:
        with pytest.raises((KeyboardInterrupt, SystemExit)):
            session.run()
    finally:
        session.close()
        wheel.detach()
    doc = json.loads((tmp_path / "P01" / "session.json").read_text())
    last = doc["attempts"][-1]
    assert (last["status"], last["end_reason"], last["note"]) == ("aborted", "interrupted", note)
    assert doc["sessions"][-1]["ended"] == "interrupted"


def test_a_resume_says_that_it_keeps_the_first_slot_and_answers(tmp_path):
    """A resumed session keeps its first slot (and schedule) and answers; given others, it
    says so instead of ignoring them silently."""
    study = small()
    said: list[str] = []
    first = StudySession(study, "P01", None, output=tmp_path, slot=1, log=said.append)
    first.open()
    again = StudySession(study, "P01", None, output=tmp_path, slot=3, log=said.append,
                         metadata={"note": "other"})  # fmt: skip
    record, resumed = again.open()
    assert resumed and record.doc["participant"]["slot"] == 1
    assert any("the slot 1 of the first start, and its schedule, are kept (--slot 3 is "
               "ignored)" in line for line in said), said  # fmt: skip
    assert any("participant metadata recorded at the first start is kept" in line
               for line in said), said  # fmt: skip


def test_study_roles_pass_over_a_session_file_that_cannot_be_used(tmp_path):
    """hasa-replay reads a study folder's session file for the runs' roles; one whose
    attempts are not attempts' records gives no roles instead of a crash."""
    from hasa_env.session.session_file import study_roles

    StudySession(small(), "P01", None, output=tmp_path, log=lambda m: None).open()
    session = tmp_path / "P01" / "session.json"
    doc = json.loads(session.read_text())
    csv = tmp_path / "P01" / "measured_01_000.csv"
    doc["attempts"] = [{"file": csv.name, "block": "measured", "number": 1, "status":
                        "completed"}]  # fmt: skip
    session.write_text(json.dumps(doc))
    assert study_roles([csv]) == {csv.resolve(): "measured run 1"}
    for broken in ([1, 2], [{"file": csv.name}], [{"file": 3, "block": "x"}], "nope"):
        doc["attempts"] = broken
        session.write_text(json.dumps(doc))
        assert study_roles([csv]) == {}, broken


def test_a_changed_study_file_does_not_resume(tmp_path, pg):
    path = write(tmp_path, '[study]\nname = "s"\nseed = 1\n[runs]\nseconds = 0.2\n'
                 "countdown = 0.0\n[measured]\nruns = 1\n")  # fmt: skip
    session, wheel = _wheel_session(tmp_path, pg, Study.load(path))
    try:
        assert session.run().state == "complete"
        path.write_text(path.read_text().replace("seconds = 0.2", "seconds = 0.3"))
        changed = StudySession(Study.load(path), "P01", session.inputs, output=tmp_path,
                               realtime=False, log=lambda m: None)  # fmt: skip
        with pytest.raises(SessionError, match="the study file changed since this session"):
            changed.run()
        other = StudySession(Study.load(path), "P02", session.inputs, output=tmp_path,
                             realtime=False, log=lambda m: None)  # fmt: skip
        assert other.open()[1] is False  # another participant starts afresh
    finally:
        session.close()
        wheel.detach()
