"""Run independent tasks locally in processes or on a Dask cluster.

Every task carries its own seed, so results never depend on the executor or
on the number of workers; results come back in task order.
"""

from __future__ import annotations

import asyncio
import os
import socket
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

__all__ = ["SCHEDULER_TIMEOUT", "SchedulerError", "check_scheduler", "default_workers", "map_tasks"]

SCHEDULER_TIMEOUT = 6.0
"""Seconds :func:`check_scheduler` waits, in all, for a Dask scheduler to answer."""

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
            "--scheduler needs Dask's distributed package: pip install 'hasa-env[dask]'",
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
    """
    tasks = list(tasks)
    if not tasks:
        return []
    if scheduler is not None:
        return _map_dask(func, tasks, scheduler, progress)
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
    pool = ProcessPoolExecutor(max_workers=min(n, len(tasks)))
    try:
        futures = [pool.submit(func, task) for task in tasks]
        results = []
        for i, fut in enumerate(futures, start=1):
            results.append(fut.result())
            if progress:
                progress(i)
    except BaseException:
        # Ctrl-C or a failed task: stop the workers now instead of letting them finish
        # every queued task (the pool's own shutdown waits for them all)
        _stop_pool(pool)
        raise
    pool.shutdown()
    return results


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    """Cancel ``pool``'s queued tasks and end its worker processes at once."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(2.0)
        if process.is_alive():
            process.kill()
            process.join()


def _map_dask(func: Callable[[Any], T], tasks: list[Any], scheduler: Any, progress: Any) -> list[T]:
    try:
        from distributed import Client  # optional extra 'dask'
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise RuntimeError(
            "--scheduler needs Dask's distributed package: pip install 'hasa-env[dask]'"
        ) from exc
    address = check_scheduler(getattr(scheduler, "scheduler_address", scheduler))
    with Client(address, set_as_default=False, timeout=f"{SCHEDULER_TIMEOUT:g}s") as client:
        futures = client.map(func, tasks, pure=False)
        results = []
        for i, fut in enumerate(futures, start=1):
            results.append(fut.result())
            if progress:
                progress(i)
        return results
