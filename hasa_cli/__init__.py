"""The command-line programs: ``hasa-bench``, ``hasa-drive``, ``hasa-replay``, ``hasa-rec``,
``hasa-demo``.

They sit above the three library packages (docs/design.md §2): this is the
only code that composes :mod:`hasa_env`, :mod:`estimators` and
:mod:`benchmarks`. Every program follows the same conventions: ``--version``
(:func:`add_version`), one error format on stderr, ``prog: error: message``
(:func:`error`, the format argparse uses for usage errors too), no traceback
for anything a user can cause (:func:`console_script`), options spelt out in full with a
"did you mean" for a misspelt one (:class:`ArgumentParser`), and these exit codes:

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
import difflib
import functools
import os
import re
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from importlib.metadata import PackageNotFoundError, version
from typing import Any, NoReturn

__all__ = [
    "ArgumentParser",
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


class ArgumentParser(argparse.ArgumentParser):
    """The parser of every program: no abbreviated options (``--stres`` is not ``--stress``)
    and a usage error that suggests the closest option or choice (``did you mean
    '--stress'?``). Its subcommands' parsers are of this class too."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        """Exit 2 with ``prog: error: message``, plus a suggestion for a misspelt word."""
        super().error(message + self._suggestion(message))

    def _suggestion(self, message: str) -> str:
        unknown = re.match(r"unrecognized arguments: (.*)", message)
        if unknown:
            options = sorted({o for p in self._parsers() for o in p._option_string_actions})
            for word in unknown.group(1).split():
                if word.startswith("-"):
                    close = difflib.get_close_matches(word.split("=")[0], options, n=1)
                    if close:
                        return f" (did you mean {close[0]!r}?)"
            return ""
        choice = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if choice:
            choices = re.findall(r"'([^']*)'", choice.group(2)) or choice.group(2).split(", ")
            close = difflib.get_close_matches(choice.group(1), choices, n=1)
            if close:
                return f" (did you mean {close[0]!r}?)"
        return ""

    def _parsers(self) -> Iterator[argparse.ArgumentParser]:
        """This parser and those of its subcommands, recursively."""
        yield self
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    yield from (sub._parsers() if isinstance(sub, ArgumentParser) else [sub])


def _version() -> str:
    """The installed hasa-env version (read from its metadata: importing hasa_env is slower)."""
    try:
        return version("hasa-env")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "0.0.0+unknown"


def add_version(parser: argparse.ArgumentParser) -> None:
    """Add ``--version`` (the installed hasa-env version) to a program's parser."""
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")


def _one_line_warning(prog: str) -> Callable[..., None]:
    """A :func:`warnings.showwarning` that prints ``prog: warning: message`` (no file or
    source line: the programs' one style)."""

    def show(message: Warning | str, category: type[Warning], *args: Any, **kwargs: Any) -> None:
        warn(prog, str(message))

    return show


def console_script(
    prog: str,
) -> Callable[[Callable[..., int]], Callable[..., int]]:
    """Decorate a program's ``main(argv)``: Ctrl-C and a closed output pipe end it quietly.

    Warnings are shown as ``prog: warning: message`` lines. Ctrl-C prints
    ``prog: error: interrupted`` and returns :data:`EXIT_INTERRUPTED`
    (what has been written stays written: every writer in hasa_env flushes as
    it goes); a closed stdout (``hasa-rec info ... | head``) ends the program
    without a traceback. Everything else a user can cause is handled inside
    ``main``; an exception that reaches here is a bug and keeps its traceback.
    """

    def decorate(main: Callable[..., int]) -> Callable[..., int]:
        @functools.wraps(main)
        def wrapped(argv: Sequence[str] | None = None) -> int:
            shown = warnings.showwarning
            warnings.showwarning = _one_line_warning(prog)
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
            finally:
                warnings.showwarning = shown

        return wrapped

    return decorate
