"""The command-line programs: ``hasa-bench``, ``hasa-drive``, ``hasa-replay``, ``hasa-rec``,
``hasa-demo``.

They sit above the three library packages (docs/design.md §2): this is the
only code that composes :mod:`hasa_env`, :mod:`estimators` and
:mod:`benchmarks`. Every program follows the same conventions: ``--version``
(:func:`add_version`), one error format on stderr, ``prog: error: message``
(:func:`error`, the format argparse uses for usage errors too), no traceback
for anything a user can cause (:func:`console_script`), and these exit codes:

======  ==============================================================
code    meaning
======  ==============================================================
0       success
1       partial: some inputs failed (each named on stderr), the rest done
2       usage or input error (nothing done)
3       environment: something the machine lacks (no screen, a missing
        optional package, an unreachable Dask scheduler, ...)
======  ==============================================================
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
from collections.abc import Callable, Sequence

from hasa_env import __version__

__all__ = [
    "EXIT_ENVIRONMENT",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_PARTIAL",
    "EXIT_USAGE",
    "add_version",
    "console_script",
    "error",
    "warn",
]

EXIT_OK = 0
EXIT_PARTIAL = 1
EXIT_USAGE = 2
EXIT_ENVIRONMENT = 3
EXIT_INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT, the shell's convention)."""


def error(prog: str, message: str) -> None:
    """Print ``prog: error: message`` on stderr (the one error format of every program)."""
    print(f"{prog}: error: {message}", file=sys.stderr, flush=True)


def warn(prog: str, message: str) -> None:
    """Print ``prog: warning: message`` on stderr (something skipped or worth knowing)."""
    print(f"{prog}: warning: {message}", file=sys.stderr, flush=True)


def add_version(parser: argparse.ArgumentParser) -> None:
    """Add ``--version`` (the installed hasa-env version) to a program's parser."""
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")


def console_script(
    prog: str,
) -> Callable[[Callable[..., int]], Callable[..., int]]:
    """Decorate a program's ``main(argv)``: Ctrl-C and a closed output pipe end it quietly.

    Ctrl-C prints ``prog: error: interrupted`` and returns :data:`EXIT_INTERRUPTED`
    (what has been written stays written: every writer in hasa_env flushes as
    it goes); a closed stdout (``hasa-rec info ... | head``) ends the program
    without a traceback. Everything else a user can cause is handled inside
    ``main``; an exception that reaches here is a bug and keeps its traceback.
    """

    def decorate(main: Callable[..., int]) -> Callable[..., int]:
        @functools.wraps(main)
        def wrapped(argv: Sequence[str] | None = None) -> int:
            try:
                return main(argv)
            except KeyboardInterrupt:
                error(prog, "interrupted")
                return EXIT_INTERRUPTED
            except BrokenPipeError:
                # stdout was closed by the reader; silence the flush at exit
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, sys.stdout.fileno())
                return EXIT_OK

        return wrapped

    return decorate
