"""Run independent tasks locally in processes or on a Dask cluster.

Every task carries its own seed, so results never depend on the executor or
on the number of workers; results come back in task order.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

__all__ = ["map_tasks", "default_workers"]

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
    with ProcessPoolExecutor(max_workers=min(n, len(tasks))) as pool:
        futures = [pool.submit(func, task) for task in tasks]
        results = []
        for i, fut in enumerate(futures, start=1):
            results.append(fut.result())
            if progress:
                progress(i)
        return results


def _map_dask(func: Callable[[Any], T], tasks: list[Any], scheduler: Any, progress: Any) -> list[T]:
    try:
        from distributed import Client  # optional extra 'dask'
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise RuntimeError(
            "--scheduler needs Dask's distributed package: pip install 'hasa-env[dask]'"
        ) from exc
    address = getattr(scheduler, "scheduler_address", scheduler)
    if not isinstance(address, str):
        raise ValueError(f"scheduler must be an address like 'tcp://host:8786', got {scheduler!r}")
    with Client(address, set_as_default=False) as client:
        futures = client.map(func, tasks, pure=False)
        results = []
        for i, fut in enumerate(futures, start=1):
            results.append(fut.result())
            if progress:
                progress(i)
        return results
