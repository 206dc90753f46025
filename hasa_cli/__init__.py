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
import re
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
    "printable",
    "warn",
]

EXIT_OK = 0
EXIT_PARTIAL = 1
EXIT_USAGE = 2
EXIT_ENVIRONMENT = 3
EXIT_INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT, the shell's convention)."""


_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029]")
_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _escape(match: re.Match[str]) -> str:
    char = match.group()
    if char in _NAMED:
        return _NAMED[char]
    return f"\\x{ord(char):02x}" if ord(char) < 0x100 else f"\\u{ord(char):04x}"


def printable(text: object, newlines: bool = False) -> str:
    """``str(text)`` with terminal control characters escaped as Python writes them in a repr
    (``\\x1b``, ``\\n``, ``\\u2028``): C0 and C1 controls, DEL and the Unicode line
    separators. Everything the programs print that comes from a file (file names, recording
    metadata, model names) goes through it, so a file cannot move the cursor, clear the screen
    or forge a line. ``newlines``: keep ``\\n`` (a table of several lines)."""
    text = str(text)
    if newlines:
        return "\n".join(_CONTROL.sub(_escape, line) for line in text.split("\n"))
    return _CONTROL.sub(_escape, text)


def _one_message(prog: str, kind: str, message: str) -> str:
    """``prog: kind: message``, escaped (:func:`printable`): a message's list items (a newline
    and two spaces) stay on their own indented lines, every other newline is escaped, so
    only the program writes a line starting ``prog:``."""
    lines: list[str] = []
    for line in printable(message, newlines=True).split("\n"):
        if lines and not line.startswith("  "):
            lines[-1] += "\\n" + line
        else:
            lines.append(line)
    return "\n".join([f"{prog}: {kind}: {lines[0]}", *lines[1:]])


def error(prog: str, message: str) -> None:
    """Print ``prog: error: message`` on stderr (the one error format of every program);
    control characters in ``message`` are escaped (:func:`printable`)."""
    print(_one_message(prog, "error", message), file=sys.stderr, flush=True)


def warn(prog: str, message: str) -> None:
    """Print ``prog: warning: message`` on stderr (something skipped or worth knowing);
    control characters in ``message`` are escaped (:func:`printable`)."""
    print(_one_message(prog, "warning", message), file=sys.stderr, flush=True)


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
