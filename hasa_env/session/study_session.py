"""A participant's session of a study: screens, practice, measured runs, breaks, resume.

:class:`StudySession` runs one participant through a :class:`~hasa_env.session.study.Study`:
the welcome screen, the practice runs, the measured runs with breaks, and
the end screen, each run recorded by :class:`~hasa_env.session.loop.DriveSession`
under ``<output>/<participant>/`` as ``practice_NN_AAA.csv`` /
``measured_NN_AAA.csv`` (NN the run's number in its block, AAA the attempt),
with its ``.json`` sidecar and ``.inputs.tsv`` raw inputs. The session file
(:mod:`hasa_env.session.session_file`) notes every run before it starts,
the recording it writes as soon as that exists, and how it ended.

Starting the same participant again resumes the session: runs left
``started`` by a killed process are marked aborted (their recordings are
kept, every step written before), and the session goes on at the first run
not completed (an aborted run is driven again into a new file when the study
says ``repeat_aborted``). A resumed session checks that the study file is
the one it started with, and keeps the schedule, seeds and metadata it
recorded then.

The participant's window shows only what the study allows
(:attr:`Study.view_options`); ``status`` gives the experimenter the run,
time, speed and estimator weights (``hasa-drive study`` prints it in the
terminal).
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hasa_env.devices.sources import InputManager
from hasa_env.recording import load_recording
from hasa_env.session.loop import DriveSession, RunResult, RunSpec
from hasa_env.session.session_file import SESSION_FILE, SessionError, SessionFile, SessionLock
from hasa_env.session.settings import DriveSettings
from hasa_env.session.study import ScheduledRun, Study, participant_slot, seed_from_entropy

__all__ = ["StudyOutcome", "StudySession"]

CONTINUE = "Press a wheel button or SPACE to go on."


@dataclass
class StudyOutcome:
    """How a session (start or resume) ended.

    Attributes:
        state: ``"complete"`` (every run done), ``"quit"`` (the driver or the
            experimenter stopped: resume later) or ``"already_complete"``.
        session: the session file.
        results: the runs recorded in this start.
        resumed: whether an earlier start of this session existed.
    """

    state: str
    session: SessionFile
    results: list[RunResult] = field(default_factory=list)
    resumed: bool = False


def _count_steps(path: Path) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # an incomplete recording warns; it is expected here
        return int(load_recording(path).steps)


class StudySession:
    """One participant's session of a study (see the module docstring).

    Args:
        study: the study.
        participant: participant id (``P07``; no names).
        inputs: the input layer (keyboard + joysticks).
        output: root folder; the participant's files go to ``output / participant``.
        metadata: the participant's answers to the study's questions (checked;
            on resume the recorded ones are kept).
        slot: the participant's number for the schedule (default: from the id).
        display, realtime, hook, env_wrapper, fps, frame_every, log,
        max_idle_iterations: as for :class:`~hasa_env.session.loop.DriveSession`.
        status: called with (this session, the drive session) while driving and
            when the state changes: the experimenter's status line.
        run_metadata: extra metadata for every recording's sidecar (e.g. a
            synthetic driver's label).
        fsync: fsync every recorded row.
    """

    def __init__(
        self,
        study: Study,
        participant: str,
        inputs: InputManager,
        *,
        output: str | Path = Path("recordings"),
        metadata: Mapping[str, Any] | None = None,
        slot: int | None = None,
        display: Any = None,
        realtime: bool = True,
        hook: Callable[[DriveSession], None] | None = None,
        env_wrapper: Callable[[Any], Any] | None = None,
        status: Callable[[StudySession, DriveSession], None] | None = None,
        fps: int = 60,
        frame_every: int = 1,
        log: Callable[[str], None] = print,
        max_idle_iterations: int = 100_000,
        run_metadata: Mapping[str, Any] | None = None,
        fsync: bool = False,
    ) -> None:
        self.study = study
        self.participant = participant
        self.inputs = inputs
        self.output = Path(output)
        self.metadata = dict(metadata or {})
        self.slot = slot
        self.display = display
        self.realtime = realtime
        self.hook = hook
        self.env_wrapper = env_wrapper
        self.status = status
        self.fps = fps
        self.frame_every = frame_every
        self.log = log
        self.max_idle_iterations = max_idle_iterations
        self.run_metadata = dict(run_metadata or {})
        self.fsync = fsync
        self.record: SessionFile | None = None
        self.current: ScheduledRun | None = None
        """The run being driven (or about to be)."""
        self._drives: dict[str, DriveSession] = {}
        # the id is checked like a drive session's (a folder name, no path tricks)
        DriveSettings(participant=participant, output=self.output)

    @property
    def directory(self) -> Path:
        """The participant's folder: ``output / participant``."""
        return self.output / self.participant

    # ---------------------------------------------------------------- file
    def open(self) -> tuple[SessionFile, bool]:
        """The session file, created or resumed; and whether it was resumed.

        Raises:
            StudyError: bad metadata, or a schedule that needs a slot.
            SessionError: the session file is unusable, or belongs to another
                study or to another version of this study file.
        """
        path = self.directory / SESSION_FILE
        if not path.exists():
            answers = self.study.check_metadata(self.metadata)
            seed = self.study.seed if self.study.seed is not None else seed_from_entropy()
            schedule = self.study.schedule_for(self.participant, self.slot, seed)
            slot = self.slot if self.slot is not None else participant_slot(self.participant)
            record = SessionFile.create(
                self.directory, self.study, self.participant, slot, answers, seed, schedule
            )
            self.record = record
            return record, False
        record = SessionFile.open(path)
        stored = record.doc["study"]
        if stored["name"] != self.study.name:
            raise SessionError(
                f"{path}: this session belongs to the study {stored['name']!r}, not "
                f"{self.study.name!r} ({self.study.source})"
            )
        if stored["sha256"] != self.study.sha256:
            raise SessionError(
                f"{path}: the study file changed since this session started (it was "
                f"{stored['file']}, SHA-256 {stored['sha256'][:12]}..., now "
                f"{self.study.source}, {self.study.sha256[:12]}...); resume with the study file "
                "the session started with, so every run follows one protocol"
            )
        if record.participant != self.participant:
            raise SessionError(
                f"{path}: holds participant {record.participant!r}, not {self.participant!r}"
            )
        if self.metadata and self.metadata != record.doc["participant"]["metadata"]:
            self.log(
                "hasa-drive: resuming: the participant metadata recorded at the first start is "
                "kept (the answers given now differ)"
            )
        stored_slot = record.doc["participant"].get("slot")
        if self.slot is not None and self.slot != stored_slot:
            self.log(
                f"hasa-drive: resuming: the slot {stored_slot} of the first start, and its "
                f"schedule, are kept (--slot {self.slot} is ignored)"
            )
        self.record = record
        return record, True

    # ------------------------------------------------------------ sessions
    def _drive_session(self, track: str, record: SessionFile) -> DriveSession:
        if track in self._drives:
            return self._drives[track]
        doc = self.study.document
        r = doc["runs"]
        settings = DriveSettings(  # the start state: in the study's env keys
            participant=self.participant,
            track=track,
            runs=len(record.schedule),
            seconds=r["seconds"],
            output=self.output,
            seed=record.doc["seed"],
            countdown=r["countdown"],
            config=self.study.env_keys(),
            fsync=self.fsync,
            speed_control=r["speed_control"],
            min_speed=r["min_speed"],
            scenario=self.study.scenario,
        )

        def status(drive: DriveSession) -> None:
            if self.status is not None:
                self.status(self, drive)

        drive = DriveSession(
            settings,
            self.inputs,
            display=self.display,
            realtime=self.realtime,
            hook=self.hook,
            view=doc["view"]["view"],
            fps=self.fps,
            frame_every=self.frame_every,
            show_points=doc["view"]["show_points"],
            metadata=self.run_metadata,
            env_wrapper=self.env_wrapper,
            log=self.log,
            max_idle_iterations=self.max_idle_iterations,
            view_options=self.study.view_options,
            status=status,
        )
        self._drives[track] = drive
        return drive

    def _spec(self, run: ScheduledRun, record: SessionFile, attempt: int) -> RunSpec:
        block_runs = sum(1 for r in record.schedule if r.block == run.block)
        name = "practice run" if run.block == "practice" else "run"
        return RunSpec(
            index=run.position - 1,
            seed=run.seed,
            reset_options=self.study.reset_options(run),
            prefix=run.prefix,
            label=f"{name} {run.number} of {block_runs}",
            metadata={
                "study": {
                    "name": self.study.name,
                    "file": self.study.source,
                    "sha256": self.study.sha256,
                    "block": run.block,
                    "number": run.number,
                    "position": run.position,
                    "attempt": attempt,
                    "schedule": self.study.document["schedule"]["kind"],
                    "scenario": self.study.scenario,
                    "bias": run.bias,
                    "bias_index": run.bias_index,
                    "session_file": SESSION_FILE,
                },
                "participant_slot": record.doc["participant"]["slot"],
                "participant_metadata": record.doc["participant"]["metadata"],
            },
        )

    def _screen(
        self, run: ScheduledRun, previous: ScheduledRun | None, resumed: bool
    ) -> list[tuple[str, str, float]]:
        """The screens (message, state, shortest time) shown before ``run``."""
        study = self.study
        screens = []
        if previous is None:
            if resumed:
                where = (
                    f"{'practice run' if run.block == 'practice' else 'measured run'} {run.number}"
                )
                screens.append((f"Welcome back.\nThe session goes on with {where}.\n{CONTINUE}",
                                "idle", 0.0))  # fmt: skip
            else:
                screens.append((f"{study.text('welcome')}\n{CONTINUE}", "idle", 0.0))
        if previous is None or previous.block != run.block:
            screens.append((f"{study.text(run.block)}\n{CONTINUE}", "idle", 0.0))
        elif run.block == "measured":
            every = study.document["measured"]["break_every"]
            if every and (run.number - 1) % every == 0:
                screens.append((f"{study.text('break')}\n{CONTINUE}", "break",
                                float(study.document["measured"]["break_seconds"])))  # fmt: skip
            else:
                screens.append((f"Run {previous.number} done.\n{CONTINUE}", "between_runs", 0.0))
        else:
            screens.append(
                (f"Practice run {previous.number} done.\n{CONTINUE}", "between_runs", 0.0)
            )
        return screens

    # ----------------------------------------------------------------- run
    def run(self) -> StudyOutcome:
        """Run (or resume) the session until it is complete or the driver quits.

        Raises:
            StudyError, SessionError: see :meth:`open`; anything the drive loop
                raises (the run is then recorded as aborted, ``error``).
        """
        lock = SessionLock(self.directory)
        lock.acquire()  # before the session file is read or created: one program at a time
        try:
            return self._run_locked()
        finally:
            lock.release()

    def _run_locked(self) -> StudyOutcome:
        record, resumed = self.open()
        results: list[RunResult] = []
        recovered = record.recover(_count_steps)
        for a in recovered:
            self.log(
                f"hasa-drive: {a['block']} run {a['number']} (attempt {a['attempt']}) was "
                f"interrupted after {a['steps']} steps; its recording {a['file']} is kept"
            )
        remaining = record.remaining()
        if not remaining:
            self.log(f"hasa-drive: the session of {self.participant} is already complete")
            record.end("complete")
            return StudyOutcome("already_complete", record, results, resumed)
        if resumed:
            first = remaining[0]
            self.log(
                f"hasa-drive: resuming {self.participant} at {first.block} run "
                f"{first.number} ({len(remaining)} run(s) to go)"
            )
        drive = self._drive_session(remaining[0].track, record)
        drive.poll_devices()  # devices already plugged in
        record.begin(drive.input_description(), {"resumed": resumed})
        previous: ScheduledRun | None = None
        for run in remaining:
            self.current = run
            drive = self._drive_session(run.track, record)
            info = drive.preview(run.seed, self.study.reset_options(run))
            for message, state, seconds in self._screen(run, previous, resumed):
                if not drive.show(message, state=state, info=info, min_seconds=seconds):
                    record.end("quit")
                    return StudyOutcome("quit", record, results, resumed)
            attempt = record.start_attempt(run, self.inputs.source_name)
            drive.on_recording = lambda path, a=attempt: record.recording_started(a, path)
            try:
                result = drive.drive(self._spec(run, record, attempt["attempt"]))
            except BaseException as exc:
                # best effort: on a full disk the session file cannot be written either;
                # it then still says "started", which the next start marks as aborted
                how, why = _how_it_ended(exc)
                with contextlib.suppress(OSError):
                    record.finish_attempt(attempt, how, drive.steps, note=why)
                    record.end(how)
                raise
            if result is None:  # quit in the countdown: nothing was recorded
                record.doc["attempts"].remove(attempt)
                record.end("quit")
                return StudyOutcome("quit", record, results, resumed)
            note = "stopped by the driver or the experimenter" if (
                result.end_reason == "stopped") else None  # fmt: skip
            record.finish_attempt(attempt, result.end_reason, result.steps, note)
            results.append(result)
            self.log(
                f"hasa-drive: {run.block} run {run.number}: {result.steps} steps, "
                f"{result.end_reason} -> {result.path}"
            )
            if drive.state == "quit":
                record.end("quit")
                return StudyOutcome("quit", record, results, resumed)
            previous = run
        record.end("complete")
        drive.show(self.study.text("end"), state="end")
        return StudyOutcome("complete", record, results, resumed)

    def close(self) -> None:
        """Close every drive session (their preview envs and renderers)."""
        for drive in self._drives.values():
            drive.close()
        self._drives.clear()


def _how_it_ended(exc: BaseException) -> tuple[str, str]:
    """How a run that raised ``exc`` ended, for the session file: ``interrupted`` by Ctrl-C
    or a signal (the program raises SystemExit(128 + signal) on SIGTERM and SIGHUP), as a
    SIGKILL's run is marked at the next start, else ``error``; and a note saying which."""
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted", "interrupted by Ctrl-C (SIGINT)"
    if isinstance(exc, SystemExit):
        return "interrupted", f"stopped by a signal (exit status {exc.code})"
    return "error", f"{type(exc).__name__}: {exc}"
