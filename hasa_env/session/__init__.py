"""Human drivers in the loop: the drive session (:mod:`~hasa_env.session.loop`),
its settings, studies (:mod:`~hasa_env.session.study`: study files and
schedules; :mod:`~hasa_env.session.study_session`: a participant's session;
:mod:`~hasa_env.session.session_file`: its session file and resume), scripted
driving through a virtual wheel, and a model of a person steering with keys
(:mod:`~hasa_env.session.keyboard_person`).

The command line is ``hasa-drive`` (the command-line layer above this package):
``hasa-drive study STUDY.toml --participant P07`` runs a study session.
"""

from hasa_env.session.loop import MAX_CATCH_UP, DriveSession, RunResult, RunSpec
from hasa_env.session.scripted import VirtualWheelDriver
from hasa_env.session.session_file import SessionError, SessionFile, find_session_files
from hasa_env.session.settings import DriveSettings
from hasa_env.session.study import MetadataField, ScheduledRun, Study, StudyError
from hasa_env.session.study_session import StudyOutcome, StudySession

__all__ = [
    "MAX_CATCH_UP",
    "DriveSession",
    "DriveSettings",
    "MetadataField",
    "RunResult",
    "RunSpec",
    "ScheduledRun",
    "SessionError",
    "SessionFile",
    "Study",
    "StudyError",
    "StudyOutcome",
    "StudySession",
    "VirtualWheelDriver",
    "find_session_files",
]
