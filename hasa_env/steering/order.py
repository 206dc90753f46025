"""Order selection of the generalized model: BIC (or AIC) on a common sample
(the paper's future work 1).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from hasa_env.sim.road import Road
from hasa_env.steering.fitting import _as_runs, _criteria
from hasa_env.steering.models import GeneralizedModel

__all__ = ["OrderSelection", "select_order"]


@dataclass(frozen=True)
class OrderSelection:
    """Result of :func:`select_order`.

    Attributes:
        orders: the selected orders {"na", "nb", "nc", "nd"}.
        criterion: "bic" or "aic".
        table: every candidate (orders, n_params, rss, aic, bic), best first.
        n_common: samples of the common estimation sample.
        model: a :class:`~hasa_env.steering.models.GeneralizedModel` of the
            selected orders fitted on all the data (not only the common sample).
    """

    orders: dict[str, int]
    criterion: str
    table: pd.DataFrame
    n_common: int
    model: GeneralizedModel


def _order_grid(
    value: Mapping[str, int] | Sequence[int] | None, default: Sequence[int], label: str
) -> tuple[int, ...]:
    keys = ("na", "nb", "nc", "nd")
    if value is None:
        return tuple(default)
    if isinstance(value, Mapping):
        unknown = [k for k in value if k not in keys]
        if unknown:
            raise ValueError(f"{label}: unknown key {unknown[0]!r}; allowed: {', '.join(keys)}")
        merged = dict(zip(keys, default, strict=True))
        merged.update(value)
        out = tuple(merged[k] for k in keys)
    else:
        out = tuple(value)
        if len(out) != 4:
            raise ValueError(f"{label} must give 4 orders (na, nb, nc, nd), got {out}")
    for k, v in zip(keys, out, strict=True):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 0:
            raise ValueError(f"{label}[{k!r}] must be a non-negative integer, got {v!r}")
    return tuple(int(v) for v in out)


def _residual_sum_of_squares(matrix: np.ndarray, target: np.ndarray) -> float | None:
    """RSS of the least-squares fit (None if the columns are linearly dependent)."""
    if matrix.shape[1] == 0:
        return float(target @ target)
    norms = np.linalg.norm(matrix, axis=0)
    if np.any(norms == 0):
        return None
    scaled = matrix / norms
    solution, _, rank, singular = np.linalg.lstsq(scaled, target, rcond=None)
    if rank < matrix.shape[1] or singular[-1] < 1e-12 * singular[0]:
        return None
    residual = target - scaled @ solution
    return float(residual @ residual)


def select_order(
    runs: pd.DataFrame | Sequence[pd.DataFrame],
    max_orders: Mapping[str, int] | Sequence[int] | None = None,
    min_orders: Mapping[str, int] | Sequence[int] | None = None,
    criterion: str = "bic",
    road: Road | None = None,
    **model_kwargs: Any,
) -> OrderSelection:
    """Search the generalized model's orders by BIC (or AIC) on a common sample.

    Every candidate (na, nb, nc, nd) between ``min_orders`` (default
    (1, 1, 0, 0)) and ``max_orders`` (default (4, 6, 3, 3)) is fitted on the
    *same* samples: those where the largest model has its full history, so the
    criteria compare like with like. BIC = n log(rss/n) + p log(n).

    Args:
        runs: one run or a list of runs.
        max_orders, min_orders: mappings {"na", "nb", "nc", "nd"} or 4-sequences.
        criterion: "bic" or "aic".
        road: the road of the runs (None: from their metadata, else straight).
        **model_kwargs: options of the models (near_distance, far_distance, dt, ...).
    """
    if criterion not in ("bic", "aic"):
        raise ValueError(f"criterion must be 'bic' or 'aic', got {criterion!r}")
    high = _order_grid(max_orders, (4, 6, 3, 3), "max_orders")
    low = _order_grid(min_orders, (1, 1, 0, 0), "min_orders")
    if any(lo > hi for lo, hi in zip(low, high, strict=True)):
        raise ValueError(f"min_orders {low} exceed max_orders {high}")
    frames = _as_runs(runs)
    largest = GeneralizedModel(*high, **model_kwargs)
    matrices, targets = [], []
    for run in frames:
        design = largest.design(largest.features(run, road))
        valid = design.valid
        matrices.append(design.matrix[valid])
        targets.append(design.target[valid])
    X = np.vstack(matrices)
    y = np.concatenate(targets)
    n = y.size
    offsets = np.cumsum([0, *high])  # column blocks a | b | c | d of the largest design
    rows = []
    for orders in itertools.product(*(range(lo, hi + 1) for lo, hi in zip(low, high, strict=True))):
        cols = [offsets[block] + i for block, order in enumerate(orders) for i in range(order)]
        p = len(cols)
        if p >= n:
            continue
        rss = _residual_sum_of_squares(X[:, cols], y)
        if rss is None:
            continue  # collinear candidate: not estimable on these data
        _, aic, bic = _criteria(rss, n, p)
        rows.append({"na": orders[0], "nb": orders[1], "nc": orders[2], "nd": orders[3],
                     "n_params": p, "rss": rss, "aic": aic, "bic": bic})  # fmt: skip
    if not rows:
        raise ValueError("no candidate order could be fitted on these data")
    table = (
        pd.DataFrame(rows)
        .sort_values([criterion, "n_params"], kind="stable")
        .reset_index(drop=True)
    )
    best = {k: int(table.loc[0, k]) for k in ("na", "nb", "nc", "nd")}
    model = GeneralizedModel(**best, **model_kwargs).fit(frames, road=road)
    return OrderSelection(best, criterion, table, n, model)
