"""Human drivers in the loop: the drive session (:mod:`~hasa_env.session.loop`),
its settings, and scripted driving through a virtual wheel.

The command line is ``hasa-drive`` (:mod:`hasa_cli.drive`).
"""

from hasa_env.session.loop import MAX_CATCH_UP, DriveSession, RunResult
from hasa_env.session.scripted import VirtualWheelDriver
from hasa_env.session.settings import DriveSettings

__all__ = ["MAX_CATCH_UP", "DriveSession", "DriveSettings", "RunResult", "VirtualWheelDriver"]
