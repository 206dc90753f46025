"""Defaults of the benchmark protocol that the command line shows in its help.

They live apart from :mod:`benchmarks.protocol.config` so that ``hasa-bench --help``
can show them without importing the protocol (statsmodels, matplotlib: seconds).
"""

from __future__ import annotations

__all__ = [
    "DEFAULT_MODEL_TIME_LIMIT",
    "DEFAULT_SEEDS",
    "DEFAULT_TRAINING_DRIVERS",
    "DEFAULT_EQUATION_ERROR_ORDER",
    "GENERALIZED_ORDERS",
    "NO_WORKER_TIMEOUT",
]

DEFAULT_SEEDS = (0, 1, 2, 3, 4)
"""Population seeds of ``hasa-bench paper`` (the verdict's intervals are over them)."""

DEFAULT_TRAINING_DRIVERS = 8
"""Extra drivers of the population, one run each, that also train the models of a synthetic
``hasa-bench paper`` (docs/design.md §8.21; 0, the paper's one-run protocol, is
``--training-drivers 0``; recordings: always 0)."""

DEFAULT_EQUATION_ERROR_ORDER = 2
"""Lags of the autoregression the built-in generalized model's fit estimates for its equation
error (docs/design.md §8.32; the estimator compares the steering whitened by it); 0 is the
paper's white error (``--equation-error-order 0``)."""

GENERALIZED_ORDERS = ("paper", "bic")
"""How ``hasa-bench`` chooses the orders of its built-in generalized model (docs/design.md
§8.26): ``"paper"`` (the default) keeps the paper's (na=2, nb=4, nc=1, nd=2); ``"bic"``
selects them on the training runs by BIC (:func:`hasa_env.steering.order.select_order`, its
default grid), the paper's future work 1."""

DEFAULT_MODEL_TIME_LIMIT = 600.0
"""Time limit in s of one call into a user model (import, a fit, a batch of runs)."""

NO_WORKER_TIMEOUT = 60.0
"""Seconds :func:`benchmarks.executor.map_tasks` waits on a Dask cluster without a worker
before it gives up."""
