"""Run independent tasks locally in processes or on a Dask cluster.

Every task carries its own seed, so results never depend on the executor or
on the number of workers; results come back in task order.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import logging
import os
import signal
import socket
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from benchmarks.defaults import NO_WORKER_TIMEOUT
from hasa_env.extras import install_hint

__all__ = [
    "NO_WORKER_TIMEOUT",
    "SCHEDULER_TIMEOUT",
    "ClusterLost",
    "SchedulerError",
    "check_scheduler",
    "default_workers",
    "map_tasks",
]

SCHEDULER_TIMEOUT = 6.0
"""Seconds :func:`check_scheduler` waits, in all, for a Dask scheduler to answer."""

_PR_SET_PDEATHSIG = 1  # linux/prctl.h
_SCHEMES = ("tcp", "tls", "ws", "wss", "inproc", "ucx")


class SchedulerError(OSError):
    """A Dask scheduler address that is malformed (``kind == "address"``), where nothing
    answers (``"unreachable"``) or where something that is no Dask scheduler answers
    (``"not_dask"``). The message is one line naming the address."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


def check_scheduler(address: str, timeout: float = SCHEDULER_TIMEOUT) -> str:
    """Check that a Dask scheduler answers at ``address``; its address (``tcp://`` added).

    Before any ``distributed.Client`` is made (whose connection to a silent
    server never times out, and which reads a non-Dask server's bytes as a
    frame length of exabytes), this parses the address, opens a plain TCP
    connection (a refused port fails at once) and asks the server for its
    identity over Dask's protocol, all within ``timeout`` seconds.

    Raises:
        SchedulerError: naming the address and what is wrong, within ``timeout`` s.
    """
    try:
        from distributed.comm import connect  # optional extra 'dask'
        from distributed.comm.addressing import (  # optional extra 'dask'
            parse_address,
            parse_host_port,
        )  # optional extra 'dask'
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise SchedulerError(
            "unreachable",
            f"--scheduler needs Dask's distributed package: {install_hint('dask')}",
        ) from exc
    if not isinstance(address, str) or not address.strip():
        raise SchedulerError(
            "address", f"scheduler address must be like tcp://host:8786, got {address!r}"
        )
    text = address.strip() if "://" in address else f"tcp://{address.strip()}"
    try:
        scheme, location = parse_address(text)
        if scheme not in _SCHEMES:
            raise ValueError(f"unknown scheme {scheme!r} (one of {', '.join(_SCHEMES)})")
        host, port = parse_host_port(location) if scheme != "inproc" else (location, None)
        if scheme != "inproc" and not (isinstance(port, int) and 0 < port < 65536 and host):
            raise ValueError("expected host:port with a port 1..65535")
    except (ValueError, TypeError) as exc:
        raise SchedulerError(
            "address", f"scheduler address {address!r} is not valid: {exc} (e.g. tcp://host:8786)"
        ) from None
    deadline = time.monotonic() + timeout
    if scheme != "inproc":
        try:
            with socket.create_connection((host, port), timeout=min(3.0, timeout)):
                pass
        except OSError as exc:
            reason = (
                exc.strerror or type(exc).__name__
                if not isinstance(exc, TimeoutError)
                else "no answer"
            )
            raise SchedulerError(
                "unreachable", f"no Dask scheduler at {text}: cannot connect ({reason})"
            ) from None

    async def identity() -> Any:
        left = max(0.5, deadline - time.monotonic())
        comm = await connect(text, timeout=left)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    try:
        reply = asyncio.run(asyncio.wait_for(identity(), max(0.5, deadline - time.monotonic())))
    except TimeoutError:
        raise SchedulerError(
            "not_dask",
            f"no Dask scheduler at {text}: the server there did not answer in "
            f"{timeout:g} s (is it a Dask scheduler's address, not its dashboard's?)",
        ) from None
    except (MemoryError, OSError, ValueError, TypeError, EOFError) as exc:
        raise SchedulerError(
            "not_dask",
            f"no Dask scheduler at {text}: the server there does not speak Dask's "
            f"protocol ({type(exc).__name__})",
        ) from None
    except Exception as exc:  # noqa: BLE001 - anything a foreign server's bytes can cause
        raise SchedulerError(
            "not_dask", f"no Dask scheduler at {text}: {type(exc).__name__} while asking it"
        ) from None
    if not (isinstance(reply, dict) and reply.get("type") == "Scheduler"):
        kind = reply.get("type") if isinstance(reply, dict) else type(reply).__name__
        raise SchedulerError(
            "not_dask",
            f"no Dask scheduler at {text}: the server there is a {kind}, not a scheduler",
        )
    return text


T = TypeVar("T")

HEARTBEAT = 1.0
"""Seconds between the checks of a Dask cluster while a task is awaited."""


class ClusterLost(SchedulerError):
    """The Dask cluster went away during :func:`map_tasks`: its scheduler (``kind ==
    "lost"``) or every worker for longer than the timeout (``"no_workers"``). :attr:`done`
    maps the index of every task that had finished to its result."""

    def __init__(self, kind: str, message: str, done: Mapping[int, Any]) -> None:
        super().__init__(kind, message)
        self.done = dict(done)


def default_workers() -> int:
    """Worker processes used by default: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def map_tasks(
    func: Callable[[Any], T],
    tasks: Sequence[Any] | Iterable[Any],
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int], None] | None = None,
    no_worker_timeout: float = NO_WORKER_TIMEOUT,
) -> list[T]:
    """``[func(t) for t in tasks]``, in parallel, in task order.

    Args:
        func: a picklable (module-level) function of one task.
        tasks: the task arguments (picklable).
        workers: local worker processes; ``1`` runs in this process; ``None``
            uses :func:`default_workers`. Ignored with ``scheduler``.
        scheduler: a Dask scheduler address (``tcp://host:8786``) or a
            ``distributed.Client``/``LocalCluster``-like object with a
            ``scheduler_address``; tasks then run on that cluster.
        progress: called with the number of finished tasks after each one.
        no_worker_timeout: on a Dask cluster, give up (:class:`ClusterLost`) when it has had
            no worker for this many seconds (all killed: it would wait for ever).

    Raises:
        ClusterLost: the Dask scheduler went away, or the cluster had no worker for
            ``no_worker_timeout`` s; the finished tasks' results are in its ``done``.
    """
    tasks = list(tasks)
    if not tasks:
        return []
    if scheduler is not None:
        return _map_dask(func, tasks, scheduler, progress, no_worker_timeout)
    n = default_workers() if workers is None else int(workers)
    if n < 1:
        raise ValueError(f"workers must be >= 1, got {workers!r}")
    if n == 1 or len(tasks) == 1:
        out = []
        for i, task in enumerate(tasks, start=1):
            out.append(func(task))
            if progress:
                progress(i)
        return out
    pool = ProcessPoolExecutor(
        max_workers=min(n, len(tasks)), initializer=_init_worker, initargs=(os.getpid(),)
    )
    try:
        futures = [pool.submit(func, task) for task in tasks]
        results = []
        for i, fut in enumerate(futures, start=1):
            results.append(fut.result())
            if progress:
                progress(i)
    except BaseException:  # a task failed, Ctrl-C, SIGTERM: no worker may outlive this call
        _terminate_pool(pool)
        raise
    pool.shutdown()
    return results


def _init_worker(parent: int) -> None:
    """A pool worker: the default action for SIGTERM and SIGHUP (it must not inherit the
    parent's handlers, which raise in Python and would let a task's loop catch them), and on
    Linux ended with its parent even if that is killed with SIGKILL (``PR_SET_PDEATHSIG``)."""
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM))
        if os.getppid() != parent:  # the parent is gone already
            os._exit(1)


def _terminate_pool(pool: ProcessPoolExecutor) -> None:
    """Stop a process pool now: pending tasks cancelled, running workers terminated
    (SIGTERM, then SIGKILL after 2 s) and reaped, then the pool's manager thread joined
    (up to 2 s): at exit CPython wakes a manager thread still running through a pipe it may
    be closing at that moment ("Exception ignored ... Bad file descriptor" after Ctrl-C)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)  # shutdown() forgets it
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        with contextlib.suppress(OSError, ValueError):
            process.terminate()
    deadline = time.monotonic() + 2.0
    for process in processes:
        with contextlib.suppress(OSError, ValueError, AssertionError):
            process.join(max(0.0, deadline - time.monotonic()))
            if process.is_alive():
                process.kill()
                process.join(1.0)
    if manager is not None:
        manager.join(2.0)


def _map_dask(
    func: Callable[[Any], T],
    tasks: list[Any],
    scheduler: Any,
    progress: Any,
    no_worker_timeout: float,
) -> list[T]:
    try:
        from distributed import Client  # optional extra 'dask'
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise RuntimeError(
            f"--scheduler needs Dask's distributed package: {install_hint('dask')}"
        ) from exc
    address = check_scheduler(getattr(scheduler, "scheduler_address", scheduler))
    with Client(address, set_as_default=False, timeout=f"{SCHEDULER_TIMEOUT:g}s") as client:
        futures = client.map(func, tasks, pure=False)
        try:
            done = _gather_dask(client, futures, address, no_worker_timeout, progress)
        except ClusterLost:
            # the client's reconnection attempts, cancelled by close(), log a traceback
            logger = logging.getLogger("distributed.client")
            level, logger.level = logger.level, logging.CRITICAL + 1
            try:
                client.close(timeout=2)
            finally:
                logger.setLevel(level)
            raise
        return [done[i] for i in range(len(tasks))]


def _gather_dask(
    client: Any, futures: list[Any], address: str, no_worker_timeout: float, progress: Any
) -> dict[int, Any]:
    """Each future's result by task index, fetched as soon as it finishes (so a worker lost
    later costs nothing finished), waiting in heartbeats of :data:`HEARTBEAT` s. A task's own
    exception propagates; a lost scheduler, or a cluster without a worker for
    ``no_worker_timeout`` s, raises :class:`ClusterLost` with the results so far."""
    from distributed import wait  # optional extra 'dask'

    pending = {fut: i for i, fut in enumerate(futures)}
    done: dict[int, Any] = {}
    workerless_since: float | None = None

    def lost(why: str) -> ClusterLost:
        return ClusterLost(
            "lost",
            f"the Dask scheduler at {address} went away ({why}) after {len(done)} of "
            f"{len(futures)} tasks",
            done,
        )

    while pending:
        try:
            with client.as_current():
                finished = wait(list(pending), HEARTBEAT, return_when="FIRST_COMPLETED").done
        except TimeoutError:
            finished = set()
        except Exception as exc:  # noqa: BLE001 - cancelled futures: the scheduler is gone
            raise lost(type(exc).__name__) from None
        for fut in finished:
            if fut.status == "cancelled":
                raise lost("its tasks were cancelled")
            done[pending.pop(fut)] = fut.result()  # a task's own error propagates
            if progress:
                progress(len(done))
        if finished:
            continue
        try:
            workers = len(client.scheduler_info(n_workers=-1).get("workers", {}))
        except Exception as exc:  # noqa: BLE001 - the scheduler's connection, in any way
            raise lost(type(exc).__name__) from None
        now = time.monotonic()
        workerless_since = None if workers else (workerless_since or now)
        if workerless_since is not None and now - workerless_since >= no_worker_timeout:
            raise ClusterLost(
                "no_workers",
                f"the Dask cluster at {address} has had no worker for {no_worker_timeout:g} s "
                f"({len(done)} of {len(futures)} tasks finished); start workers and run again",
                done,
            )
    return done
