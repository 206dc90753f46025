"""The command-line programs: ``hasa-bench``, ``hasa-drive``, ``hasa-replay``, ``hasa-rec``,
``hasa-demo``.

They sit above the three library packages (docs/design.md §2): this is the
only code that composes :mod:`hasa_env`, :mod:`estimators` and
:mod:`benchmarks`. Every program follows the same conventions
(:func:`error`, :func:`add_version`) and exit codes:

======  ==============================================================
code    meaning
======  ==============================================================
0       success
1       partial: some inputs failed (each named on stderr), the rest done
2       usage or input error (nothing done)
3       environment: something the machine lacks (no screen, ...)
======  ==============================================================
"""

from __future__ import annotations

import argparse
import sys

from hasa_env import __version__

__all__ = ["EXIT_OK", "EXIT_PARTIAL", "EXIT_USAGE", "EXIT_ENVIRONMENT", "add_version", "error"]

EXIT_OK = 0
EXIT_PARTIAL = 1
EXIT_USAGE = 2
EXIT_ENVIRONMENT = 3


def error(prog: str, message: str) -> None:
    """Print ``prog: error: message`` on stderr (the one error format of every program)."""
    print(f"{prog}: error: {message}", file=sys.stderr)


def add_version(parser: argparse.ArgumentParser) -> None:
    """Add ``--version`` (the installed hasa-env version) to a program's parser."""
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
