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
        optional package, an unreachable or lost Dask scheduler, a full
        disk, ...)
130     Ctrl-C; 143 / 129: SIGTERM / SIGHUP under :func:`stop_on_signals`
======  ==============================================================
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import errno
import functools
import math
import os
import re
import signal
import sys
import threading
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
    "Stopped",
    "add_equation_error_order_option",
    "add_speed_scaled_error_option",
    "add_trust_model_option",
    "add_version",
    "console_script",
    "equation_error_order",
    "error",
    "os_error_behind",
    "output_file_problem",
    "report_write_failure",
    "seed_list",
    "speed_list",
    "stop_on_signals",
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


DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""Write errors that mean "no space left": the disk (or the quota, or the file-size limit)."""


def os_error_behind(exc: BaseException) -> OSError | None:
    """The operating-system error behind ``exc``: ``exc`` itself if it is an ``OSError`` with
    an errno, else the first such one in its ``__cause__`` / ``__context__`` chain (e.g. a
    ``RecordingError`` raised because a write failed); None if there is none."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        if isinstance(current, OSError) and current.errno is not None:
            return current
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return None


def output_file_problem(option: str, path: str | os.PathLike[str]) -> str | None:
    """Why the output file ``path`` of ``option`` (e.g. ``--json``) cannot be written, checked
    before any work (its folder missing or not writable, a folder in its place, ``-``), or
    None."""
    shown = os.fspath(path)
    if shown == "-":
        return f"{option} -: standard output carries the printed results; give a file name"
    parent = os.path.dirname(os.path.abspath(shown))
    if not os.path.isdir(parent):
        return f"{option} {shown}: directory {parent} does not exist"
    if os.path.isdir(shown):
        return f"{option} {shown}: is a directory"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"{option} {shown}: directory {parent} is not writable"
    return None


def seed_list(text: str) -> tuple[int, ...]:
    """An argparse type: comma-separated population seeds, integers >= 0 (``--seeds``)."""
    try:
        seeds = tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"seeds must be comma-separated integers >= 0, e.g. 0,1,2, got {text!r}"
        ) from None
    if not seeds or any(s < 0 for s in seeds):
        raise argparse.ArgumentTypeError(f"seeds must be integers >= 0, got {text!r}")
    return seeds


def speed_list(text: str) -> tuple[float, ...]:
    """An argparse type (``--training-speeds``, the examples' ``--speeds``): comma-separated
    finite speeds in m/s, each in [1, 150], no repeats (the env's own limits, e.g.
    vehicle.max_speed, are checked with the protocol settings)."""
    try:
        speeds = tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        speeds = ()
    if (
        not speeds
        or not all(math.isfinite(v) and 1.0 <= v <= 150.0 for v in speeds)
        or len(set(speeds)) != len(speeds)
    ):
        raise argparse.ArgumentTypeError(
            f"speeds must be comma-separated distinct numbers in m/s within [1, 150], e.g. "
            f"15,25,35, got {printable(text)!r}"
        )
    return speeds


def report_write_failure(prog: str, exc: BaseException, output: object, kept: str) -> int | None:
    """One error line for a write into ``output`` that failed, and its exit status.

    ``kept`` says what is on disk (e.g. "2 complete run(s) are kept"). Returns
    :data:`EXIT_ENVIRONMENT` for a full disk (no space, quota, file-size limit),
    :data:`EXIT_PARTIAL` for any other write error, None if no ``OSError`` is behind
    ``exc`` (not a write failure: the caller re-raises it).
    """
    cause = os_error_behind(exc)
    if cause is None:
        return None
    reason = cause.strerror or str(cause)
    full = cause.errno in DISK_FULL_ERRNOS
    where = f" ({cause.filename})" if cause.filename else ""
    error(prog, f"cannot write to {output}: {reason}{where}; {kept}")
    return EXIT_ENVIRONMENT if full else EXIT_PARTIAL


class Stopped(BaseException):
    """SIGTERM or SIGHUP arrived while :func:`stop_on_signals` was in force."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _raise_stopped(signum: int, frame: object) -> None:
    raise Stopped(signum)


@contextlib.contextmanager
def stop_on_signals() -> Iterator[None]:
    """While inside, SIGTERM and SIGHUP raise :class:`Stopped` in the main thread, so the
    program unwinds (``finally`` blocks run, worker pools are terminated) and
    :func:`console_script` ends it with ``prog: error: stopped by SIGTERM`` and 128 + the
    signal's number (143, 129). The previous handlers come back on leaving."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    names = [n for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n)]
    previous = {n: signal.signal(getattr(signal, n), _raise_stopped) for n in names}
    try:
        yield
    finally:
        for name, handler in previous.items():
            signal.signal(getattr(signal, name), handler)


def add_trust_model_option(parser: argparse.ArgumentParser, subject: str) -> None:
    """``--trust-model-module``: ``subject`` (e.g. "--estimator's model file") may import the
    module its ``"class"`` field names when its type is not registered."""
    parser.add_argument(
        "--trust-model-module",
        action="store_true",
        help=f"let {subject} import the module its 'class' names when its type is not "
        "registered (searched in the working directory, the file's folder and the installed "
        "packages): a user model is code, importing it runs it; only for files you trust",
    )


def add_speed_scaled_error_option(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, what: str, instead: str, off: str
) -> None:
    """``--speed-scaled-error`` / ``--no-speed-scaled-error`` (default on): ``what`` (e.g. "fit
    the built-in generalized model's") equation error fitted as the speed-scaled error of
    docs/design.md §8.34, carried by its filter in place of ``instead``; ``off``: what the
    filter uses without it."""
    parser.add_argument(
        "--speed-scaled-error",
        action=argparse.BooleanOptionalAction,
        default=True,
        help=f"{what} equation error as a coloured part scaled by (15 / v)^2 plus a white part, "
        f"which its filter carries as a state in place of {instead} (default; "
        f"--no-speed-scaled-error: {off}; docs/design.md §8.34)",
    )


def equation_error_order(text: str) -> int:
    """An argparse type (``--equation-error-order``): lags of the equation error's
    autoregression, an integer from 0 (white) to
    :data:`hasa_env.steering.equation_error.MAX_EQUATION_ERROR_ORDER`."""
    from hasa_env.steering.equation_error import (  # start-up: only when the option is given
        MAX_EQUATION_ERROR_ORDER,
    )

    try:
        order = int(text)
    except ValueError:
        order = -1
    if not 0 <= order <= MAX_EQUATION_ERROR_ORDER:
        raise argparse.ArgumentTypeError(
            f"must be an integer in [0, {MAX_EQUATION_ERROR_ORDER}] (0: white), "
            f"got {printable(text)!r}"
        )
    return order


def add_equation_error_order_option(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    subject: str,
    default: int | None,
    shown_default: str,
) -> None:
    """``--equation-error-order P`` (:func:`equation_error_order`): lags of the autoregression
    ``subject`` (e.g. "the built-in generalized model's fit") estimates for its equation error
    (docs/design.md §8.32); ``default`` as the help shows it, ``shown_default``."""
    parser.add_argument(
        "--equation-error-order",
        type=equation_error_order,
        default=default,
        metavar="P",
        help=f"lags of the autoregression {subject} estimates for its equation error; the "
        f"estimator compares the steering whitened by it (default {shown_default}; 0: white, "
        "the paper's model; docs/design.md §8.32)",
    )


class ArgumentParser(argparse.ArgumentParser):
    """The parser of every program: no abbreviated options (``--stres`` is not ``--stress``)
    and a usage error that suggests the closest option or choice (``did you mean
    '--stress'?``). Its subcommands' parsers are of this class too."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self._given: list[str] = []

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """As argparse's, keeping the words given (a missing required option may be one of
        them misspelt: :meth:`error` says so)."""
        self._given = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        """Exit 2 with ``prog: error: message``, plus a suggestion for a misspelt word."""
        super().error(message + self._suggestion(message))

    def _suggestion(self, message: str) -> str:
        required = re.match(r"the following arguments are required: (.*)", message)
        if required:  # argparse says so before it says that a misspelt one is unknown
            wanted = [w for w in required.group(1).split(", ") if w.startswith("-")]
            known = set(self._option_string_actions)
            for word in self._given:
                name = word.split("=")[0]
                if name.startswith("-") and name not in known:
                    close = difflib.get_close_matches(name, wanted, n=1)
                    if close:
                        return f" (did you mean {close[0]!r}? {name!r} is no option)"
            return ""
        unknown = re.match(r"unrecognized arguments: (.*)", message)
        if unknown:
            options = sorted({o for p in self._parsers() for o in p._option_string_actions})
            for word in unknown.group(1).split():
                if not word.startswith("-"):
                    continue
                name = word.split("=")[0]
                owners = [p.prog for p in self._parsers() if name in p._option_string_actions]
                if owners:  # spelt right, given to another command
                    return f" ({name} is an option of {' and '.join(map(repr, owners))} only)"
                close = difflib.get_close_matches(name, options, n=1)
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
    it goes), SIGTERM / SIGHUP under :func:`stop_on_signals` likewise with 128 + the
    signal's number; a closed stdout (``hasa-rec info ... | head``) ends the program
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
            except Stopped as stop:
                name = signal.Signals(stop.signum).name
                error(prog, f"stopped by {name} (what was written so far stays written)")
                return 128 + stop.signum
            except BrokenPipeError:
                # stdout was closed by the reader; silence the flush at exit
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, sys.stdout.fileno())
                return EXIT_OK
            finally:
                warnings.showwarning = shown

        return wrapped

    return decorate
