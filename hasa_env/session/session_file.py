"""The session file of a study participant: ``<output>/<participant>/session.json``.

``hasa-drive study`` keeps one JSON document per participant next to their
recordings. It is rewritten atomically (a new randomly named temporary file, fsync,
``os.replace``, fsync of the folder: :func:`hasa_env.atomic.write_atomic`) at every change, so at any moment it holds either the
previous or the new state, never a torn one. It records:

- ``study``: the study's name, file, SHA-256 and the whole validated study;
- ``participant``: the id, the schedule slot and the metadata the study asks
  for (no names);
- ``seed`` and ``hypotheses``; ``schedule``: every run with its block
  (practice or measured), number, track, true bias and env seed;
- ``attempts``: every run started, in order: its schedule position, the
  recording it went to, ``status`` (``started``, ``completed``, ``aborted``),
  ``end_reason`` (``truncated``: full length; ``terminated``: left the road;
  ``stopped``, ``interrupted``, ``error``) and the steps recorded;
- ``sessions``: every time the session was (re)started: when, how it ended,
  the input devices and calibrations used, the versions;
- ``state``: ``in_progress`` or ``complete``.

An attempt left ``started`` means the process died during the run (a
SIGKILL, a power cut): :meth:`SessionFile.recover` marks it ``aborted``
(``interrupted``) and counts the steps its recording kept. The session goes
on at the next run not completed: with the study's ``repeat_aborted`` the
aborted run is driven again into a new file (``measured_03_001.csv`` after
``measured_03_000.csv``); recordings are never overwritten. A lock on the
participant's folder (``session.lock``, ``flock``; it holds the owner's
process id) stops two programs from creating or running one session at once;
the operating system drops it when its process ends, however it ends.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import platform
import socket
import sys
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from hasa_env._walk import walk_files
from hasa_env.atomic import write_atomic
from hasa_env.session.study import ScheduledRun, Study
from hasa_env.validation import ANY_JSON, Field, schema, validate

__all__ = [
    "SESSION_FILE",
    "SESSION_FORMAT",
    "SESSION_FORMAT_VERSION",
    "SessionError",
    "SessionFile",
    "SessionLock",
    "find_session_files",
    "study_roles",
]

SESSION_FILE = "session.json"
SESSION_FORMAT = "hasa_env.study_session"
SESSION_FORMAT_VERSION = 1
LOCK_FILE = "session.lock"
COMPLETED_REASONS = ("truncated", "terminated")
"""End reasons of a completed run: its full length, or the car left the road."""

_SCHEMA = schema(
    {
        "format": Field("choice", choices=(SESSION_FORMAT,)),
        "format_version": Field("choice", choices=(SESSION_FORMAT_VERSION,),
                                hint="the version this hasa_env reads"),
        "study": Field("mapping", each=ANY_JSON),
        "participant": Field("mapping", fields={
            "id": Field("string", non_empty=True),
            "slot": Field("integer", optional=True),
            "metadata": Field("mapping", {}, each=ANY_JSON),
        }),
        "seed": Field("integer", low=0),
        "hypotheses": Field("numbers", non_empty=True),
        "schedule": Field("json"),
        "attempts": Field("json"),
        "sessions": Field("json"),
        "state": Field("choice", choices=("in_progress", "complete")),
    }
)  # fmt: skip


class SessionError(ValueError):
    """A session file that cannot be used (or a session that cannot go on); the message
    names the file and what is wrong."""


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _version() -> str:
    try:
        return version("hasa-env")
    except PackageNotFoundError:
        return "0.0.0+unknown"


class SessionLock:
    """The lock of a participant's folder: ``<folder>/session.lock``, locked with ``flock``.

    Taken before the session file is read or created, so two programs started at once for
    one participant cannot both create or run the session: the second is refused at once
    with the first one's process id. The operating system releases the lock when its
    process ends in any way (even SIGKILL), so a lock is never stale. The file holds the
    owner's process id, host and start time (for the message) and is removed on release.
    """

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.path = Path(directory) / LOCK_FILE
        self._fd: int | None = None

    def acquire(self) -> None:
        """Lock the folder (created if missing).

        Raises:
            SessionError: another process holds the lock (its id named).
            OSError: the folder or the lock file cannot be created.
        """
        if self._fd is not None:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOFOLLOW", 0)
        for _ in range(100):
            fd = os.open(self.path, flags, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                owner = os.read(fd, 200).decode("utf-8", "replace").split()
                os.close(fd)
                pid = f"process {owner[0]}" if owner else "starting"
                raise SessionError(
                    f"{self.path}: another program ({pid}) is running this participant's "
                    "session; wait for it to end or stop it first"
                ) from None
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path, follow_symlinks=False))
            except FileNotFoundError:
                same = False
            if same:  # not a file its previous owner removed while we waited to lock it
                self._fd = fd
                with contextlib.suppress(OSError):  # a full disk: the lock holds all the same
                    os.ftruncate(fd, 0)
                    os.write(fd, f"{os.getpid()} {socket.gethostname()} {_now()}\n".encode())
                return
            os.close(fd)
        raise SessionError(f"{self.path}: cannot take the lock file")

    def release(self) -> None:
        """Remove the lock file and unlock (no-op if not held)."""
        fd, self._fd = self._fd, None
        if fd is None:
            return
        with contextlib.suppress(OSError):
            self.path.unlink()
        os.close(fd)


class SessionFile:
    """One participant's session document (see the module docstring).

    Use :meth:`create` or :meth:`open`; every change goes to disk at once.
    """

    def __init__(self, path: Path, document: dict[str, Any]) -> None:
        self.path = Path(path)
        self.doc = document
        self._lock: SessionLock | None = None

    # ------------------------------------------------------------ creation
    @classmethod
    def create(
        cls,
        directory: Path,
        study: Study,
        participant: str,
        slot: int | None,
        metadata: Mapping[str, Any],
        seed: int,
        schedule: Sequence[ScheduledRun],
    ) -> SessionFile:
        """Start a new session file in ``directory`` (refused if one exists)."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / SESSION_FILE
        if path.exists():
            raise SessionError(f"{path}: a session file exists already; resume it instead")
        doc = {
            "format": SESSION_FORMAT,
            "format_version": SESSION_FORMAT_VERSION,
            "study": {
                "name": study.name,
                "file": study.source,
                "sha256": study.sha256,
                "spec": study.to_dict(),
            },
            "participant": {"id": participant, "slot": slot, "metadata": dict(metadata)},
            "seed": int(seed),
            "hypotheses": study.hypotheses,
            "schedule": [r.to_dict() for r in schedule],
            "attempts": [],
            "sessions": [],
            "state": "in_progress",
        }
        session = cls(path, doc)
        session.save()
        return session

    @classmethod
    def open(cls, path: str | os.PathLike[str]) -> SessionFile:
        """Read and check a session file.

        Raises:
            SessionError: the file cannot be read, is not a session file, or
                has a field that is wrong (named).
        """
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise SessionError(f"{path}: no such session file") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise SessionError(f"{path}: cannot read the session file ({exc})") from None
        try:
            raw = json.loads(text)
        except json.JSONDecodeError as exc:
            raise SessionError(
                f"{path}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
            ) from None
        except RecursionError:
            raise SessionError(f"{path}: not a session file: JSON nested too deeply") from None
        except ValueError as exc:  # an integer of more than 4300 digits
            raise SessionError(f"{path}: cannot be read as JSON: {str(exc)[:200]}") from None
        doc = validate(
            raw,
            _SCHEMA,
            describe=lambda p: f"field '{p}'" if p else "the session file",
            error=lambda p, message: SessionError(f"{path}: {message}"),
        )
        for i, entry in enumerate(doc["schedule"]):
            try:
                ScheduledRun.from_dict(entry)
            except (KeyError, TypeError) as exc:
                raise SessionError(f"{path}: field 'schedule[{i}]' is not a run ({exc})") from None
        return cls(path, doc)

    def save(self) -> None:
        """Write the document to disk atomically."""
        write_atomic(self.path, json.dumps(self.doc, indent=2, allow_nan=False) + "\n")

    # ------------------------------------------------------------- locking
    @property
    def lock_path(self) -> Path:
        return self.path.with_name(LOCK_FILE)

    def acquire(self) -> None:
        """Take the participant folder's lock (:class:`SessionLock`), held until
        :meth:`release` or the process ends.

        Raises:
            SessionError: another process holds it.
        """
        if self._lock is None:
            self._lock = SessionLock(self.path.parent)
        self._lock.acquire()

    def release(self) -> None:
        """Release the lock if this object holds it."""
        if self._lock is not None:
            self._lock.release()

    # ----------------------------------------------------------- accessors
    @property
    def participant(self) -> str:
        return str(self.doc["participant"]["id"])

    @property
    def schedule(self) -> list[ScheduledRun]:
        return [ScheduledRun.from_dict(r) for r in self.doc["schedule"]]

    @property
    def attempts(self) -> list[dict[str, Any]]:
        return list(self.doc["attempts"])

    @property
    def repeat_aborted(self) -> bool:
        return bool(self.doc["study"]["spec"]["runs"]["repeat_aborted"])

    def done(self, position: int) -> bool:
        """Whether schedule position ``position`` needs no further attempt."""
        mine = [a for a in self.doc["attempts"] if a["position"] == position]
        if any(a["status"] == "completed" for a in mine):
            return True
        return (
            bool(mine) and not self.repeat_aborted and all(a["status"] == "aborted" for a in mine)
        )

    def remaining(self) -> list[ScheduledRun]:
        """The scheduled runs still to drive, in order."""
        return [r for r in self.schedule if not self.done(r.position)]

    def completed(self, block: str | None = None) -> list[dict[str, Any]]:
        """Completed attempts (of ``block``)."""
        return [
            a for a in self.doc["attempts"]
            if a["status"] == "completed" and (block is None or a["block"] == block)
        ]  # fmt: skip

    def aborted(self) -> list[dict[str, Any]]:
        return [a for a in self.doc["attempts"] if a["status"] == "aborted"]

    # ------------------------------------------------------------- changes
    def recover(self, load_steps: Any = None) -> list[dict[str, Any]]:
        """Mark attempts left ``started`` (the process died in the run) as aborted.

        ``load_steps(path) -> int`` counts the steps a recording kept (None:
        not counted). Returns the attempts it marked.
        """
        marked = []
        for attempt in self.doc["attempts"]:
            if attempt["status"] != "started":
                continue
            attempt["status"] = "aborted"
            attempt["end_reason"] = "interrupted"
            attempt["note"] = (
                "the program ended during the run (killed, crashed or a power cut); the "
                "recording keeps every step written before"
            )
            attempt["ended_at"] = None
            if load_steps is not None and attempt.get("file"):
                try:
                    attempt["steps"] = int(load_steps(self.path.parent / attempt["file"]))
                except Exception as exc:  # noqa: BLE001 - report, never lose the attempt
                    attempt["steps"] = None
                    attempt["note"] += f"; its recording cannot be read ({exc})"
            marked.append(attempt)
        for entry in self.doc["sessions"]:
            if entry.get("ended") is None:
                entry["ended"] = "interrupted"
        if marked or self.doc["sessions"]:
            self.save()
        return marked

    def begin(self, devices: Mapping[str, Any], extra: Mapping[str, Any] | None = None) -> None:
        """Record that a (re)started session begins, with the devices in use."""
        self.doc["sessions"].append(
            {
                "started_at": _now(),
                "ended_at": None,
                "ended": None,
                "host": socket.gethostname(),
                "hasa_env": _version(),
                "python": platform.python_version(),
                "platform": sys.platform,
                "devices": dict(devices),
                **dict(extra or {}),
            }
        )
        self.save()

    def end(self, how: str) -> None:
        """Record how the current (re)start ended: complete, quit, interrupted or error."""
        if self.doc["sessions"]:
            self.doc["sessions"][-1].update(ended_at=_now(), ended=how)
        if not self.remaining():
            self.doc["state"] = "complete"
        self.save()

    def start_attempt(self, run: ScheduledRun, source: str) -> dict[str, Any]:
        """Record that ``run`` starts now, driven with input ``source``."""
        attempt = {
            "position": run.position,
            "block": run.block,
            "number": run.number,
            "attempt": sum(1 for a in self.doc["attempts"] if a["position"] == run.position),
            "bias": run.bias,
            "seed": run.seed,
            "file": None,
            "status": "started",
            "end_reason": None,
            "steps": 0,
            "started_at": _now(),
            "ended_at": None,
            "input_source": source,
        }
        self.doc["attempts"].append(attempt)
        self.save()
        return attempt

    def recording_started(self, attempt: dict[str, Any], path: Path) -> None:
        """Record the recording file an attempt writes (as soon as it exists)."""
        attempt["file"] = os.path.relpath(path, self.path.parent)
        self.save()

    def finish_attempt(
        self, attempt: dict[str, Any], end_reason: str, steps: int, note: str | None = None
    ) -> None:
        """Record how an attempt ended (completed if it ran its length or left the road)."""
        attempt["status"] = "completed" if end_reason in COMPLETED_REASONS else "aborted"
        attempt["end_reason"] = end_reason
        attempt["steps"] = int(steps)
        attempt["ended_at"] = _now()
        if note:
            attempt["note"] = note
        self.save()

    def summary(self) -> dict[str, Any]:
        """Counts of what was recorded, for the end of a session."""
        return {
            "participant": self.participant,
            "state": self.doc["state"],
            "practice_completed": len(self.completed("practice")),
            "measured_completed": len(self.completed("measured")),
            "measured_scheduled": sum(1 for r in self.schedule if r.block == "measured"),
            "aborted": len(self.aborted()),
            "remaining": len(self.remaining()),
            "left_road": sum(1 for a in self.completed() if a["end_reason"] == "terminated"),
        }


def find_session_files(root: str | os.PathLike[str]) -> list[Path]:
    """Every ``session.json`` under ``root``, in folders linked into it too (sorted; a
    folder that cannot be read is left to the recordings' loader to name)."""
    return walk_files(root, names=(SESSION_FILE,))[0]


def study_roles(paths: Iterable[str | os.PathLike[str]]) -> dict[Path, str]:
    """What each recording of ``paths`` was in its study session, by its resolved path, as
    the session file beside it says (``hasa-drive study``): ``measured run 3``, ``practice
    run 1``, ``aborted measured run 2 (interrupted)`` or ``unfinished measured run 2`` (its
    session stopped in it and was not resumed). Recordings without a usable session file
    beside them, or that it does not list, are left out (``hasa-bench`` leaves the unlisted
    ones of a session's folder out of a verdict)."""
    folders: dict[Path, dict[Path, str]] = {}
    roles: dict[Path, str] = {}
    for raw in paths:
        path = Path(raw).resolve()
        if path.parent not in folders:
            folders[path.parent] = _folder_roles(path.parent)
        if path in folders[path.parent]:
            roles[path] = folders[path.parent][path]
    return roles


def _folder_roles(folder: Path) -> dict[Path, str]:
    """:func:`study_roles` of the recordings the session file in ``folder`` lists (empty:
    none there, or one that cannot be used, e.g. an attempt that is no attempt's record)."""
    try:
        session = SessionFile.open(folder / SESSION_FILE)
        roles = {}
        for attempt in session.attempts:
            if not attempt.get("file"):
                continue
            run = f"{attempt['block']} run {attempt['number']}"
            if attempt["status"] == "completed":
                role = run
            elif attempt["status"] == "aborted":
                role = f"aborted {run} ({attempt['end_reason']})"
            else:
                role = f"unfinished {run}"
            roles[(folder / str(attempt["file"])).resolve()] = role
        return roles
    except (SessionError, KeyError, TypeError, AttributeError, ValueError, OSError):
        return {}
