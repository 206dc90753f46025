"""The isolation of user code: every call into a user model in a child process of its own.

Isolation (:func:`run_isolated`): with a time limit (``ProtocolConfig.model_time_limit``,
600 s by default) every call into a user model -- importing it, fitting it on one
training run, scoring it on one batch of runs -- runs in a child process forked for
it, in its own session (a signal the model sends to its process group reaches only
itself), with an address-space limit (:data:`DEFAULT_MODEL_MEMORY_LIMIT` more than
it holds when forked) and a CPU-time limit. A call that takes longer than the limit
is stopped; ``sys.exit``, ``os._exit``, a segmentation fault, a signal, the memory
limit or any exception inside it ends that model (a :class:`ModelError` naming the
reason), never the benchmark, and whatever the model does to the data it is given
stays in its own process. What it prints goes to stderr (stdout holds the tables). When the call ends its whole process group is killed, so
processes it forked do not outlive it (unless they left the group). This is crash
isolation, not a sandbox: the model runs as the user, with the user's files,
network and processes (it can still write files or signal the benchmark's process
by its id). Built-in models and baselines run in the calling
process (trusted, and forking for them would cost time). Without a limit
(``None``) user code runs in the calling process too: faster, but a model that
hangs or exits takes the benchmark with it. Where processes cannot be forked
(Windows, or a daemonic Dask worker: set ``distributed.worker.daemon: false``)
user code runs in the calling process, guarded against exceptions and
``SystemExit`` only.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import multiprocessing
import os
import pickle
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

try:
    import resource
except ImportError:  # pragma: no cover - not Unix: no resource limits
    resource = None  # type: ignore[assignment]

from hasa_env.steering.loading import describe_exception

__all__ = [
    "DEFAULT_MODEL_MEMORY_LIMIT",
    "ModelError",
    "describe",
    "guarded",
    "guarded_in_time",
    "run_isolated",
]


class ModelError(Exception):
    """A user model failed; the message names the model and what went wrong.

    Attributes:
        model: the model's name (or its import path if it never loaded).
        stage: "import", "interface", "fit", "lane-keeping check", "predict" or "estimate".
        detail: what went wrong.
    """

    def __init__(self, model: str, stage: str, detail: str) -> None:
        self.model = model
        self.stage = stage
        self.detail = detail
        super().__init__(f"model {model!r} failed ({stage}): {detail}")

    def __reduce__(self) -> tuple[Any, tuple[str, str, str]]:
        # picklable, so it can come back from a worker process
        return (type(self), (self.model, self.stage, self.detail))

    def to_dict(self) -> dict[str, str]:
        return {"model": self.model, "stage": self.stage, "message": str(self)}


Result = TypeVar("Result")

describe = describe_exception
"""``Type: message (at file:line in function)`` of an exception (its innermost frame)."""


def _fork_context() -> Any:
    """The multiprocessing "fork" context, or None where user code cannot be isolated."""
    if "fork" not in multiprocessing.get_all_start_methods():
        return None
    if multiprocessing.current_process().daemon:  # e.g. a Dask worker under a nanny
        return None
    return multiprocessing.get_context("fork")


class _OutOfTime(BaseException):
    """Raised by the alarm of :func:`guarded_in_time` (not an Exception: user code that
    catches every Exception cannot swallow it)."""


def guarded(func: Callable[..., Any], args: tuple[Any, ...], model: str, stage: str) -> Any:
    """``func(*args)``; any exception and ``SystemExit`` become this model's ModelError.
    What the user's code prints goes to stderr, so that stdout holds hasa-bench's tables
    only."""
    try:
        with contextlib.redirect_stdout(sys.stderr):
            return func(*args)
    except (ModelError, KeyboardInterrupt, _OutOfTime):
        raise
    except BaseException as exc:  # noqa: BLE001 - SystemExit in user code is its failure
        raise ModelError(model, stage, f"raised {describe(exc)}") from None


DEFAULT_MODEL_MEMORY_LIMIT = 4 * 2**30
"""Address space (bytes) an isolated call into a user model may add to what its process
holds when it is forked (``RLIMIT_AS``): 4 GiB."""

_POLL = 0.05
"""Seconds between checks of an isolated call's process (did it end without a result?)."""


def _limit_child(time_limit: float, memory_limit: int | None) -> None:
    """In the forked child, before any user code: its own session (a signal to its process
    group reaches no one else), death with the parent (Linux), and resource limits the model
    cannot raise again: address space (``memory_limit`` bytes more than now) and CPU time (a
    bound for a child whose parent died and could not stop it: ``time_limit`` per CPU + 1 s,
    then SIGXCPU; SIGKILL 5 s later). SIGTERM and SIGHUP get their default action back: the
    handlers the program installed to stop itself (``hasa_cli.stop_on_signals``) are not the
    model's, whose process a signal ends."""
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    os.setsid()
    with contextlib.suppress(OSError, AttributeError):  # Linux only: PR_SET_PDEATHSIG
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))
    if resource is None:  # pragma: no cover - not Unix
        return
    if memory_limit is not None:
        with open("/proc/self/statm", encoding="ascii") as f:  # Linux; elsewhere no limit
            used = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        _lower_limit(resource.RLIMIT_AS, used + memory_limit, 0)
    cpu = math.ceil(time_limit * max(1, os.cpu_count() or 1)) + 1
    _lower_limit(resource.RLIMIT_CPU, cpu, 5)


def _lower_limit(which: int, value: int, margin: int) -> None:
    """Lower a resource's soft limit to ``value`` and its hard limit to ``value + margin``
    (never raising either)."""
    soft, hard = resource.getrlimit(which)
    infinite = resource.RLIM_INFINITY
    new_hard = value + margin if hard == infinite else min(hard, value + margin)
    new_soft = min(value, new_hard) if soft == infinite else min(soft, value, new_hard)
    resource.setrlimit(which, (new_soft, new_hard))


def _child(
    conn: Any,
    func: Callable[..., Any],
    args: tuple[Any, ...],
    model: str,
    stage: str,
    limits: tuple[float, int | None],
) -> None:
    with contextlib.suppress(OSError):  # what the model's code writes to fd 1 goes to stderr
        sys.stdout.flush()
        os.dup2(2, 1)
    try:
        _limit_child(*limits)
    except (OSError, ValueError) as exc:  # a platform without these limits: still isolated
        warnings.warn(f"resource limits not set: {exc}", RuntimeWarning, stacklevel=1)
    try:
        outcome: tuple[str, Any] = ("ok", guarded(func, args, model, stage))
    except ModelError as exc:
        if "MemoryError" in exc.detail and limits[1] is not None:
            exc = ModelError(
                model, stage, f"exceeded the memory limit of {_gib(limits[1])} ({exc.detail})"
            )
        outcome = ("error", exc)
    except KeyboardInterrupt:
        outcome = ("error", ModelError(model, stage, "interrupted"))
    try:
        conn.send(outcome)
    except Exception as exc:  # noqa: BLE001 - an unpicklable result
        conn.send(
            ("error", ModelError(model, stage, f"its result cannot be sent back: {describe(exc)}"))
        )
    conn.close()


def _gib(n: int) -> str:
    return f"{n / 2**30:g} GiB"


def _ended(pid: int) -> Any:
    """The child's ``waitid`` result if it has ended (not reaped: its pid and process group id
    cannot be reused until then), else None."""
    try:
        return os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
    except ChildProcessError:  # reaped already
        return None


def _why_ended(status: Any, time_limit: float) -> str:
    """How an isolated call's process ended without a result, in words."""
    if status is None:
        return "its process ended without a result"
    if status.si_code == os.CLD_EXITED:
        return (
            f"its process ended without a result (exit status {status.si_status}: os._exit "
            "or a crash)"
        )
    number = status.si_status
    try:
        name = signal.Signals(number).name
    except ValueError:
        name = f"signal {number}"
    if number == signal.SIGXCPU:
        return f"it used more than its CPU-time limit ({time_limit:g} s per CPU) and was stopped"
    why = {
        signal.SIGKILL: "by another process or the system's out-of-memory killer",
        signal.SIGSEGV: "a crash",
        signal.SIGABRT: "an abort",
    }.get(number, "")
    return (
        f"its process ended without a result (killed by signal {number}, {name}"
        f"{': ' + why if why else ''})"
    )


def _await_result(receive: Any, pid: int, model: str, stage: str, time_limit: float) -> Any:
    """The child's ``(status, value)``; ModelError if it ends without one or runs out of time."""
    deadline = time.monotonic() + time_limit
    while True:
        left = deadline - time.monotonic()
        if receive.poll(max(0.0, min(_POLL, left))):
            try:
                return receive.recv()
            except (EOFError, OSError, pickle.UnpicklingError):
                for _ in range(100):  # it closed the pipe: wait up to 5 s for how it ended
                    status = _ended(pid)
                    if status is not None:
                        break
                    time.sleep(_POLL)
                raise ModelError(model, stage, _why_ended(status, time_limit)) from None
        status = _ended(pid)
        if status is not None:
            if receive.poll(0):
                continue  # a result sent just before it ended
            raise ModelError(model, stage, _why_ended(status, time_limit))
        if left <= 0:
            raise ModelError(
                model, stage, f"took longer than the time limit of {time_limit:g} s and was stopped"
            )


def guarded_in_time(
    func: Callable[..., Result], args: tuple[Any, ...], model: str, stage: str,
    time_limit: float | None,
) -> Result:  # fmt: skip
    """:func:`guarded` in this process, stopped by an alarm after ``time_limit`` s (only in
    the main thread, where Python delivers signals; elsewhere, or without a limit, as
    :func:`guarded`). For what must run here, e.g. importing a user module the workers need,
    after it has imported isolated once.

    Raises:
        ModelError: as :func:`guarded`, or "took longer than the time limit".
    """
    if time_limit is None or threading.current_thread() is not threading.main_thread():
        return guarded(func, args, model, stage)

    def alarm(signum: int, frame: Any) -> None:
        raise _OutOfTime

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, time_limit)
    try:
        return guarded(func, args, model, stage)
    except _OutOfTime:
        raise ModelError(
            model,
            stage,
            f"took longer than the time limit of {time_limit:g} s in hasa-bench's "
            "own process (it had imported within the limit in its isolated process)",
        ) from None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def run_isolated(
    func: Callable[..., Result],
    args: tuple[Any, ...],
    *,
    model: str,
    stage: str,
    time_limit: float | None,
    memory_limit: int | None = DEFAULT_MODEL_MEMORY_LIMIT,
) -> Result:
    """``func(*args)`` for user model ``model``, isolated (see the module docstring).

    With ``time_limit`` (s) the call runs in a forked child process in its own
    session, with an address-space limit of ``memory_limit`` bytes more than
    it holds when forked (None: none) and a CPU-time limit; its result
    (picklable) comes back through a pipe. When the call ends, fails or runs
    out of time, the child's whole process group is killed (what it forked
    dies with it, unless it left the group). Without a ``time_limit``, or
    where processes cannot be forked, it runs here, guarded.

    Raises:
        ModelError: ``func`` raised (or raised ModelError itself), called
            ``sys.exit``/``os._exit``, crashed or was killed (naming the
            signal), exceeded the memory or CPU-time limit, or ran out of time.
    """
    context = _fork_context() if time_limit is not None else None
    if context is None or time_limit is None:
        return guarded(func, args, model, stage)
    receive, send = context.Pipe(duplex=False)
    process = context.Process(
        target=_child,
        args=(send, func, args, model, stage, (time_limit, memory_limit)),
        name=f"hasa-bench {model} {stage}",
    )
    process.daemon = True
    process.start()
    send.close()
    try:
        status, value = _await_result(receive, process.pid, model, stage, time_limit)
    finally:
        receive.close()
        for kill in (os.killpg, os.kill):  # its group (it leads it), then itself
            with contextlib.suppress(ProcessLookupError, PermissionError):
                kill(process.pid, signal.SIGKILL)
        process.join()
    if status == "error":
        raise value
    return value
